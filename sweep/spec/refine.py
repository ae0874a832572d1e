"""The ``refine:`` section of a campaign and its check.

::

    refine:
      axis: eps                 # the sweep axis refined (a numeric axis of its own, not zipped)
      # axes: [chi, K, eps]     # or several (each refined along the lines of the others)
      # log: [K]                # axes whose midpoints are geometric (spacing in decades)
      observable: growth        # what decides: a phase.nc observable (sigma2_S, mean_S, ...),
                                #   a run scalar (sigma2_S_final, ...), or growth
      criterion: fraction       # fraction (default) or jump
      patterned_above: 0.0      # fraction: a run is patterned when observable > this
      # classes: {sigma2_S: 1.0e-6, cos2theta: 0.5}   # fraction over several observables:
                                #   a run's class is which of these thresholds it is above
      fraction: [0.1, 0.9]      # fraction: a point is mixed when its patterned fraction lies
                                #   strictly between these (for each observable of classes)
      jump: 10                  # jump: a cell is a boundary when the geometric seed mean
                                #   changes by more than this factor across it
      rounds: 4                 # refinement rounds after the first (the grid itself)
      min_spacing: 0.0125       # a cell is split only if both halves are at least this wide
                                #   (several axes: a mapping axis -> spacing; decades on log)
      seeds:                    # sequential seeds (default: every seed at once)
        initial: 2              # seeds at every new point
        add: 2                  # seeds added in a round where a point is uncertain
        max_width: 0.6          # uncertain: the interval is wider than this
        confidence: 0.9         # of that interval

``growth`` is the stability fit's classification (Fig. A1): log10 of sigma2_S(t_final) /
sigma2_S(t_final / 2), read from the run file; with ``patterned_above: 0`` a run is
"patterned" (unstable) when sigma2_S grows over the second half of the run.

A log axis is one named in ``log:`` (never guessed from the values): its grid values must be
positive, its midpoints are geometric (sqrt(a b), so halving 1e-6 to 1e-4 gives 1e-5) and
its ``min_spacing`` is in decades. With a ``precision:`` section the seeds of every point,
grid and refined, are decided by its rules, so ``seeds:`` is refused here.

The checks add their problems to the campaign's checker
(:class:`nematic_solids.sweep.spec.checker.Checker`), so a mistake here is reported with the file,
line, key path, value and what is allowed, in the same pass as every other problem of the file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ..campaign import (
    DEFAULT_CONFIDENCE,
    DEFAULT_FRACTION,
    DEFAULT_JUMP,
    DEFAULT_MAX_WIDTH,
    DEFAULT_MODEL,
    DEFAULT_ROUNDS,
    Dim,
    PrecisionSpec,
    RefinedAxis,
    RefineSpec,
    Threshold,
)
from ..models.interface import classifier
from ..models.registry import get_model
from .checker import Checker, KeyPath, is_finite_number, is_int, suggest
from .observables import observable_sources, read_classes, read_observable

KEYS = (
    "axis",
    "axes",
    "log",
    "observable",
    "classes",
    "criterion",
    "patterned_above",
    "fraction",
    "jump",
    "rounds",
    "min_spacing",
    "seeds",
)
SEED_KEYS = ("initial", "add", "max_width", "confidence")
CRITERIA = ("fraction", "jump")
MAX_ROUNDS = 50


def read_refine(c: Checker, raw: Any, read: Mapping[str, Any]) -> RefineSpec | None:
    """The reader of the ``refine:`` section (a row of :data:`nematic_solids.sweep.spec.SECTIONS`):
    needs the ``sweep``, ``seeds`` and ``precision`` sections read before it."""
    return check_refine(
        c,
        raw,
        read.get("sweep") or (),
        read.get("seeds") or (),
        read.get("precision"),
        read.get("model") or DEFAULT_MODEL,
    )


def _axis_values(
    c: Checker, path: KeyPath, axis: Any, dims: Sequence[Dim]
) -> tuple[Any, ...] | None:
    """The grid values of a refinable axis named ``axis``, or ``None`` (problem added)."""
    names = [a.name for d in dims for a in d.axes]
    if not isinstance(axis, str) or axis not in names:
        c.bad(
            path,
            axis,
            "a sweep axis of this campaign ("
            + (", ".join(names) or "none")
            + ")"
            + (suggest(axis, names) if isinstance(axis, str) else ""),
        )
        return None
    dim = next(d for d in dims if any(a.name == axis for a in d.axes))
    values = next(a.values for a in dim.axes if a.name == axis)
    if len(dim.axes) > 1:
        c.bad(
            path,
            axis,
            "an axis of its own (this one is in the zip group "
            f"{', '.join(a.name for a in dim.axes)}): refined points have no value on the "
            "zipped axes",
        )
    elif not all(isinstance(v, float) for v in values):
        kind = next(type(v).__name__ for v in values if not isinstance(v, float))
        c.bad(
            path,
            axis,
            f"a real-valued axis (refined points are midpoints; {axis} is of type {kind})",
        )
    elif len(values) < 2:
        c.bad(path, axis, "an axis with at least two values (the cells between them are refined)")
    else:
        return values
    return None


def _refined_axes(
    c: Checker, path: KeyPath, sec: Mapping[str, Any], dims: Sequence[Dim]
) -> dict[str, tuple[Any, ...]] | None:
    """``axis:`` or ``axes:`` as axis -> grid values in the campaign's order of dims."""
    if "axis" in sec and "axes" in sec:
        c.add((*path, "axes"), "give axis (one refined axis) or axes (several), not both")
        return None
    if "axes" not in sec:
        values = _axis_values(c, (*path, "axis"), sec.get("axis"), dims)
        return None if values is None else {sec["axis"]: values}
    raw = sec["axes"]
    if not isinstance(raw, list) or not raw:
        c.bad((*path, "axes"), raw, "a list of sweep axes, e.g. [chi, K, eps]")
        return None
    found: dict[str, tuple[Any, ...]] = {}
    for i, name in enumerate(raw):
        if isinstance(name, str) and name in found:
            c.bad((*path, "axes", i), name, "each axis once")
            return None
        values = _axis_values(c, (*path, "axes", i), name, dims)
        if values is None:
            return None
        found[name] = values
    order = [a.name for d in dims for a in d.axes]
    return {name: found[name] for name in sorted(found, key=order.index)}


