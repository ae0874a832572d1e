"""The seeds of each point of an adaptive campaign: how many a new point starts with and, after
a round, which a point gets next and why. Pure functions of the outcomes; seeds are always
the campaign's, in its order (0, 1, 2, ...), so a point's runs are its first seeds.

- Without a ``precision:`` section (``refine.seeds``): the first ``initial``; the next ``add``
  while the point is uncertain (:func:`nematic_solids.sweep.refine.stats.is_uncertain`), up to every
  seed.
- With one: its ``initial``; after each round the point's decision
  (:func:`nematic_solids.sweep.precision.decide.decide`: precise, unanimous, cap or pending) from
  its seeds' outcomes, and the next ``add`` seeds while it is pending. Grid and refined points
  alike.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from ..campaign import Campaign, RefineSpec
from ..precision.decide import Decision, decide
from .stats import Outcome, PointStats, is_uncertain, value_of


def _spec(campaign: Campaign) -> RefineSpec:
    if campaign.refine is None:
        raise ValueError(f"campaign {campaign.name} has no refine: section")
    return campaign.refine


def initial_count(campaign: Campaign) -> int:
    """The seeds a new point (grid or refined) starts with."""
    if campaign.precision is not None:
        return min(campaign.precision.initial, len(campaign.seeds))
    return _spec(campaign).initial


def sources(campaign: Campaign) -> tuple[str, ...] | None:
    """The run scalars an outcome needs (the refine class's, the precision section's value
    and class), or ``None`` when the ``refine:`` observable alone decides (a float outcome)."""
    spec = _spec(campaign)
    own = [t.source for t in spec.thresholds] or [spec.source]
    if campaign.precision is None and len(own) == 1:
        return None
    out = list(own)
    p = campaign.precision
    if p is not None:
        out.append(p.source)
        if p.unanimous is not None:
            out.extend(t.source for t in p.thresholds)
    return tuple(dict.fromkeys(out))


def decision(campaign: Campaign, values: Sequence[Outcome]) -> Decision:
    """A point's decision by the ``precision:`` section from its seeds' outcomes (in seed
    order)."""
    p = campaign.precision
    if p is None:
        raise ValueError(f"campaign {campaign.name} has no precision: section")
    for v in values:
        if not isinstance(v, Mapping):
            raise ValueError("seeds by precision need outcomes by run scalar (sources())")
    obs = [value_of(v, p.source) for v in values]
    classes = [tuple(value_of(v, t.source) for t in p.thresholds) for v in values]
    return decide(p, obs, classes, len(campaign.seeds))


def more_seeds(
    campaign: Campaign, values: Sequence[Outcome], stats: PointStats
) -> tuple[tuple[int, ...], str]:
    """The seeds a point whose first ``len(values)`` seeds ran gets next, and why (none:
    ``()``)."""
    seeds = campaign.seeds
    have = len(values)
    if have >= len(seeds):
        return (), ""
    if campaign.precision is not None:
        d = decision(campaign, values)
        if d.state != "pending":
            return (), ""
        return (
            seeds[have : have + campaign.precision.add],
            f"undecided after {have} seeds: {d.why}",
        )
    spec = _spec(campaign)
    if not is_uncertain(spec, stats):
        return (), ""
    what = (
        f"interval {stats.width:.2f} wider than {spec.max_width:g}"
        if math.isfinite(stats.width)
        else "one seed"
    )
    return seeds[have : have + spec.add], f"uncertain: {stats.label(spec.criterion)}, {what}"
