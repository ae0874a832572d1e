"""The refinement plan: pure functions of the campaign and the outcomes of its runs.

A *line* is one combination of the other sweep dims (their indices, in the campaign's order
without the refined dim); a *point* is ``(line, x)`` with ``x`` a value of the refined axis.
Round 0 is the campaign's grid with the first ``seeds.initial`` seeds. Each later round is
planned from the outcomes of every run of the rounds before it (all finished):

- **seeds**: a point whose outcome is uncertain gets the next ``seeds.add`` of the
  campaign's seeds (up to all of them). Criterion ``fraction``: uncertain when the Wilson
  score interval (``seeds.confidence``) of its patterned fraction is wider than
  ``seeds.max_width``; with the defaults (0.9, 0.6) two seeds that agree are certain, two
  that disagree are not. Criterion ``jump``: uncertain when the confidence interval of the
  mean of log10(observable) over its seeds (normal, 2 z s / sqrt(n)) is wider than
  ``seeds.max_width`` decades, or when it has a single seed.
- **points**: neighbouring points ``a < b`` of a line (those with a classified seed) form a
  boundary cell when, for ``fraction``, their classes differ (no seed patterned: fraction
  <= low; all: >= high; mixed in between) or either is mixed, and for ``jump``, when the
  geometric seed means differ by more than the factor ``jump``. A boundary cell is split at
  its midpoint (normalised to 12 significant digits, as grid values are, so a midpoint
  equal to a grid value is the same run) if both halves are at least ``min_spacing`` wide.

Nothing here reads a file or a clock, and the result does not depend on the order in which
the outcomes are given: the same outcomes give the same plan.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from ..campaign import Campaign, RefineSpec, normalise_float

Line = tuple[int, ...]
Point = tuple[Line, float]
#: A run's outcome: the observable's value; NaN when it cannot be classified (failed runs).
Outcome = float


@dataclass(frozen=True)
class PlannedRun:
    """One run of a round: where (line, x), which seed, and why."""

    line: Line
    x: float
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
            if r.why.startswith("uncertain"):
                seen.setdefault(r.point)
        return list(seen)


def refined_dim(campaign: Campaign) -> int:
    """Index of the refined dim among the campaign's dims."""
    assert campaign.refine is not None
    axis = campaign.refine.axis
    return next(i for i, d in enumerate(campaign.dims) if d.name == axis)


def lines(campaign: Campaign) -> list[Line]:
    """Every combination of the other dims' indices, in C order."""
    k = refined_dim(campaign)
    shape = [len(d) for i, d in enumerate(campaign.dims) if i != k]
    out: list[Line] = [()]
    for n in shape:
        out = [(*line, i) for line in out for i in range(n)]
    return out


def first_round(campaign: Campaign) -> Round:
    """Round 0: every grid point with the first ``seeds.initial`` seeds."""
    spec = _spec(campaign)
    k = refined_dim(campaign)
    xs = campaign.dims[k].axes[0].values
    seeds = campaign.seeds[:spec.initial]
    runs = [PlannedRun(line, float(x), s, "grid") for line in lines(campaign) for x in xs
            for s in seeds]
    return Round(0, tuple(runs))


def wilson(k: int, n: int, confidence: float) -> tuple[float, float]:
    """The Wilson score interval of a fraction ``k / n``."""
    if n <= 0:
        return 0.0, 1.0
    z = statistics.NormalDist().inv_cdf(0.5 + confidence / 2)
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True)
class PointStats:
    """What the seeds of one point say: ``n`` classified seeds; for ``fraction``, ``k``
    patterned and the class (0 none, 1 all, 0.5 mixed); for ``jump``, the mean of log10
    and its interval width."""

    n_run: int
    n: int
    k: int = 0
    cls: float = math.nan
    mean_log: float = math.nan
    width: float = math.nan

    def label(self, criterion: str) -> str:
        if criterion == "fraction":
            return f"{self.k}/{self.n} patterned"
        return f"log10 mean {self.mean_log:.3g} ({self.n} seeds)"


