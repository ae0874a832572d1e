"""The decision of one point from its seeds' values: pure functions, no file, no clock.

A point's seeds are taken in the campaign's order; after each round the point is:

- ``precise`` when every seed run has a finite value of the observable (a NaN, e.g. a run
  without a peak or a failed run, counts as not precise), there are at least two, and the
  Student-t interval of their mean at ``confidence`` (full width ``2 t s / sqrt(n)``, ``t``
  of ``n - 1`` degrees of freedom) is narrower than ``width`` (times ``|mean|`` when
  ``relative``; a zero mean is never relatively precise);
- else ``unanimous`` when at least ``unanimous`` seeds were run and each has the same
  class: sigma2_S above ``patterned_above`` (patterned) or not, or with ``classes:`` the
  tuple of the thresholds a run is above; a run without a value of one of these observables
  has no class and breaks the unanimity;
- else ``cap`` when every seed of the campaign was run;
- else ``pending``: the next ``add`` seeds are run in the next round.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import lru_cache

from ..campaign import PrecisionSpec

#: The decisions, in the order of their flag values in phase.nc (``seed_decision``).
DECISIONS = ("pending", "precise", "unanimous", "cap")


@lru_cache(maxsize=256)
def t_quantile(confidence: float, dof: int) -> float:
    """The two-sided Student-t quantile of ``confidence`` with ``dof`` degrees of freedom."""
    from scipy.stats import t

    return float(t.ppf(0.5 + confidence / 2, dof))


def interval_width(values: Sequence[float], confidence: float) -> tuple[float, float]:
    """The seed mean of ``values`` (all finite, at least two) and the full width of its
    Student-t confidence interval."""
    n = len(values)
    mean = math.fsum(values) / n
    sd = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1))
    return mean, 2 * t_quantile(confidence, n - 1) * sd / math.sqrt(n)


@dataclass(frozen=True)
class Decision:
    """A point's state after a round: ``state`` one of :data:`DECISIONS`, ``n`` seeds run,
    and why (for the plan file and the messages)."""

    state: str
    n: int
    why: str
    mean: float = math.nan
    width: float = math.nan


def decide(
    spec: PrecisionSpec,
    values: Sequence[float],
    classes: Sequence[float | tuple[float, ...]],
    cap: int,
) -> Decision:
    """The decision of a point whose first ``len(values)`` seeds ran: ``values`` are the
    observable's, ``classes`` the class's observables (sigma2_S; a tuple in the order of
    ``classes:`` for several), both in seed order, NaN where a run has none; ``cap`` is the
    campaign's seed count."""
    n = len(values)
    finite = all(math.isfinite(v) for v in values)
    mean = width = math.nan
    if n >= 2 and finite:
        mean, width = interval_width(values, spec.confidence)
    if spec.width is not None:
        if not finite:
            what = f"{sum(not math.isfinite(v) for v in values)} of {n} seeds without a value"
        elif n < 2:
            what = "one seed"
        else:
            limit = spec.width * abs(mean) if spec.relative else spec.width
            if width < limit:
                return Decision(
                    "precise",
                    n,
                    f"interval {width:.3g} < {limit:.3g} (mean {mean:.4g}, {n} seeds)",
                    mean,
                    width,
                )
            what = f"interval {width:.3g} >= {limit:.3g} (mean {mean:.4g})"
    else:
        what = "no width rule"
    if spec.unanimous is not None and n >= spec.unanimous:
        shared = common_class(spec, classes)
        if shared is not None:
            return Decision(
                "unanimous", n, f"{n} of {n} seeds " + class_name(spec, shared), mean, width
            )
    if n >= cap:
        return Decision("cap", n, f"every seed run ({n}); {what}", mean, width)
    return Decision("pending", n, what, mean, width)


def common_class(
    spec: PrecisionSpec, classes: Sequence[float | tuple[float, ...]]
) -> tuple[bool, ...] | None:
    """The class every seed of ``classes`` has (which of the section's thresholds it is
    above), or ``None`` when they differ, a seed has no class (NaN, a missing value) or there
    is no seed."""
    thresholds = spec.thresholds
    rows = [c if isinstance(c, tuple) else (c,) for c in classes]
    if not rows or not all(
        len(r) == len(thresholds) and all(math.isfinite(x) for x in r) for r in rows
    ):
        return None
    found = {tuple(x > t.above for x, t in zip(r, thresholds, strict=True)) for r in rows}
    return found.pop() if len(found) == 1 else None


def class_name(spec: PrecisionSpec, above: tuple[bool, ...]) -> str:
    """A class in words: patterned or relaxed (sigma2_S), else which thresholds."""
    if not spec.classes:
        return "patterned" if above[0] else "relaxed"
    return ", ".join(
        f"{t.observable} {'>' if a else '<='} {t.above:g}"
        for t, a in zip(spec.classes, above, strict=True)
    )


def counts_text(states: Iterable[str]) -> str:
    """How many points have each decision: ``2 precise, 1 unanimous, 0 cap, 0 pending``."""
    n = Counter(states)
    return ", ".join(f"{n[k]} {k}" for k in DECISIONS[1:] + DECISIONS[:1])


def next_count(spec: PrecisionSpec, decision: Decision, cap: int) -> int:
    """How many seeds the point has after the next round."""
    if decision.state != "pending":
        return decision.n
    return min(decision.n + spec.add, cap)


def rounds_bound(spec: PrecisionSpec, cap: int) -> int:
    """The most rounds a campaign takes: round 0, then one per ``add`` seeds up to the cap."""
    return 1 + max(0, math.ceil((cap - min(spec.initial, cap)) / spec.add))