def _log_axes(c: Checker, path: KeyPath, raw: Any, axes: Mapping[str, tuple[Any, ...]]) -> set[str]:
    if raw is None:
        return set()
    if not isinstance(raw, list) or not all(isinstance(n, str) for n in raw):
        c.bad(path, raw, "a list of refined axes whose midpoints are geometric, e.g. [K]")
        return set()
    out: set[str] = set()
    for i, name in enumerate(raw):
        if name not in axes:
            c.bad(
                (*path, i),
                name,
                "a refined axis (" + ", ".join(axes) + ")" + suggest(name, list(axes)),
            )
        elif not all(is_finite_number(v) and v > 0 for v in axes[name]):
            c.bad(
                (*path, i),
                name,
                "an axis whose values are all > 0 (a geometric midpoint "
                f"needs them; {name} has {min(axes[name])!r})",
            )
        else:
            out.add(name)
    return out


def _spacing(
    c: Checker, path: KeyPath, spacing: Any, values: Sequence[Any], log: bool
) -> float | None:
    finite = len(values) >= 2 and all(is_finite_number(v) for v in values)
    span = None
    if finite:
        span = math.log10(max(values) / min(values)) if log else max(values) - min(values)
    if not is_finite_number(spacing) or not spacing > 0 or (span is not None and spacing >= span):
        where = (
            f" and below the axis's span ({span:g}" + (" decades)" if log else ")")
            if span is not None
            else ""
        )
        c.bad(path, spacing, ("a number of decades > 0" if log else "a number > 0") + where)
        return None
    return float(spacing)


def _spacings(
    c: Checker, path: KeyPath, raw: Any, axes: Mapping[str, tuple[Any, ...]], log: set[str]
) -> dict[str, float] | None:
    """``min_spacing:`` per refined axis: a number (one axis) or a mapping."""
    several = ", ".join(axes)
    if raw is None:
        c.add(
            path,
            "missing; allowed: a number > 0 (a cell is split only while both halves "
            "are at least this wide)"
            + (
                ""
                if len(axes) == 1
                else f"; several axes: a mapping axis -> number ({several};"
                " in decades on a log axis)"
            ),
        )
        return None
    if not isinstance(raw, Mapping):
        if len(axes) > 1:
            c.bad(
                path,
                raw,
                f"a mapping axis -> smallest spacing for each of {several} "
                "(several axes are refined; in decades on a log axis)",
            )
            return None
        name = next(iter(axes))
        value = _spacing(c, path, raw, axes[name], name in log)
        return None if value is None else {name: value}
    out: dict[str, float] = {}
    for key in raw:
        if key not in axes:
            c.unknown((*path, str(key)), key, list(axes), " (not a refined axis)")
    for name, values in axes.items():
        if name not in raw:
            c.add(
                (*path, name),
                f"missing; allowed: the smallest spacing of {name}, a number "
                "> 0" + (" (decades: a log axis)" if name in log else ""),
            )
            continue
        value = _spacing(c, (*path, name), raw[name], values, name in log)
        if value is not None:
            out[name] = value
    return out if len(out) == len(axes) and set(raw) <= set(axes) else None


