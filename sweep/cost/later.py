"""The cost of the rounds after the current one, for a campaign with seeds by precision or
refinement: the **bound** (every run its rules allow: every point to the cap, every cell
split to the smallest spacing) always, and an **expected** value only where it has data,
labelled with what it stands on:

- seeds by precision: each point with finished seeds is forecast from them
  (:func:`nematic_solids.sweep.precision.forecast.expected_seeds`); a point without any takes its
  seeds from the campaign's ``prior:`` (the phase.nc of a finished run of the same campaign) when
  there is one, at the prior's measured run time there (phase.nc's ``run_time``); a point with
  neither is *unknown*: it is in the bound, not in the expected value, and the line says how many
  there are;
- refinement: the rounds' runs cannot be forecast from the grid's outcomes; with a
  ``prior:`` the expected value is the prior's runs beyond the runs planned so far, at their
  measured run times (a prior without them: its run count at the mean cost of a run), without
  one there is no expected value.

Otherwise the run times are the estimate's own (:class:`nematic_solids.sweep.cost.estimate.Basis`:
the campaign's finished runs, scaled, or the cost model). After each round the estimate is made
again from the runs finished by then.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..campaign import Campaign
from .result import Expected, LaterRounds


@dataclass(frozen=True)
class Prior:
    """The runs of a finished campaign: seeds run per grid point (by its coordinates) and in
    all; ``label``: where they come from, for the estimate's text."""

    seeds: dict[tuple[tuple[str, str], ...], int]
    total: int
    label: str
    #: each run's measured wall time in seconds, by (point key, seed) (phase.nc's
    #: ``run_time``; empty for a phase.nc written before it had one)
    run_time: dict[tuple[tuple[tuple[str, str], ...], int], float] = field(default_factory=dict)
    #: each point's grid (phase.nc's ``resolution`` variable, or its ``num_resolution``)
    resolution: dict[tuple[tuple[str, str], ...], int] = field(default_factory=dict)

    @functools.cached_property
    def _point_times(self) -> dict[tuple[tuple[str, str], ...], float]:
        times: dict[tuple[tuple[str, str], ...], list[float]] = {}
        for (key, _), t in self.run_time.items():
            times.setdefault(key, []).append(t)
        return {key: float(np.mean(v)) for key, v in times.items()}

    def point_seconds(self, coords: dict[str, Any]) -> float | None:
        """The mean run time of the prior's runs at a point, if it has any."""
        return self._point_times.get(point_key(coords))


def point_key(coords: dict[str, Any]) -> tuple[tuple[str, str], ...]:
    """A grid point's coordinates as a key that a phase.nc's values match (numbers to ten
    significant digits)."""

    def text(v: Any) -> str:
        if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
            return f"{float(v):.10g}"
        return str(v)

    return tuple(sorted((str(k), text(v)) for k, v in coords.items()))


def load_prior(path: str) -> Prior | str:
    """The :class:`Prior` in the phase.nc at ``path``, or why it cannot be read."""
    import xarray as xr

    try:
        with xr.open_dataset(path) as ds:
            if "status" not in ds or "seed" not in ds["status"].dims:
                return f"{path} is not a campaign's phase.nc (no status over seeds)"
            status = ds["status"].load()
            dims = [d for d in status.dims if d != "seed"]
            status = status.transpose(*dims, "seed")
            axes = {
                str(c): str(ds[c].dims[0])
                for c in ds.coords
                if ds[c].ndim == 1 and ds[c].dims[0] in dims
            }
            values = {c: ds[c].values for c in axes}
            ran = (status.values != 0).sum(axis=-1)
            times = (
                ds["run_time"].load().transpose(*dims, "seed").values if "run_time" in ds else None
            )
            seed_values = [int(v) for v in ds["seed"].values]
            grids = ds["resolution"].load().transpose(*dims).values if "resolution" in ds else None
            fixed = ds.attrs.get("num_resolution")
            seeds, run_time, resolution = {}, {}, {}
            for index in np.ndindex(*ran.shape):
                at = dict(zip(dims, index, strict=True))
                coords = {c: values[c][at[d]] for c, d in axes.items()}
                key = point_key(coords)
                seeds[key] = int(ran[index])
                if grids is not None:
                    resolution[key] = int(grids[index])
                elif isinstance(fixed, (int, np.integer)):
                    resolution[key] = int(fixed)
                if times is not None:
                    for j, seed in enumerate(seed_values):
                        if np.isfinite(times[(*index, j)]):
                            run_time[(key, seed)] = float(times[(*index, j)])
            name = ds.attrs.get("campaign", "?")
            commits = ", ".join(  # short hashes, as git log --oneline shows them
                c.strip()[:7] + ("+dirty" if c.strip().endswith("+dirty") else "")
                for c in str(ds.attrs.get("run_git_commits", "")).split(",")
                if c.strip()
            )
    except (OSError, ValueError, KeyError) as e:
        return f"cannot read {path}: {e}"
    total = int(ran.sum())
    where = Path(path)
    label = f"prior: the {total} runs of campaign {name} in {where.parent.name}/{where.name}" + (
        f" (commits {commits})" if commits else ""
    )
    return Prior(seeds, total, label, run_time, resolution)


