"""The text that ``nematic run``, ``validate`` and ``status`` print about a refined
campaign's rounds (plain lines: the commands print them literally)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .plan import first_round, points_of, run_bound
from .seeds import initial_count

if TYPE_CHECKING:
    from ..campaign import Campaign, RefinedAxis, RefineSpec
    from .rounds import Refinement

#: Points listed per round (the plan file has them all).
MAX_LINES = 12


def _value(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _where(coords: dict[str, Any]) -> str:
    return ", ".join(f"{k}={_value(v)}" for k, v in coords.items())


def _spacing(spec: RefineSpec) -> str:
    def one(a: RefinedAxis) -> str:
        return f"{a.min_spacing:g}" + (" decades (geometric midpoints)" if a.log else "")

    if len(spec.axes) == 1:
        return f"smallest spacing {one(spec.axes[0])}"
    return "smallest spacing " + ", ".join(f"{a.name} {one(a)}" for a in spec.axes)


def spec_line(campaign: Campaign) -> str:
    spec = campaign.refine
    assert spec is not None
    thresholds = spec.thresholds
    if spec.criterion == "fraction" and len(thresholds) == 1:
        one = thresholds[0]
        rule = (
            f"patterned when {one.observable} > {one.above:g}; a point is mixed when its "
            f"patterned fraction lies in ({spec.fraction[0]:g}, {spec.fraction[1]:g})"
        )
    elif spec.criterion == "fraction":
        rule = (
            "a run's class is which of "
            + ", ".join(f"{t.observable} > {t.above:g}" for t in thresholds)
            + " hold; a point is mixed when the fraction of its seeds above one of these "
            f"lies in ({spec.fraction[0]:g}, {spec.fraction[1]:g})"
        )
    else:
        rule = f"a cell whose geometric seed mean of {spec.observable} changes by > {spec.jump:g}x"
    if campaign.precision is not None:
        seeds = "seeds by precision at every point (below)"
    elif spec.initial < len(campaign.seeds):
        seeds = (
            f"seeds {spec.initial} per new point, +{spec.add} where uncertain up to "
            f"{len(campaign.seeds)}"
        )
    else:
        seeds = f"all {len(campaign.seeds)} seeds at every point"
    return (
        f"refine {', '.join(spec.names)}: {rule}; at most {spec.rounds} round(s) after the "
        f"grid, {_spacing(spec)}; {seeds}"
    )


def validation_lines(campaign: Campaign) -> list[str]:
    """What ``nematic validate`` prints for a refined campaign: the rule(s), the first
    round's plan and an upper bound on the run count."""
    spec = campaign.refine
    assert spec is not None
    first = first_round(campaign)
    points = points_of([first])
    out = [spec_line(campaign)]
    if campaign.precision is not None:
        from ..precision.decide import rounds_bound
        from ..precision.rounds import spec_line as precision_line

        extra = rounds_bound(campaign.precision, len(campaign.seeds)) - 1
        out.append(
            precision_line(campaign) + f" (rounds that only add seeds follow the "
            f"refinement's, at most {extra} more)"
        )
    n = initial_count(campaign)
    return [
        *out,
        f"round 0 (the grid): {len(points)} points x {n} seed(s) = "
        f"{len(first.runs)} runs; later rounds are planned from the results",
        f"runs: at most {run_bound(campaign)} (every cell split down to the smallest "
        f"spacing, once per round, and every point run with all {len(campaign.seeds)} "
        "seeds)",
    ]


def round_lines(ref: Refinement, number: int) -> list[str]:
    """A round's plan: how many runs, new points and seeds, and where and why (the first
    :data:`MAX_LINES` points; ``refine.json`` in the results folder lists every run)."""
    rnd = ref.rounds[number]
    namer = ref.namer
    assert namer is not None
    if number == 0:
        return [f"round 0 (the grid): {len(rnd.new_points)} points, {len(rnd.runs)} runs"]
    out = [
        f"round {number}: {len(rnd.runs)} runs: {len(rnd.new_points)} new point(s), "
        f"{len(rnd.seeded_points)} point(s) with more seeds"
    ]
    shown: dict[tuple[Any, ...], tuple[str, list[int]]] = {}
    for r in rnd.runs:
        shown.setdefault(r.point, (r.why, []))[1].append(r.seed)
    for i, ((line, x), (why, seeds)) in enumerate(shown.items()):
        if i == MAX_LINES:
            out.append(f"  ... and {len(shown) - MAX_LINES} more (refine.json lists every run)")
            break
        out.append(f"  {_where(namer.coords(line, x))}: seeds {', '.join(map(str, seeds))}: {why}")
    return out


def status_lines(ref: Refinement) -> list[str]:
    """What ``nematic status`` adds for a refined campaign: one line per round (and the
    decisions, with seeds by precision)."""
    if hasattr(ref, "status_lines"):  # seeds by precision (sweep/precision)
        return list(ref.status_lines())
    out = [spec_line(ref.campaign)]
    for rnd in ref.rounds:
        pending = sum(1 for r in rnd.runs if ref.outcomes.get((r.line, r.x, r.seed)) is None)
        out.append(
            f"round {rnd.number}: {len(rnd.runs)} runs ({len(rnd.new_points)} new "
            f"point(s), {len(rnd.seeded_points)} with more seeds); "
            + (f"{pending} pending" if pending else "done")
        )
    if ref.campaign.precision is not None:
        out.append(f"decisions: {ref.decisions_text()}")
    state = (
        f"finished: {ref.stop}"
        if ref.finished
        else f"round {ref.current.number} in progress; later rounds are planned from its results"
    )
    out.append(f"{state}; {ref.n_runs} runs planned so far, at most {run_bound(ref.campaign)}")
    return out
