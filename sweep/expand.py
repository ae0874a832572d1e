"""Campaign -> grid points -> runs (and, for a campaign whose runs begin from another
campaign's, ``initial: {from: ...}``, the parent run of each: :class:`Parents`).

The grid is the product of the campaign's dims (a zip group is one dim); every grid point is
run once per seed. Runs are numbered point-major: run ``i`` is point ``i // n_seeds`` with seed
``seeds[i % n_seeds]``, and the point's multi-index is ``np.unravel_index(point, shape)``.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .campaign import Campaign, InitialSpec, same_value
from .chains import chain_parents, in_chain_order
from .identity import PointHasher, hash_canonical, identity_start, start_state, trajectory_id
from .models.registry import get_model
from .protocols import with_axis_values
from .settings import setting_names

log = logging.getLogger(__name__)

#: At most this many distinct problems are reported from the grid check.
MAX_POINT_PROBLEMS = 20


@dataclass(frozen=True)
class GridPoint:
    """One point of the grid: its multi-index, the swept values and the model's objects of
    its settings (:meth:`~nematic_solids.sweep.models.interface.Model.point`)."""

    index: tuple[int, ...]
    coords: dict[str, Any]
    parameters: Any
    numerics: Any


@dataclass(frozen=True)
class RunSpec:
    """One (grid point, seed) run."""

    run_id: str
    seed: int
    point: GridPoint
    #: where the run begins (``initial.from``): the parent run's ``run`` id, its ``time``
    #: ("end" or the time) and its ``campaign``; None: the seeded texture
    start: dict[str, str] | None = None

    @property
    def coords(self) -> dict[str, Any]:
        return {**self.point.coords, "seed": self.seed}


def _settings(campaign: Campaign, values: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    params = dict(campaign.parameters)
    numerics = dict(campaign.numerics)
    names = setting_names(campaign.model)
    for name, value in values.items():
        if name in names.parameters:
            params[name] = value
        elif name in names.numerics:
            numerics[name] = value
    with_axis_values(params, values)  # the protocol's swept numbers
    return params, numerics


def iter_points(campaign: Campaign) -> Iterator[tuple[tuple[int, ...], dict[str, Any]]]:
    """(multi-index, {axis: value}) of every grid point, in C order."""
    for index in itertools.product(*(range(len(d)) for d in campaign.dims)):
        coords: dict[str, Any] = {}
        for d, i in zip(campaign.dims, index, strict=True):
            for axis in d.axes:
                coords[axis.name] = axis.values[i]
        yield index, coords


def make_point(campaign: Campaign, index: tuple[int, ...], coords: dict[str, Any]) -> GridPoint:
    params, numerics = _settings(campaign, coords)
    parameters, nums = get_model(campaign.model).point(params, numerics)
    return GridPoint(index, coords, parameters, nums)


class Parents:
    """The parent run (its run id, position in the parent's expansion) of each run of a
    campaign with ``initial.from``: the parent campaign's grid point whose swept values are
    the ones ``point`` pins, the others the child's own values of the same name, and the seed
    ``seed`` (``same``: the child's own). The child's run id includes the parent run's id and
    the time (:func:`nematic_solids.sweep.identity.hash_canonical`'s ``start``), so a child of
    another parent, or of another time, is another run; and, where it does not begin from the
    parent's exact end state or a float64 snapshot of all fields (the parent keeps no end
    state, or float32 or fewer snapshot fields), what it begins from (``state``)."""

    def __init__(self, spec: InitialSpec, parent: Expansion):
        self.spec, self.parent = spec, parent
        store = parent.campaign.store
        #: what the children begin from when it is not the exact end state (or "":
        #: :func:`nematic_solids.sweep.run.continuation.start_state`), part of their ids
        self.state = start_state(
            spec.time_text, store.end_state, store.snapshot_dtype, store.snapshot_fields
        )

    def of(self, point: GridPoint, seeds: Sequence[int]) -> list[str]:
        """The parent run ids of the child runs at ``point`` with ``seeds``; ``KeyError``
        naming the value or seed that has no parent."""
        campaign = self.parent.campaign
        position = 0  # of the parent point, in C order (Expansion's point order)
        for dim in campaign.dims:
            values = [self.value(axis.name, point.coords) for axis in dim.axes]
            found = next(
                (
                    i
                    for i in range(len(dim))
                    if all(
                        same_value(a.values[i], v) for a, v in zip(dim.axes, values, strict=True)
                    )
                ),
                None,
            )
            if found is None:
                names = ", ".join(
                    f"{a.name} = {v!r}" for a, v in zip(dim.axes, values, strict=True)
                )
                raise KeyError(f"campaign {campaign.name} has no point with {names}")
            position = position * len(dim) + found
        out = []
        for seed in seeds:
            parent_seed = seed if self.spec.seed is None else self.spec.seed
            if parent_seed not in campaign.seeds:
                raise KeyError(f"campaign {campaign.name} has no seed {parent_seed}")
            out.append(
                self.parent.run_ids[
                    position * len(campaign.seeds) + campaign.seeds.index(parent_seed)
                ]
            )
        return out

    def value(self, name: str, coords: Mapping[str, Any]) -> Any:
        """The parent axis ``name``'s value for a child point: pinned, else the child's."""
        if name in self.spec.point:
            return self.spec.point[name]
        if name in coords:
            return coords[name]
        raise KeyError(f"the parent's axis {name} is neither pinned in 'point' nor swept here")


class Expansion:
    """Every run of a campaign with its run_id (built once; cheap for 10^5 runs)."""

    #: where each run begins (campaigns with ``initial.from``): ``{"run": the parent run's
    #: id, "time": "end" or the time}``, else None (the seeded texture); class-level defaults
    #: for the expansions of adaptive campaigns, which build their runs otherwise
    starts: list[dict[str, str]] | None = None
    parents: Parents | None = None
    #: where each run of a chain begins, its predecessor's ``run`` id and ``time`` ("end"),
    #: or None for the first run of a branch
    chain_starts: list[dict[str, str] | None] = []

    def __init__(self, campaign: Campaign):
        self.campaign = campaign
        self.seeds = campaign.seeds
        self.points: list[GridPoint] = []
        self.run_ids: list[str] = []
        self.starts = None
        #: each run's predecessor in its chain (``chain:``, nematic_solids.sweep.chains), else None
        self.chain_parents: list[int | None] = chain_parents(campaign)
        parents = None
        if campaign.chain is not None:
            self._chain_runs(campaign)
        elif campaign.initial is not None:
            parents, self.starts = Parents(campaign.initial, Expansion(campaign.initial.parent)), []
        for index, coords in iter_points(campaign) if campaign.chain is None else ():
            point = make_point(campaign, index, coords)
            self.points.append(point)
            if parents is None or self.starts is None:
                hasher = PointHasher(
                    point.parameters.to_dict(), point.numerics.to_dict(), campaign.model
                )
                self.run_ids.extend(hasher.many(self.seeds))
                continue
            p, n = point.parameters.to_dict(), point.numerics.to_dict()
            for seed, parent_id in zip(self.seeds, parents.of(point, self.seeds), strict=True):
                start = {"run": parent_id, "time": parents.spec.time_text}
                if parents.state:  # not the exact end state: another id (and a warning)
                    start["state"] = parents.state
                self.starts.append(start)
                self.run_ids.append(hash_canonical(p, n, seed, start, campaign.model))
        self.parents = parents
        self.position: dict[str, int] = {}  # each run's first position
        for i, rid in enumerate(self.run_ids):
            self.position.setdefault(rid, i)
        twins = campaign.chain is not None and campaign.chain.up == "fresh"  # by design
        if len(self.position) != len(self.run_ids) and not twins:
            # Two grid points that normalise to the same run (e.g. alpha and alpha_minus_B
            # values that coincide) would share one file: that is a campaign mistake.
            dup = next(r for i, r in enumerate(self.run_ids) if self.position[r] != i)
            first = self.run(self.position[dup])
            log.warning("grid points collapse onto one run (%s at %s)", dup, first.coords)

    def _chain_runs(self, campaign: Campaign) -> None:
        """The points and run ids of a chain: each run after the first of its branch starts
        from its predecessor's end state, whose id its own includes."""
        n = len(self.seeds)
        self.points = [make_point(campaign, index, c) for index, c in iter_points(campaign)]
        ids: list[str] = [""] * (len(self.points) * n)
        starts: list[dict[str, str] | None] = [None] * len(ids)
        for i in in_chain_order(range(len(ids)), self.chain_parents):
            point, parent = self.points[i // n], self.chain_parents[i]
            p, num = point.parameters.to_dict(), point.numerics.to_dict()
            starts[i] = None if parent is None else {"run": ids[parent], "time": "end"}
            ids[i] = hash_canonical(p, num, self.seeds[i % n], starts[i], campaign.model)
        self.run_ids, self.chain_starts = ids, starts

    def __len__(self) -> int:
        return len(self.run_ids)

    def run(self, i: int) -> RunSpec:
        n = len(self.seeds)
        start = None
        if self.starts is not None and self.campaign.initial is not None:
            start = {**self.starts[i], "campaign": self.campaign.initial.parent.name}
        elif self.campaign.chain is not None and (chained := self.chain_starts[i]) is not None:
            start = {**chained, "campaign": self.campaign.name}
        return RunSpec(self.run_ids[i], self.seeds[i % n], self.points[i // n], start)

    def __iter__(self) -> Iterator[RunSpec]:
        return (self.run(i) for i in range(len(self)))

    def by_point(self) -> Iterator[tuple[GridPoint, list[str], list[int]]]:
        """Each point with its runs' ids and seeds, in run order (what iterating the runs
        gives, grouped by point, without a ``RunSpec`` per run)."""
        n = len(self.seeds)
        for k, point in enumerate(self.points):
            yield point, self.run_ids[k * n : (k + 1) * n], list(self.seeds)


def continued_runs(
    expansion: Expansion, todo: list[int], records: Mapping[str, Any]
) -> dict[int, tuple[str, float]]:
    """For each run to do (positions ``todo``), the finished run of its trajectory it
    continues, and how far that run went: the one with an end state (ok, ``end_state``
    recorded) that reached furthest below the run's ``t_final`` (``records``: the store's)."""
    ends: dict[str, list[tuple[float, str]]] = {}
    for rid, rec in records.items():
        t_end, traj = rec.get("end_state"), rec.get("trajectory")
        if rec.get("status") == "ok" and isinstance(t_end, (int, float)) and traj:
            ends.setdefault(str(traj), []).append((float(t_end), rid))
    if not ends:
        return {}
    out: dict[int, tuple[str, float]] = {}
    for i in todo:
        run = expansion.run(i)
        numerics = run.point.numerics
        start = identity_start(run.start)
        traj = trajectory_id(
            run.point.parameters.to_dict(),
            numerics.to_dict(),
            run.seed,
            start,
            expansion.campaign.model,
        )
        shorter = [e for e in ends.get(traj, ()) if e[0] < numerics.t_final and e[1] != run.run_id]
        if shorter:
            t_end, rid = max(shorter)
            out[i] = (rid, t_end)
    return out


def expand(campaign: Campaign) -> Expansion:
    return Expansion(campaign)