def campaign_prior(campaign: Campaign) -> tuple[Prior | None, str]:
    """The campaign's ``prior:`` read, or ``None`` and why it is not used."""
    if campaign.prior is None:
        return None, ""
    got = load_prior(campaign.prior)
    return (got, "") if isinstance(got, Prior) else (None, f"the prior is not used: {got}")


def grid_factor(campaign: Campaign, prior: Prior, key: tuple[tuple[str, str], ...]) -> float:
    """The cost model's ratio of a run on this campaign's grid at the prior's point ``key``
    to one on the prior's grid there (1 where they agree or either is unknown): a refined point
    that the prior ran on 256^2 and this campaign's resolution rule puts on 512^2 costs about
    4.5 times the prior's measured time."""
    import dataclasses

    from ..expand import make_point
    from .model import model_seconds

    grid = prior.resolution.get(key)
    if grid is None:
        return 1.0
    try:
        point = make_point(campaign, (), {name: _value(text) for name, text in key})
    except (ValueError, TypeError, KeyError):  # (a point this campaign cannot make)
        return 1.0
    if point.numerics.resolution == grid:
        return 1.0
    there = dataclasses.replace(point.numerics, resolution=grid)
    protocol = point.parameters.protocol
    return model_seconds(point.numerics, protocol=protocol) / model_seconds(
        there, protocol=protocol
    )


def _value(text: str) -> Any:
    """A coordinate of :func:`point_key` back as a number where it is one."""
    try:
        return float(text)
    except ValueError:
        return text


