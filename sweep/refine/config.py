"""The ``refine:`` section of a campaign and its check.

::

    refine:
      axis: eps                 # the sweep axis refined (a numeric axis of its own, not zipped)
      observable: growth        # what decides: a phase.nc observable (sigma2_S, mean_S, ...),
                                #   a run scalar (sigma2_S_final, ...), or growth
      criterion: fraction       # fraction (default) or jump
      patterned_above: 0.0      # fraction: a run is patterned when observable > this
      fraction: [0.1, 0.9]      # fraction: a point is mixed when its patterned fraction lies
                                #   strictly between these
      jump: 10                  # jump: a cell is a boundary when the geometric seed mean
                                #   changes by more than this factor across it
      rounds: 4                 # refinement rounds after the first (the grid itself)
      min_spacing: 0.0125       # a cell is split only if both halves are at least this wide
      seeds:                    # sequential seeds (default: every seed at once)
        initial: 2              # seeds at every new point
        add: 2                  # seeds added in a round where a point is uncertain
        max_width: 0.6          # uncertain: the interval is wider than this
        confidence: 0.9         # of that interval

``growth`` is the stability fit's classification (Fig. A1): log10 of sigma2_S(t_final) /
sigma2_S(t_final / 2), read from the run file; with ``patterned_above: 0`` a run is
"patterned" (unstable) when sigma2_S grows over the second half of the run.

The checks add their problems to the campaign's checker (:class:`sweep.checker.Checker`), so
a mistake here is reported with the file, line, key path, value and what is allowed, in the
same pass as every other problem of the file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ..campaign import (
    AXIS_TYPES,
    DEFAULT_CONFIDENCE,
    DEFAULT_FRACTION,
    DEFAULT_JUMP,
    DEFAULT_MAX_WIDTH,
    DEFAULT_ROUNDS,
    Dim,
    RefineSpec,
    Threshold,
)
from ..checker import Checker, KeyPath, is_finite_number, is_int, suggest

KEYS = ("axis", "observable", "criterion", "patterned_above", "fraction", "jump", "rounds",
        "min_spacing", "seeds")
SEED_KEYS = ("initial", "add", "max_width", "confidence")
CRITERIA = ("fraction", "jump")
#: The derived observable read from the run files (the stability fit's criterion).
GROWTH = "growth"
MAX_ROUNDS = 50


def observable_sources() -> dict[str, str]:
    """Observable name -> the run scalar it is read from (phase.nc names and the scalars
    themselves), plus ``growth``."""
    from ..aggregate import OBSERVABLES

    out = {name: src for name, (src, _) in OBSERVABLES.items()}
    out.update({src: src for src in list(out.values())})
    out[GROWTH] = GROWTH
    return out


def read_classes(c: Checker, path: KeyPath, raw: Any) -> tuple[Threshold, ...] | None:
    """A ``classes:`` mapping (observable -> threshold) as thresholds, in the order written;
    ``None`` (problems added to ``c``) when it is not one."""
    sources = observable_sources()
    if not isinstance(raw, Mapping) or not raw:
        c.bad(path, raw, "a mapping observable -> threshold (a run's class is which "
              "thresholds it is above), e.g. {sigma2_S: 1.0e-6, cos2theta: 0.5}")
        return None
    out: list[Threshold] = []
    ok = True
    for name, above in raw.items():
        if not isinstance(name, str) or name not in sources:
            c.bad((*path, str(name)), name, "an observable: one of " + ", ".join(sorted(sources))
                  + (suggest(name, list(sources)) if isinstance(name, str) else ""))
            ok = False
        elif not is_finite_number(above):
            c.bad((*path, name), above, "a finite number (the run is above it or not)")
            ok = False
        else:
            out.append(Threshold(name, sources[name], float(above)))
    if ok and len({t.source for t in out}) < len(out):
        c.bad(path, dict(raw), "each observable once (a name and its run scalar are one)")
        ok = False
    return tuple(out) if ok else None


def read_refine(c: Checker, raw: Any, read: Mapping[str, Any]) -> RefineSpec | None:
    """The reader of the ``refine:`` section (a row of :data:`sweep.spec.SECTIONS`): needs the
    ``sweep`` and ``seeds`` sections read before it."""
    return check_refine(c, raw, read.get("sweep") or (), read.get("seeds") or ())


def check_refine(c: Checker, raw: Any, dims: Sequence[Dim],
                 seeds: Sequence[int]) -> RefineSpec | None:
    """The ``refine:`` section as a :class:`RefineSpec`, or ``None`` when there is none (or
    it has problems, which are added to ``c``)."""
    if raw is None:
        return None
    path: tuple[str | int, ...] = ("refine",)
    if not isinstance(raw, dict):
        c.bad(path, raw, "a mapping with keys " + ", ".join(KEYS))
        return None
    sec = c.mapping(path, raw, KEYS)
    before = len(c.problems)

    axis = sec.get("axis")
    names = [a.name for d in dims for a in d.axes]
    values: tuple[Any, ...] = ()
    if not isinstance(axis, str) or axis not in names:
        c.bad((*path, "axis"), axis, "a sweep axis of this campaign ("
              + (", ".join(names) or "none") + ")"
              + (suggest(axis, names) if isinstance(axis, str) else ""))
    else:
        dim = next(d for d in dims if any(a.name == axis for a in d.axes))
        values = next(a.values for a in dim.axes if a.name == axis)
        if len(dim.axes) > 1:
            c.bad((*path, "axis"), axis, "an axis of its own (this one is in the zip group "
                  f"{', '.join(a.name for a in dim.axes)}): refined points have no value on "
                  "the zipped axes")
        elif AXIS_TYPES.get(axis) != "float":
            c.bad((*path, "axis"), axis, "a real-valued axis (refined points are midpoints; "
                  f"{axis} is of type {AXIS_TYPES.get(axis)})")
        elif len(values) < 2:
            c.bad((*path, "axis"), axis, "an axis with at least two values (the cells "
                  "between them are refined)")

    observable = sec.get("observable", "sigma2_S")
    sources = observable_sources()
    if not isinstance(observable, str) or observable not in sources:
        c.bad((*path, "observable"), observable, "one of " + ", ".join(sorted(sources))
              + (suggest(observable, list(sources)) if isinstance(observable, str) else ""))
        observable = "sigma2_S"

    criterion = sec.get("criterion", "fraction")
    if criterion not in CRITERIA:
        c.bad((*path, "criterion"), criterion, " or ".join(CRITERIA))
        criterion = "fraction"

    patterned = sec.get("patterned_above")
    if criterion == "fraction":
        if patterned is None:
            c.add((*path, "patterned_above"), "missing; allowed: a number (a run counts as "
                  f"patterned when its {observable} is above it); needed by criterion "
                  "'fraction'")
        elif not is_finite_number(patterned):
            c.bad((*path, "patterned_above"), patterned, "a finite number")
    elif patterned is not None:
        c.add((*path, "patterned_above"), "used by criterion 'fraction' only; this section "
              "has criterion 'jump' (remove it, or set criterion: fraction)")

    fraction = sec.get("fraction", list(DEFAULT_FRACTION))
    if (not isinstance(fraction, Sequence) or isinstance(fraction, str) or len(fraction) != 2
            or not all(is_finite_number(f) for f in fraction)
            or not 0 <= fraction[0] < fraction[1] <= 1):
        c.bad((*path, "fraction"), fraction, "[low, high] with 0 <= low < high <= 1")
        fraction = list(DEFAULT_FRACTION)

    jump = sec.get("jump", DEFAULT_JUMP)
    if not is_finite_number(jump) or not jump > 1:
        c.bad((*path, "jump"), jump, "a factor > 1 (the change of the geometric seed mean "
              "that marks a boundary cell)")
        jump = DEFAULT_JUMP

    rounds = sec.get("rounds", DEFAULT_ROUNDS)
    if not is_int(rounds) or not 0 <= rounds <= MAX_ROUNDS:
        c.bad((*path, "rounds"), rounds, f"an integer from 0 to {MAX_ROUNDS} (refinement "
              "rounds after the grid's)")
        rounds = DEFAULT_ROUNDS

    spacing = sec.get("min_spacing")
    span = (max(values) - min(values)) if len(values) >= 2 and all(
        is_finite_number(v) for v in values) else None
    if spacing is None:
        c.add((*path, "min_spacing"), "missing; allowed: a number > 0 (a cell is split only "
              "while both halves are at least this wide)")
        spacing = 0.0
    elif not is_finite_number(spacing) or not spacing > 0 or (span is not None and spacing >= span):
        c.bad((*path, "min_spacing"), spacing, "a number > 0"
              + (f" and below the axis's span ({span:g})" if span is not None else ""))
        spacing = 0.0

    n_seeds = len(seeds)
    sd = c.mapping((*path, "seeds"), sec.get("seeds"), SEED_KEYS)
    initial = sd.get("initial", n_seeds)
    if not is_int(initial) or not 1 <= initial <= max(n_seeds, 1):
        c.bad((*path, "seeds", "initial"), initial, f"an integer from 1 to {n_seeds} (the "
              "campaign's seeds)")
        initial = max(n_seeds, 1)
    add = sd.get("add", initial)
    if not is_int(add) or add < 1:
        c.bad((*path, "seeds", "add"), add, "an integer >= 1")
        add = 1
    width = sd.get("max_width", DEFAULT_MAX_WIDTH)
    if not is_finite_number(width) or not width > 0 or (criterion == "fraction" and width > 1):
        c.bad((*path, "seeds", "max_width"), width,
              "a number in (0, 1] (the widest acceptable interval on the patterned fraction)"
              if criterion == "fraction" else "a number > 0 (decades: the widest acceptable "
              "interval on the log10 seed mean)")
        width = DEFAULT_MAX_WIDTH
    confidence = sd.get("confidence", DEFAULT_CONFIDENCE)
    if not is_finite_number(confidence) or not 0 < confidence < 1:
        c.bad((*path, "seeds", "confidence"), confidence, "a number in (0, 1)")
        confidence = DEFAULT_CONFIDENCE

    if len(c.problems) > before or not isinstance(axis, str):
        return None
    spec = RefineSpec(
        axis=axis, observable=observable, source=sources[observable], criterion=criterion,
        patterned_above=None if patterned is None else float(patterned),
        fraction=(float(fraction[0]), float(fraction[1])), jump=float(jump),
        rounds=int(rounds), min_spacing=float(spacing), initial=int(initial), add=int(add),
        max_width=float(width), confidence=float(confidence))
    # the union grid phase.nc holds (and the most runs) is bounded like a grid
    from .plan import points_bound

    lines = math.prod(len(d) for d in dims if d.name != axis)
    bound = lines * points_bound(values, spec) * n_seeds
    if bound > c.max_runs:
        c.add((*path, "min_spacing"), f"got {spacing!r}: the refined grid may reach {bound} "
              f"runs; allowed: at most {c.max_runs} (limits.max_runs): a larger smallest "
              "spacing, fewer rounds or a smaller grid")
        return None
    return spec
