"""The refinement plan: pure functions of the campaign and the outcomes of its runs.

A *line* is one combination of the dims that are not refined (their indices, in the
campaign's order); a *point* is ``(line, x)`` with ``x`` its refined values: a float when one
axis is refined, else a tuple (one value per refined axis, in the campaign's order of dims).
Round 0 is the campaign's grid with the first seeds
(:func:`nematic_solids.sweep.refine.seeds.initial_count`). Each later round is planned from the
outcomes of every run of the rounds before it (all finished):

- **seeds**: a point gets the next seeds by :func:`nematic_solids.sweep.refine.seeds.more_seeds`
  (the ``refine.seeds`` interval rule, or the ``precision:`` section's decision);
- **points**: along each refined axis, the points of a line that share their other refined
  values, in order (those with a classified seed), form cells. A boundary cell
  (:func:`nematic_solids.sweep.refine.stats.is_boundary`: the classes differ or either point is
  mixed; or the geometric seed mean jumps) is split at its midpoint, the geometric one on a ``log``
  axis, normalised to 12 significant digits as grid values are (so a midpoint equal to a grid value
  is the same run), if both halves are at least the axis's ``min_spacing`` wide (in decades on a log
  axis). A refined point starts cells along another axis once points beside it on that axis exist.

Points are split in rounds ``1 .. rounds``; with a ``precision:`` section later rounds only
add seeds (``split=False``) until every point is decided.

Nothing here reads a file or a clock, and the result does not depend on the order in which
the outcomes are given: the same outcomes give the same plan.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..campaign import Campaign, RefinedAxis, RefineSpec, normalise_float
from ..spec.refine import points_bound
from .seeds import initial_count, more_seeds
from .stats import Outcome, PointStats, is_boundary, point_stats, wilson

__all__ = [
    "Line",
    "Outcome",
    "PlannedRun",
    "Point",
    "PointStats",
    "Round",
    "first_round",
    "lines",
    "merge_index",
    "midpoint",
    "next_round",
    "point_at",
    "points_bound",
    "points_of",
    "refined_dims",
    "run_bound",
    "values_at",
    "wilson",
]

Line = tuple[int, ...]
#: The refined values of a point: a float (one refined axis) or a tuple of floats (several);
#: typed ``Any`` so that a one-axis campaign's points compare with floats as they are.
At = Any
Point = tuple[Line, At]


def values_at(x: At) -> tuple[float, ...]:
    """The refined values of ``x`` as a tuple."""
    return tuple(x) if isinstance(x, tuple) else (float(x),)


def point_at(values: Sequence[float]) -> At:
    """A point's refined values as the plan holds them: a float for one refined axis."""
    return float(values[0]) if len(values) == 1 else tuple(float(v) for v in values)


@dataclass(frozen=True)
class PlannedRun:
    """One run of a round: where (line, x), which seed, and why."""

    line: Line
    x: At
    seed: int
    why: str

    @property
    def point(self) -> Point:
        return (self.line, self.x)


@dataclass(frozen=True)
class Round:
    number: int
    runs: tuple[PlannedRun, ...]

    @property
    def new_points(self) -> list[Point]:
        """Points first run in this round (with their first seed)."""
        seen: dict[Point, None] = {}
        for r in self.runs:
            if r.why.startswith(("grid", "boundary")):
                seen.setdefault(r.point)
        return list(seen)

    @property
    def seeded_points(self) -> list[Point]:
        """Points that got more seeds in this round."""
        seen: dict[Point, None] = {}
        for r in self.runs:
            if r.why.startswith(("uncertain", "undecided")):
                seen.setdefault(r.point)
        return list(seen)


def refined_dims(campaign: Campaign) -> tuple[int, ...]:
    """Indices of the refined dims among the campaign's dims, in order."""
    names = set(_spec(campaign).names)
    return tuple(i for i, d in enumerate(campaign.dims) if d.name in names)


def merge_index(ks: Sequence[int], line: Line, refined: Sequence[int]) -> tuple[int, ...]:
    """The full index of a point: ``refined`` at the refined dims ``ks``, ``line`` elsewhere."""
    out: list[int] = []
    it, jt = iter(line), iter(refined)
    for i in range(len(line) + len(refined)):
        out.append(next(jt) if i in ks else next(it))
    return tuple(out)


def lines(campaign: Campaign) -> list[Line]:
    """Every combination of the other dims' indices, in C order."""
    ks = refined_dims(campaign)
    shape = [len(d) for i, d in enumerate(campaign.dims) if i not in ks]
    out: list[Line] = [()]
    for n in shape:
        out = [(*line, i) for line in out for i in range(n)]
    return out


