"""What the seeds of one point of an adaptive campaign say: pure functions of their outcomes.

A run's *outcome* is the value of the ``refine:`` section's observable (a float), or, when
the campaign needs several run scalars (``classes:`` of several observables, or a
``precision:`` section), a mapping run scalar -> value. NaN (or a missing scalar) means the
run cannot be classified (a failed run).

- Criterion ``fraction``: for each threshold of the class (one: ``observable`` above
  ``patterned_above``; several: ``classes:``), the seeds above it out of the classified
  seeds (those with a value of every observable of the class), and that observable's class:
  0 (fraction <= ``fraction[0]``), 1 (>= ``fraction[1]``) or 0.5 (mixed). The point's class
  is the tuple of these; it is mixed when any of them is. Uncertain: a Wilson score interval
  (``seeds.confidence``) of one of the fractions is wider than ``seeds.max_width``.
- Criterion ``jump``: the mean of log10(observable) over the seeds and the width of its
  normal interval (2 z s / sqrt(n)); uncertain when wider than ``seeds.max_width`` decades,
  or with one seed.

A cell between two points is a boundary when, for ``fraction``, their classes differ or
either is mixed, and for ``jump``, when the geometric seed means differ by more than the
factor ``jump``.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from ..campaign import RefineSpec

#: A run's outcome (see the module docstring).
Outcome = float | Mapping[str, float]


def value_of(outcome: Outcome, source: str) -> float:
    """The value of the run scalar ``source`` in ``outcome`` (NaN when it has none); a float
    outcome is the value of the ``refine:`` section's own observable."""
    if isinstance(outcome, Mapping):
        v = outcome.get(source)
        return math.nan if v is None else float(v)
    return float(outcome)


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
    """What the seeds of one point say: ``n`` classified seeds of ``n_run``; for ``fraction``,
    per threshold of the class the seeds above it (``ks``) and the class (``classes``: 0
    none, 1 all, 0.5 mixed); for ``jump``, the mean of log10 and its interval width."""

    n_run: int
    n: int
    ks: tuple[int, ...] = ()
    classes: tuple[float, ...] = ()
    mean_log: float = math.nan
    width: float = math.nan
    #: the observables of the class and their thresholds, for the label
    names: tuple[tuple[str, float], ...] = ()

    @property
    def mixed(self) -> bool:
        return 0.5 in self.classes

    def label(self, criterion: str) -> str:
        if criterion != "fraction":
            return f"log10 mean {self.mean_log:.3g} ({self.n} seeds)"
        if len(self.ks) == 1:
            return f"{self.ks[0]}/{self.n} patterned"
        return ", ".join(
            f"{k}/{self.n} {name} > {above:g}"
            for k, (name, above) in zip(self.ks, self.names, strict=True)
        )


def point_stats(spec: RefineSpec, values: Sequence[Outcome]) -> PointStats:
    """The statistics of one point from its seeds' outcomes."""
    if spec.criterion == "fraction":
        thresholds = spec.thresholds
        names = tuple((t.observable, t.above) for t in thresholds)
        rows = [[value_of(v, t.source) for t in thresholds] for v in values]
        rows = [r for r in rows if all(math.isfinite(x) for x in r)]
        n = len(rows)
        if n == 0:
            return PointStats(len(values), 0, names=names)
        ks = tuple(sum(1 for r in rows if r[i] > t.above) for i, t in enumerate(thresholds))
        lo, hi = spec.fraction
        classes = tuple(0.0 if k / n <= lo else 1.0 if k / n >= hi else 0.5 for k in ks)
        width = max(b - a for a, b in (wilson(k, n, spec.confidence) for k in ks))
        return PointStats(len(values), n, ks, classes, width=width, names=names)
    logs = [
        math.log10(x)
        for x in (value_of(v, spec.source) for v in values)
        if math.isfinite(x) and x > 0
    ]
    n = len(logs)
    if n == 0:
        return PointStats(len(values), 0)
    mean = math.fsum(logs) / n
    if n < 2:
        return PointStats(len(values), n, mean_log=mean, width=math.inf)
    z = statistics.NormalDist().inv_cdf(0.5 + spec.confidence / 2)
    sd = math.sqrt(math.fsum((v - mean) ** 2 for v in logs) / (n - 1))
    return PointStats(len(values), n, mean_log=mean, width=2 * z * sd / math.sqrt(n))


def is_boundary(spec: RefineSpec, a: PointStats, b: PointStats) -> bool:
    """Whether the cell between two classified points is a boundary."""
    if spec.criterion == "fraction":
        return a.classes != b.classes or a.mixed or b.mixed
    return abs(b.mean_log - a.mean_log) > math.log10(spec.jump)


def is_uncertain(spec: RefineSpec, s: PointStats) -> bool:
    """Whether a point wants more seeds by the ``refine.seeds`` rule."""
    return s.n > 0 and s.width > spec.max_width