def check_refine(
    c: Checker,
    raw: Any,
    dims: Sequence[Dim],
    seeds: Sequence[int],
    precision: PrecisionSpec | None = None,
    model: str = DEFAULT_MODEL,
) -> RefineSpec | None:
    """The ``refine:`` section as a :class:`RefineSpec`, or ``None`` when there is none (or
    it has problems, which are added to ``c``); its observables are ``model``'s."""
    if raw is None:
        return None
    path: KeyPath = ("refine",)
    if not isinstance(raw, dict):
        c.bad(path, raw, "a mapping with keys " + ", ".join(KEYS))
        return None
    sec = c.mapping(path, raw, KEYS)
    before = len(c.problems)

    axes = _refined_axes(c, path, sec, dims)
    log = _log_axes(c, (*path, "log"), sec.get("log"), axes or {})

    criterion = sec.get("criterion", "fraction")
    if criterion not in CRITERIA:
        c.bad((*path, "criterion"), criterion, " or ".join(CRITERIA))
        criterion = "fraction"

    classes = _classes(c, path, sec, criterion, model)

    sources = observable_sources(model)
    default = classes[0].observable if classes else classifier(get_model(model)).name
    observable = sec.get("observable", default)
    observable = read_observable(c, (*path, "observable"), observable, sources, model)

    patterned = _patterned_above(c, path, sec, criterion, observable)
    fraction = _fraction(c, path, sec)

    jump = sec.get("jump", DEFAULT_JUMP)
    if not is_finite_number(jump) or not jump > 1:
        c.bad(
            (*path, "jump"),
            jump,
            "a factor > 1 (the change of the geometric seed mean that marks a boundary cell)",
        )
        jump = DEFAULT_JUMP

    rounds = sec.get("rounds", DEFAULT_ROUNDS)
    if not is_int(rounds) or not 0 <= rounds <= MAX_ROUNDS:
        c.bad(
            (*path, "rounds"),
            rounds,
            f"an integer from 0 to {MAX_ROUNDS} (refinement rounds after the grid's)",
        )
        rounds = DEFAULT_ROUNDS

    spacings = (
        _spacings(c, (*path, "min_spacing"), sec.get("min_spacing"), axes or {}, log)
        if axes is not None
        else None
    )

    initial, add, width, confidence = _seeds(c, path, sec, len(seeds), criterion, precision)

    if len(c.problems) > before or axes is None or spacings is None:
        return None
    spec = RefineSpec(
        axes=tuple(RefinedAxis(name, spacings[name], name in log) for name in axes),
        observable=observable,
        source=sources[observable],
        criterion=criterion,
        patterned_above=None if patterned is None else float(patterned),
        classes=classes,
        fraction=(float(fraction[0]), float(fraction[1])),
        jump=float(jump),
        rounds=int(rounds),
        initial=initial,
        add=add,
        max_width=width,
        confidence=confidence,
    )
    return spec if _within_bound(c, path, sec, spec, axes, dims, len(seeds)) else None


def _classes(
    c: Checker, path: KeyPath, sec: Mapping[str, Any], criterion: str, model: str
) -> tuple[Threshold, ...]:
    """``classes:`` (a run's class from several observables; criterion ``fraction`` only, and
    not with ``observable`` or ``patterned_above``) as thresholds; ``()`` without it."""
    if "classes" not in sec:
        return ()
    read = read_classes(c, (*path, "classes"), sec["classes"], model)
    if criterion != "fraction":
        c.add(
            (*path, "classes"),
            "used by criterion 'fraction' only; this section has "
            "criterion 'jump' (remove it, or set criterion: fraction)",
        )
    for key in ("observable", "patterned_above"):
        if key in sec:
            c.add(
                (*path, key),
                "not with classes: (each observable of classes has its "
                "threshold); remove one of the two",
            )
    return read or ()


def _patterned_above(
    c: Checker, path: KeyPath, sec: Mapping[str, Any], criterion: str, observable: str
) -> Any:
    """``patterned_above:``, as given: needed by criterion ``fraction`` without ``classes``,
    refused with criterion ``jump`` (problems added to ``c``)."""
    patterned = sec.get("patterned_above")
    if criterion == "fraction":
        if patterned is None and "classes" not in sec:
            c.add(
                (*path, "patterned_above"),
                "missing; allowed: a number (a run counts as "
                f"patterned when its {observable} is above it); needed by criterion "
                "'fraction' (or classes: for several observables)",
            )
        elif patterned is not None and not is_finite_number(patterned):
            c.bad((*path, "patterned_above"), patterned, "a finite number")
    elif patterned is not None:
        c.add(
            (*path, "patterned_above"),
            "used by criterion 'fraction' only; this section "
            "has criterion 'jump' (remove it, or set criterion: fraction)",
        )
    return patterned


