"""How many seeds each point of a campaign with seeds by precision is expected to need: the
forecast behind the cost of its later rounds (``nematic run --dry-run``,
:mod:`nematic_solids.sweep.cost.estimate`).

From the seeds a point has finished (in the campaign's order), with ``n`` seeds whose
Student-t interval of the mean is ``w`` wide against the rule's limit ``l``:

- a point the rules have decided (precise, unanimous, every seed run) needs the seeds it has;
- a width rule: the interval narrows as ``t(n - 1) / sqrt(n)`` with a spread that stays
  what it is, so the point is expected to need the fewest ``n' = initial + k add`` (the
  counts the rounds give) with ``w t(n' - 1) sqrt(n) / (t(n - 1) sqrt(n')) < l``, at most the
  cap;
- a ``unanimous`` rule: finished seeds that all share a pattern class are expected to
  stop at ``unanimous`` seeds (the earlier of the two rules counts);
- a point with neither (seeds that disagree on the class, and no interval to project: fewer
  than two finished seeds, or a seed without a value, which is never precise) runs to the
  cap;
- a point without any finished seed: the cap (nothing is known yet).

It is a forecast, not a bound: the bound is every point at the cap.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from ..campaign import PrecisionSpec
from .decide import common_class, decide, interval_width, t_quantile


def round_counts(spec: PrecisionSpec, cap: int) -> list[int]:
    """The seed counts a point can have: ``initial``, then ``+ add`` per round, up to ``cap``."""
    first = min(spec.initial, cap)
    counts = [first]
    while counts[-1] < cap:
        counts.append(min(counts[-1] + spec.add, cap))
    return counts


def expected_seeds(
    spec: PrecisionSpec,
    values: Sequence[float],
    classes: Sequence[float | tuple[float, ...]],
    cap: int,
    planned: int,
) -> int:
    """The seeds a point is expected to end with: ``values`` and ``classes`` of its finished
    seeds (in order, NaN where a run has none), ``planned`` the seeds its rounds so far give
    it (at least as many as finished)."""
    n = len(values)
    if n == 0:
        return cap
    d = decide(spec, values, classes, cap)
    if d.state != "pending":
        return max(planned, d.n)
    finite = all(math.isfinite(v) for v in values)
    counts = [c for c in round_counts(spec, cap) if c >= max(planned, n)]
    best = cap
    if spec.width is not None and finite and n >= 2:
        mean, width = interval_width(values, spec.confidence)
        limit = spec.width * abs(mean) if spec.relative else spec.width
        spread = width * math.sqrt(n) / t_quantile(spec.confidence, n - 1)
        best = next(
            (
                m
                for m in counts
                if m >= 2
                and limit > 0
                and spread * t_quantile(spec.confidence, m - 1) / math.sqrt(m) < limit
            ),
            cap,
        )
    if spec.unanimous is not None and common_class(spec, classes) is not None:
        best = min(best, next((m for m in counts if m >= spec.unanimous), cap))
    return best
