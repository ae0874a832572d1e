"""Campaign -> grid points -> runs.

The grid is the product of the campaign's dims (a zip group is one dim); every grid point is
run once per seed. Runs are numbered point-major: run ``i`` is point ``i // n_seeds`` with seed
``seeds[i % n_seeds]``, and the point's multi-index is ``np.unravel_index(point, shape)``.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from model.errors import ParameterError
from model.parameters import Numerics, Parameters, check_compatible

from .campaign import AMB, NUMERICS_TYPES, PARAMETER_TYPES, Campaign
from .checker import Checker
from .identity import PointHasher

log = logging.getLogger(__name__)

#: At most this many distinct problems are reported from the grid check.
MAX_POINT_PROBLEMS = 20


@dataclass(frozen=True)
class GridPoint:
    """One point of the grid: its multi-index, the swept values and the model's objects."""

    index: tuple[int, ...]
    coords: dict[str, Any]
    parameters: Parameters
    numerics: Numerics


@dataclass(frozen=True)
class RunSpec:
    """One (grid point, seed) run."""

    run_id: str
    seed: int
    point: GridPoint

    @property
    def coords(self) -> dict[str, Any]:
        return {**self.point.coords, "seed": self.seed}


def _settings(campaign: Campaign, values: dict[str, Any]) -> tuple[dict[str, Any],
                                                                      dict[str, Any]]:
    params = dict(campaign.parameters)
    numerics = dict(campaign.numerics)
    for name, value in values.items():
        if name in PARAMETER_TYPES:
            params[name] = value
        elif name in NUMERICS_TYPES:
            numerics[name] = value
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
    point = GridPoint(index, coords, Parameters.from_dict(params), Numerics.from_dict(numerics))
    check_compatible(point.parameters, point.numerics)
    return point


def check_points(campaign: Campaign, checker: Checker) -> None:
    """Build the model's objects at every grid point; report each distinct
    :class:`~model.errors.ParameterError` at the key path that caused it."""
    axis_names = {a.name for a in campaign.axes}
    seen: set[tuple[str, str]] = set()
    for index, coords in iter_points(campaign):
        try:
            make_point(campaign, index, coords)
        except ParameterError as e:
            name = e.name
            if name == "alpha" and AMB in axis_names:
                name = AMB
            if name in axis_names:
                path: tuple[str | int, ...] = ("sweep", "axes", name)
                at = ", ".join(f"{k}={v!r}" for k, v in coords.items())
                msg = f"got {e.value!r}; allowed: {e.allowed} (at the grid point {at})"
            elif name in campaign.numerics:
                path, msg = ("numerics", name), f"got {e.value!r}; allowed: {e.allowed}"
            elif name in campaign.parameters:
                path, msg = ("parameters", name), f"got {e.value!r}; allowed: {e.allowed}"
            else:
                path, msg = (name,), f"got {e.value!r}; allowed: {e.allowed}"
            key = (repr(path), e.allowed)
            if key in seen:
                continue
            seen.add(key)
            checker.add(path, msg)
            if len(seen) >= MAX_POINT_PROBLEMS:
                checker.add((), "further grid problems not shown")
                return


class Expansion:
    """Every run of a campaign with its run_id (built once; cheap for 10^5 runs)."""

    def __init__(self, campaign: Campaign):
        self.campaign = campaign
        self.seeds = campaign.seeds
        self.points: list[GridPoint] = []
        self.run_ids: list[str] = []
        for index, coords in iter_points(campaign):
            point = make_point(campaign, index, coords)
            self.points.append(point)
            hasher = PointHasher(point.parameters.to_dict(), point.numerics.to_dict())
            self.run_ids.extend(hasher.many(self.seeds))
        self.position = {rid: i for i, rid in enumerate(self.run_ids)}
        if len(self.position) != len(self.run_ids):
            # Two grid points that normalise to the same run (e.g. alpha and alpha_minus_B
            # values that coincide) would share one file: that is a campaign mistake.
            dup = next(r for i, r in enumerate(self.run_ids) if self.position[r] != i)
            first = self.run(self.position[dup])
            log.warning("grid points collapse onto one run (%s at %s)", dup, first.coords)

    def __len__(self) -> int:
        return len(self.run_ids)

    def run(self, i: int) -> RunSpec:
        n = len(self.seeds)
        return RunSpec(self.run_ids[i], self.seeds[i % n], self.points[i // n])

    def __iter__(self) -> Iterator[RunSpec]:
        return (self.run(i) for i in range(len(self)))


def expand(campaign: Campaign) -> Expansion:
    return Expansion(campaign)
