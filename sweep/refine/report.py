"""The text that ``nematic run``, ``validate`` and ``status`` print about a refined
campaign's rounds (plain lines: the commands print them literally)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .plan import first_round, points_of, run_bound

if TYPE_CHECKING:
    from ..campaign import Campaign
    from .rounds import Refinement

#: Points listed per round (the plan file has them all).
MAX_LINES = 12


def _value(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _where(coords: dict[str, Any]) -> str:
    return ", ".join(f"{k}={_value(v)}" for k, v in coords.items())


def spec_line(campaign: Campaign) -> str:
    spec = campaign.refine
    assert spec is not None
    if spec.criterion == "fraction":
        rule = (f"patterned when {spec.observable} > {spec.patterned_above:g}; a point is mixed "
                f"when its patterned fraction lies in ({spec.fraction[0]:g}, "
                f"{spec.fraction[1]:g})")
    else:
        rule = f"a cell whose geometric seed mean of {spec.observable} changes by > {spec.jump:g}x"
    seeds = (f"seeds {spec.initial} per new point, +{spec.add} where uncertain up to "
             f"{len(campaign.seeds)}" if spec.initial < len(campaign.seeds)
             else f"all {len(campaign.seeds)} seeds at every point")
    return (f"refine {spec.axis}: {rule}; at most {spec.rounds} round(s) after the grid, "
            f"smallest spacing {spec.min_spacing:g}; {seeds}")


def validation_lines(campaign: Campaign) -> list[str]:
    """What ``nematic validate`` prints for a refined campaign: the rule, the first round's
    plan and an upper bound on the run count."""
    spec = campaign.refine
    assert spec is not None
    first = first_round(campaign)
    points = points_of([first])
    return [spec_line(campaign),
            f"round 0 (the grid): {len(points)} points x {spec.initial} seed(s) = "
            f"{len(first.runs)} runs; later rounds are planned from the results",
            f"runs: at most {run_bound(campaign)} (every cell split down to the smallest "
            f"spacing, once per round, and every point run with all {len(campaign.seeds)} "
            "seeds)"]


def round_lines(ref: Refinement, number: int) -> list[str]:
    """A round's plan: how many runs, new points and seeds, and where and why (the first
    :data:`MAX_LINES` points; ``refine.json`` in the results folder lists every run)."""
    rnd = ref.rounds[number]
    namer = ref.namer
    assert namer is not None
    if number == 0:
        return [f"round 0 (the grid): {len(rnd.new_points)} points, {len(rnd.runs)} runs"]
    out = [f"round {number}: {len(rnd.runs)} runs: {len(rnd.new_points)} new point(s), "
           f"{len(rnd.seeded_points)} point(s) with more seeds"]
    shown: dict[tuple[Any, ...], tuple[str, list[int]]] = {}
    for r in rnd.runs:
        shown.setdefault(r.point, (r.why, []))[1].append(r.seed)
    for i, ((line, x), (why, seeds)) in enumerate(shown.items()):
        if i == MAX_LINES:
            out.append(f"  ... and {len(shown) - MAX_LINES} more (refine.json lists every run)")
            break
        out.append(f"  {_where(namer.coords(line, x))}: seeds {', '.join(map(str, seeds))}: "
                   f"{why}")
    return out


def status_lines(ref: Refinement) -> list[str]:
    """What ``nematic status`` adds for a refined campaign: one line per round."""
    if hasattr(ref, "status_lines"):  # seeds by precision (sweep/precision)
        return list(ref.status_lines())
    out = [spec_line(ref.campaign)]
    for rnd in ref.rounds:
        pending = sum(1 for r in rnd.runs
                      if ref.outcomes.get((r.line, r.x, r.seed)) is None)
        out.append(f"round {rnd.number}: {len(rnd.runs)} runs ({len(rnd.new_points)} new "
                   f"point(s), {len(rnd.seeded_points)} with more seeds); "
                   + (f"{pending} pending" if pending else "done"))
    state = (f"finished: {ref.stop}" if ref.finished
             else f"round {ref.current.number} in progress; later rounds are planned from its "
                  "results")
    out.append(f"{state}; {ref.n_runs} runs planned so far, at most "
               f"{run_bound(ref.campaign)}")
    return out
