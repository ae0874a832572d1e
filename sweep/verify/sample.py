"""What a verification runs: the sampled points, their base runs and the variants' runs.

The sample (:func:`plan_sample`): by default both sides of each fitted transition (the grid
bracket of every ``*_grid_lower`` / ``*_grid_upper`` pair in fits.nc, one per line of the
other dims) and the grid's corners; or the selections of ``verify.points`` (with the corners
unless ``corners: false``). Before the grid has fits (``nematic verify --before``), the
corners and the selections only.

At each sampled point the campaign's first ``verify.seeds`` seeds are its **base runs**:
ordinary runs of the campaign (the same run ids as in its grid, stored in its folder, so a
verification before the grid is a head start on it). Each variant reruns the point with its
settings (:func:`nematic_solids.sweep.spec.verify.resolve`) and the same seeds (or its own):
**variant runs**, stored apart in ``results/NAME/verify/`` under their own run ids.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..campaign import Campaign, Variant, VerifySpec, same_value
from ..expand import Expansion, GridPoint, RunSpec
from ..identity import PointHasher
from ..models.interface import setting_error
from ..spec.verify import resolve

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Transition:
    """A fitted transition the sample brackets: the fit's prefix and axis, the other dims'
    values of its line, its location and interval, and the sampled points below and above
    (indices into :attr:`Sample.points`)."""

    prefix: str
    axis: str
    where: Mapping[str, Any]
    location: float
    lower: float
    upper: float
    below: int
    above: int
    log: bool = True
    min_jump: float = 1.0
    observable: str = "sigma2_S"
    mean: str = "geometric"


@dataclass
class Sample:
    """The sampled points (grid points of the campaign), why each was chosen, the seeds, and
    the runs: ``base[i][s]`` the base run of point ``i`` and seed ``s``; ``variant_runs[v][i]``
    the runs of variant ``v`` at point ``i`` (``None`` where the variant is not a valid run
    there, with the reason in :attr:`problems`)."""

    campaign: Campaign
    spec: VerifySpec
    points: list[GridPoint]
    why: list[str]
    seeds: tuple[int, ...]
    base: list[list[RunSpec]]
    variant_runs: list[list[list[RunSpec] | None]]
    transitions: list[Transition] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def variants(self) -> tuple[Variant, ...]:
        return self.spec.variants

    def base_list(self) -> list[RunSpec]:
        return [r for runs in self.base for r in runs]

    def variant_list(self) -> list[RunSpec]:
        seen: dict[str, RunSpec] = {}
        for per_point in self.variant_runs:
            for runs in per_point:
                for r in runs or ():
                    seen.setdefault(r.run_id, r)
        return list(seen.values())


def point_label(point: GridPoint) -> str:
    return ", ".join(
        f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}" for k, v in point.coords.items()
    )


def _matching(expansion: Expansion, where: Mapping[str, Any]) -> list[int]:
    return [
        i
        for i, p in enumerate(expansion.points)
        if all(k not in p.coords or same_value(p.coords[k], v) for k, v in where.items())
    ]


def corner_points(expansion: Expansion) -> list[int]:
    """The grid points at an end of every dim (2^d of them, fewer for one-value dims)."""
    shape = expansion.campaign.shape
    return [
        i
        for i, p in enumerate(expansion.points)
        if all(k in (0, n - 1) for k, n in zip(p.index, shape, strict=True))
    ]


def fitted_transitions(
    fits: Any,
) -> Iterable[tuple[str, str, dict[str, Any], dict[str, float], dict[str, Any]]]:
    """(prefix, axis, other dims' values, {location, lower, upper, grid_lower, grid_upper},
    the fit's options) of every transition in a fits Dataset with a grid bracket."""
    if fits is None:
        return
    for name in fits.data_vars:
        if not str(name).endswith("_grid_lower"):
            continue
        prefix = str(name)[: -len("_grid_lower")]
        attrs = fits[name].attrs
        axis = attrs.get("fit_axis")
        if not axis or f"{prefix}_location" not in fits:
            continue
        lo = fits[name]
        for idx in np.ndindex(*lo.shape):
            sel = dict(zip(lo.dims, idx, strict=True))
            vals = {
                k: float(fits[f"{prefix}_{k}"].isel(sel).values)
                for k in ("location", "lower", "upper", "grid_lower", "grid_upper")
            }
            if not all(math.isfinite(vals[k]) for k in ("grid_lower", "grid_upper")):
                continue
            where = {d: fits[d].values[i].item() for d, i in sel.items() if d in fits.coords}
            yield (
                prefix,
                str(axis),
                where,
                vals,
                {
                    "log": bool(int(attrs.get("fit_log", 1))),
                    "min_jump": float(attrs.get("fit_min_jump", 1.0)),
                    "observable": str(attrs.get("fit_observable", "sigma2_S")),
                    "mean": str(attrs.get("fit_mean", "geometric")),
                },
            )


def plan_sample(campaign: Campaign, expansion: Expansion, fits: Any = None) -> Sample:
    """The sample of ``campaign`` (a ``verify:`` section is required) on its grid
    ``expansion`` (an adaptive campaign's union grid), with the transitions of ``fits`` (the
    fits Dataset, or ``None`` before the grid is run)."""
    spec = campaign.verify
    assert spec is not None
    chosen: dict[int, list[str]] = {}
    transitions: list[
        tuple[str, str, dict[str, Any], dict[str, float], dict[str, Any], int, int]
    ] = []
    if spec.points is None:
        for prefix, axis, where, vals, options in fitted_transitions(fits):
            ends = []
            for side in ("grid_lower", "grid_upper"):
                hit = _matching(expansion, {**where, axis: vals[side]})
                if hit:
                    chosen.setdefault(hit[0], []).append(f"{prefix} {side.split('_')[1]}")
                    ends.append(hit[0])
            if len(ends) == 2:
                transitions.append((prefix, axis, where, vals, options, ends[0], ends[1]))
    else:
        for sel in spec.points:
            for i in _matching(expansion, sel):
                chosen.setdefault(i, []).append("selected")
    if spec.corners:
        for i in corner_points(expansion):
            chosen.setdefault(i, []).append("corner")
    order = sorted(chosen)
    position = {i: k for k, i in enumerate(order)}
    points = [expansion.points[i] for i in order]
    seeds = tuple(campaign.seeds[: spec.seeds])
    n_seeds = len(expansion.seeds)
    base = []
    for i in order:
        first = i * n_seeds
        base.append([expansion.run(first + k) for k in range(len(seeds))])
    sample = Sample(campaign, spec, points, [", ".join(chosen[i]) for i in order], seeds, base, [])
    for variant in spec.variants:
        per_point: list[list[RunSpec] | None] = []
        for point in points:
            try:
                params, numerics = resolve(
                    variant, point.parameters, point.numerics, campaign.model
                )
            except ValueError as exc:
                e = setting_error(exc)
                sample.problems.append(
                    f"variant {variant.name} at {point_label(point)}: "
                    f"{e.name} = {e.value!r}; allowed: {e.allowed}"
                )
                per_point.append(None)
                continue
            vpoint = GridPoint(point.index, point.coords, params, numerics)
            hasher = PointHasher(params.to_dict(), numerics.to_dict(), campaign.model)
            vseeds = variant.seeds if variant.seeds is not None else seeds
            per_point.append(
                [
                    RunSpec(rid, s, vpoint)
                    for rid, s in zip(hasher.many(vseeds), vseeds, strict=True)
                ]
            )
        sample.variant_runs.append(per_point)
    for prefix, axis, where, vals, options, lo, hi in transitions:
        sample.transitions.append(
            Transition(
                prefix,
                axis,
                where,
                vals["location"],
                vals["lower"],
                vals["upper"],
                position[lo],
                position[hi],
                **options,
            )
        )
    return sample