def grid_values(campaign: Campaign) -> list[tuple[float, ...]]:
    """Every combination of the refined axes' grid values, in C order."""
    axes = [campaign.dims[k].axes[0].values for k in refined_dims(campaign)]
    return [tuple(float(v) for v in vs) for vs in itertools.product(*axes)]


def first_round(campaign: Campaign) -> Round:
    """Round 0: every grid point with its first seeds."""
    seeds = campaign.seeds[: initial_count(campaign)]
    runs = [
        PlannedRun(line, point_at(vs), s, "grid")
        for line in lines(campaign)
        for vs in grid_values(campaign)
        for s in seeds
    ]
    return Round(0, tuple(runs))


def midpoint(axis: RefinedAxis, a: float, b: float) -> float | None:
    """The midpoint of the cell ``a < b`` of ``axis`` (geometric on a log axis), normalised;
    ``None`` when a half would be narrower than the axis's smallest spacing."""
    width = math.log10(b / a) if axis.log else b - a
    if width / 2 < axis.min_spacing * (1 - 1e-9):
        return None
    mid = normalise_float(math.sqrt(a) * math.sqrt(b) if axis.log else (a + b) / 2)
    return mid if a < mid < b else None


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def next_round(
    campaign: Campaign,
    number: int,
    outcomes: Mapping[Point, Mapping[int, Outcome]],
    *,
    split: bool = True,
) -> Round:
    """Round ``number`` planned from the outcomes so far: ``outcomes[point][seed]`` for every
    run of the earlier rounds (all finished). ``split=False``: seeds only, no new points. An
    empty round means nothing is left to do."""
    spec = _spec(campaign)
    seeds = campaign.seeds
    first = seeds[: initial_count(campaign)]
    by_line: dict[Line, list[tuple[float, ...]]] = {}
    for line, x in outcomes:
        by_line.setdefault(line, []).append(values_at(x))
    runs: list[PlannedRun] = []
    for line in sorted(by_line):
        pts = sorted(by_line[line])
        ordered = {
            v: [
                outcomes[(line, point_at(v))][s]
                for s in sorted(outcomes[(line, point_at(v))], key=seeds.index)
            ]
            for v in pts
        }
        stats = {v: point_stats(spec, ordered[v]) for v in pts}
        for v in pts:
            extra, why = more_seeds(campaign, ordered[v], stats[v])
            runs.extend(PlannedRun(line, point_at(v), s, why) for s in extra)
        if not split:
            continue
        present = set(pts)
        for a, axis in enumerate(spec.axes):
            along: dict[tuple[float, ...], list[tuple[float, ...]]] = {}
            for v in pts:  # sorted: each group is in the order of axis a
                along.setdefault(v[:a] + v[a + 1 :], []).append(v)
            for key in sorted(along):
                classified = [v for v in along[key] if stats[v].n > 0]
                for p, q in zip(classified, classified[1:], strict=False):
                    if not is_boundary(spec, stats[p], stats[q]):
                        continue
                    mid = midpoint(axis, p[a], q[a])
                    new = (*p[:a], mid, *p[a + 1 :]) if mid is not None else None
                    if new is None or new in present:
                        continue
                    present.add(new)
                    why = (
                        f"boundary: {axis.name} {_fmt(p[a])} "
                        f"({stats[p].label(spec.criterion)}) | {_fmt(q[a])} "
                        f"({stats[q].label(spec.criterion)})"
                    )
                    runs.extend(PlannedRun(line, point_at(new), s, why) for s in first)
    return Round(number, tuple(runs))


def run_bound(campaign: Campaign) -> int:
    """An upper bound on the campaign's runs: every cell of the grid split to the smallest
    spacing (or as far as the rounds go) along every refined axis, and every point of that
    union grid run with every seed."""
    spec = _spec(campaign)
    per_axis = [
        points_bound(campaign.dims[k].axes[0].values, axis, spec.rounds)
        for k, axis in zip(refined_dims(campaign), spec.axes, strict=True)
    ]
    return len(lines(campaign)) * math.prod(per_axis) * len(campaign.seeds)


def _spec(campaign: Campaign) -> RefineSpec:
    spec = campaign.refine
    if spec is None:
        raise ValueError(f"campaign {campaign.name} has no refine: section")
    return spec


def points_of(rounds: Iterable[Round]) -> dict[Point, list[int]]:
    """Every point of ``rounds`` with its seeds, in the order they were planned."""
    out: dict[Point, list[int]] = {}
    for rnd in rounds:
        for r in rnd.runs:
            out.setdefault(r.point, []).append(r.seed)
    return out