def point_stats(spec: RefineSpec, values: Sequence[Outcome]) -> PointStats:
    """The statistics of one point from its seeds' outcomes (NaN: unclassified)."""
    finite = [v for v in values if math.isfinite(v)]
    n = len(finite)
    if spec.criterion == "fraction":
        assert spec.patterned_above is not None
        k = sum(1 for v in finite if v > spec.patterned_above)
        if n == 0:
            return PointStats(len(values), 0)
        f = k / n
        lo, hi = spec.fraction
        cls = 0.0 if f <= lo else 1.0 if f >= hi else 0.5
        a, b = wilson(k, n, spec.confidence)
        return PointStats(len(values), n, k, cls, width=b - a)
    logs = [math.log10(v) for v in finite if v > 0]
    n = len(logs)
    if n == 0:
        return PointStats(len(values), 0)
    mean = math.fsum(logs) / n
    if n < 2:
        return PointStats(len(values), n, mean_log=mean, width=math.inf)
    z = statistics.NormalDist().inv_cdf(0.5 + spec.confidence / 2)
    sd = math.sqrt(math.fsum((v - mean) ** 2 for v in logs) / (n - 1))
    return PointStats(len(values), n, mean_log=mean, width=2 * z * sd / math.sqrt(n))


def _boundary(spec: RefineSpec, a: PointStats, b: PointStats) -> bool:
    if spec.criterion == "fraction":
        return a.cls != b.cls or a.cls == 0.5 or b.cls == 0.5
    return abs(b.mean_log - a.mean_log) > math.log10(spec.jump)


def _uncertain(spec: RefineSpec, s: PointStats) -> bool:
    return s.n > 0 and s.width > spec.max_width


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def next_round(campaign: Campaign, number: int,
               outcomes: Mapping[Point, Mapping[int, Outcome]]) -> Round:
    """Round ``number`` planned from the outcomes so far: ``outcomes[point][seed]`` for every
    run of the earlier rounds (all finished). An empty round means nothing is left to do."""
    spec = _spec(campaign)
    seeds = campaign.seeds
    by_line: dict[Line, list[float]] = {}
    for line, x in outcomes:
        by_line.setdefault(line, []).append(x)
    runs: list[PlannedRun] = []
    for line in sorted(by_line):
        xs = sorted(by_line[line])
        stats = {x: point_stats(spec, [outcomes[(line, x)][s] for s in
                                       sorted(outcomes[(line, x)], key=seeds.index)])
                 for x in xs}
        for x in xs:
            st = stats[x]
            have = len(outcomes[(line, x)])
            if have < len(seeds) and _uncertain(spec, st):
                extra = seeds[have:have + spec.add]
                what = (f"interval {st.width:.2f} wider than {spec.max_width:g}"
                        if math.isfinite(st.width) else "one seed")
                why = f"uncertain: {st.label(spec.criterion)}, {what}"
                runs.extend(PlannedRun(line, x, s, why) for s in extra)
        classified = [x for x in xs if stats[x].n > 0]
        present = set(xs)
        for a, b in zip(classified, classified[1:], strict=False):
            if not _boundary(spec, stats[a], stats[b]):
                continue
            if (b - a) / 2 < spec.min_spacing * (1 - 1e-9):
                continue
            mid = normalise_float((a + b) / 2)
            if mid in present or not a < mid < b:
                continue
            present.add(mid)
            why = (f"boundary: {spec.axis} {_fmt(a)} ({stats[a].label(spec.criterion)}) | "
                   f"{_fmt(b)} ({stats[b].label(spec.criterion)})")
            runs.extend(PlannedRun(line, mid, s, why) for s in seeds[:spec.initial])
    return Round(number, tuple(runs))


def run_bound(campaign: Campaign) -> int:
    """An upper bound on the campaign's runs: every cell of the grid split to the smallest
    spacing (or as far as the rounds go) and every point run with every seed."""
    spec = _spec(campaign)
    xs = campaign.dims[refined_dim(campaign)].axes[0].values
    return len(lines(campaign)) * points_bound(xs, spec) * len(campaign.seeds)


def points_bound(values: Sequence[float], spec: RefineSpec) -> int:
    """The most points one line can have: its grid values and every midpoint the rounds can
    add down to the smallest spacing."""
    xs = sorted(float(v) for v in values)
    total = len(xs)
    for a, b in zip(xs, xs[1:], strict=False):
        depth = 0
        while depth < spec.rounds and (b - a) / 2 ** (depth + 1) >= spec.min_spacing * (1 - 1e-9):
            depth += 1
        total += 2 ** depth - 1
    return total


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
