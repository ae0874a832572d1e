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

from model.parameters import Numerics, Parameters, check_compatible

from .campaign import NUMERICS_TYPES, PARAMETER_TYPES, Campaign
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


def _settings(campaign: Campaign, values: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
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