def refine_rounds(
    campaign: Campaign,
    current: int,
    planned: int,
    per_run: Sequence[float],
    workers: int,
    planned_runs: set[tuple[tuple[tuple[str, str], ...], int]] | None = None,
) -> LaterRounds | None:
    """An adaptive campaign's rounds after ``current`` (with seeds by precision, the rounds
    that only add seeds too): the bound is every run
    :func:`~nematic_solids.sweep.refine.plan.run_bound` allows beyond the ``planned`` ones, each
    at the mean cost of ``per_run``; each round ends when its longest run does. The expected
    value is the prior's runs beyond them: with the prior's measured run times, the runs it
    holds that are not among ``planned_runs`` ((point key, seed)), at their own times (the
    later rounds' points are the expensive ones near the boundaries: a mean of the first
    round's underprices them); without, the prior's run count at the mean cost."""
    from ..refine.plan import run_bound

    assert campaign.refine is not None
    last = campaign.refine.rounds
    if campaign.precision is not None:  # rounds that only add seeds follow
        from ..precision.decide import rounds_bound

        last += rounds_bound(campaign.precision, len(campaign.seeds)) - 1
    rounds = last - current
    runs = max(0, run_bound(campaign) - planned)
    if rounds <= 0 or runs == 0 or not per_run:
        return None
    mean, longest = float(np.mean(per_run)), max(per_run)
    cpu = runs * mean
    later = LaterRounds(rounds, runs, cpu, cpu / workers + rounds * longest)
    prior, note = campaign_prior(campaign)
    if prior is not None and prior.run_time and planned_runs is not None:
        to_grid = functools.cache(functools.partial(grid_factor, campaign, prior))
        beyond = [
            t * to_grid(key) for (key, seed), t in prior.run_time.items()
            if (key, seed) not in planned_runs
        ]  # fmt: skip
        scaled = {key for key, _ in prior.run_time if to_grid(key) != 1.0}
        seconds = float(sum(beyond))
        later.expected = Expected(
            len(beyond),
            seconds,
            seconds / workers + (rounds * max(beyond) if beyond else 0.0),
            f"{prior.label}: {prior.total} runs in all, {len(beyond)} of them beyond the "
            "runs planned so far, at their measured run times"
            + (
                f" (at {len(scaled)} point(s) on another grid than this campaign's there: "
                "scaled by the cost model)"
                if scaled
                else ""
            ),
        )
    elif prior is not None:
        more = max(0, prior.total - planned)
        later.expected = Expected(
            more,
            more * mean,
            more * mean / workers + (rounds * longest if more else 0.0),
            f"{prior.label}: {prior.total} runs in all, {planned} planned so far",
        )
    later.note = note or (
        ""
        if prior is not None
        else "no expected value: a refinement's rounds are not "
        "forecast from the grid; a prior: (a finished run's phase.nc) gives one"
    )
    return later


def precision_rounds(campaign: Campaign, plan: Any, cost: Any, workers: int) -> LaterRounds | None:
    """The rounds of seeds by precision after the current one: per point, the seeds its
    finished ones forecast, else the prior's, else unknown (see the module docstring); the
    bound every point at the cap. ``cost(point) -> seconds`` of one run."""
    from ..precision.decide import rounds_bound
    from ..precision.forecast import expected_seeds

    cap = plan.cap
    prior, note = campaign_prior(campaign)
    runs = cpu = bound_cpu = longest = biggest = 0.0
    forecast = from_prior = unknown = unknown_runs = 0
    for p, point in enumerate(plan.grid.points):
        planned = plan.decisions[p].n  # the seeds its rounds so far give it
        seconds = cost(point)
        bound_cpu += (cap - planned) * seconds
        biggest = max(biggest, seconds)
        idx = [p * cap + j for j in range(planned)]
        done = [i for i in idx if plan.outcomes.get(i) is not None]
        if done:
            values = [float(plan.outcomes[i]) for i in done]
            classes = [plan.classes.get(i) or () for i in done]
            more = expected_seeds(plan.spec, values, classes, cap, planned) - planned
            forecast += 1
        elif prior is not None and point_key(point.coords) in prior.seeds:
            more = max(0, min(cap, prior.seeds[point_key(point.coords)]) - planned)
            from_prior += 1
            seconds = prior.point_seconds(point.coords) or seconds  # its measured times
        else:
            unknown += 1
            unknown_runs += cap - planned
            continue
        if more > 0:
            runs += more
            cpu += more * seconds
            longest = max(longest, seconds)
    at_most = plan.run_bound() - plan.n_runs
    rounds = rounds_bound(plan.spec, cap) - 1 - plan.current.number
    if at_most <= 0 or rounds <= 0:
        return None
    later = LaterRounds(rounds, at_most, bound_cpu, bound_cpu / workers + rounds * biggest)
    if forecast or from_prior:
        parts = []
        if forecast:
            parts.append(f"forecast from the finished seeds of {forecast} point(s)")
        if from_prior:
            parts.append(f"{from_prior} point(s) from the {prior.label if prior else ''}")
        later.expected = Expected(
            int(runs),
            cpu,
            cpu / workers + rounds * longest if runs else 0.0,
            "; ".join(parts),
            unknown,
            unknown_runs,
        )
    later.note = note or (
        ""
        if later.expected is not None
        else "no expected value: no point has finished seeds yet and there is no prior: "
        "(it is made from the first round's runs)"
    )
    return later