def _fraction(c: Checker, path: KeyPath, sec: Mapping[str, Any]) -> Any:
    """``fraction: [low, high]``: a point is mixed when its patterned fraction lies between
    them (the default, its problem added to ``c``, when it is not such a pair)."""
    fraction = sec.get("fraction", list(DEFAULT_FRACTION))
    if (
        not isinstance(fraction, Sequence)
        or isinstance(fraction, str)
        or len(fraction) != 2
        or not all(is_finite_number(f) for f in fraction)
        or not 0 <= fraction[0] < fraction[1] <= 1
    ):
        c.bad((*path, "fraction"), fraction, "[low, high] with 0 <= low < high <= 1")
        fraction = list(DEFAULT_FRACTION)
    return fraction


def _within_bound(
    c: Checker,
    path: KeyPath,
    sec: Mapping[str, Any],
    spec: RefineSpec,
    axes: Mapping[str, tuple[Any, ...]],
    dims: Sequence[Dim],
    n_seeds: int,
) -> bool:
    """Whether the union grid phase.nc holds (and the most runs) is within
    ``limits.max_runs``, like a grid; else ``False``, its problem added to ``c``."""
    lines = math.prod(len(d) for d in dims if d.name not in axes)
    bound = (
        lines * math.prod(points_bound(axes[a.name], a, spec.rounds) for a in spec.axes) * n_seeds
    )
    if bound > c.max_runs:
        c.add(
            (*path, "min_spacing"),
            f"got {sec.get('min_spacing')!r}: the refined grid may "
            f"reach {bound} runs; allowed: at most {c.max_runs} (limits.max_runs): a larger "
            "smallest spacing, fewer rounds or a smaller grid",
        )
        return False
    return True


def _seeds(
    c: Checker,
    path: KeyPath,
    sec: Mapping[str, Any],
    n_seeds: int,
    criterion: str,
    precision: PrecisionSpec | None,
) -> tuple[int, int, float, float]:
    """``seeds:`` as (initial, add, max_width, confidence); with a ``precision:`` section its
    ``initial`` and ``add`` (and ``seeds:`` here is refused)."""
    if precision is not None:
        if "seeds" in sec:
            c.add(
                (*path, "seeds"),
                "not with a precision: section, whose rules decide the "
                "seeds of every point, grid and refined (its initial and add); remove one "
                "of the two",
            )
        return precision.initial, precision.add, DEFAULT_MAX_WIDTH, DEFAULT_CONFIDENCE
    sd = c.mapping((*path, "seeds"), sec.get("seeds"), SEED_KEYS)
    initial = sd.get("initial", n_seeds)
    if not is_int(initial) or not 1 <= initial <= max(n_seeds, 1):
        c.bad(
            (*path, "seeds", "initial"),
            initial,
            f"an integer from 1 to {n_seeds} (the campaign's seeds)",
        )
        initial = max(n_seeds, 1)
    add = sd.get("add", initial)
    if not is_int(add) or add < 1:
        c.bad((*path, "seeds", "add"), add, "an integer >= 1")
        add = 1
    width = sd.get("max_width", DEFAULT_MAX_WIDTH)
    if not is_finite_number(width) or not width > 0 or (criterion == "fraction" and width > 1):
        c.bad(
            (*path, "seeds", "max_width"),
            width,
            "a number in (0, 1] (the widest acceptable interval on the patterned fraction)"
            if criterion == "fraction"
            else "a number > 0 (decades: the widest acceptable interval on the log10 seed mean)",
        )
        width = DEFAULT_MAX_WIDTH
    confidence = sd.get("confidence", DEFAULT_CONFIDENCE)
    if not is_finite_number(confidence) or not 0 < confidence < 1:
        c.bad((*path, "seeds", "confidence"), confidence, "a number in (0, 1)")
        confidence = DEFAULT_CONFIDENCE
    return int(initial), int(add), float(width), float(confidence)


def points_bound(values: Sequence[float], axis: RefinedAxis, rounds: int) -> int:
    """The most values one refined axis can have: its grid values and every midpoint the
    rounds can add down to the smallest spacing."""
    xs = sorted(float(v) for v in values)
    total = len(xs)
    for a, b in zip(xs, xs[1:], strict=False):
        width = math.log10(b / a) if axis.log else b - a
        depth = 0
        while depth < rounds and width / 2 ** (depth + 1) >= axis.min_spacing * (1 - 1e-9):
            depth += 1
        total += 2**depth - 1
    return total
