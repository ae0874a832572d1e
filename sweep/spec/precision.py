"""The ``precision:`` section of a campaign and its check.

::

    seeds: 50                   # the cap
    precision:
      observable: lambda_peak   # a phase.nc observable or a run scalar (as refine: takes)
      width: 0.1                # precise: the interval of the seed mean is narrower than this
      relative: true            # width relative to |seed mean| (default) or absolute
      confidence: 0.95          # of that interval (Student-t)
      unanimous: 4              # or: at least this many seeds, all of one pattern class
      patterned_above: 1.0e-6   # the class: sigma2_S above this (needed by unanimous)
      # classes: {sigma2_S: 1.0e-6, cos2theta: 0.5}   # or: the class from several
                                #   observables (which of these thresholds a run is above)
      initial: 4                # seeds every point starts with
      add: 4                    # seeds added per round to an undecided point

``width`` or ``unanimous`` (or both) must be given. With a ``refine:`` section the same rules
decide the seeds of every point, grid and refined (:mod:`nematic_solids.sweep.refine.seeds`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..campaign import DEFAULT_MODEL, PrecisionSpec, Threshold
from ..models.interface import classifier
from ..models.registry import get_model
from .checker import Checker, KeyPath, is_finite_number, is_int
from .observables import observable_sources, read_classes, read_observable

KEYS = (
    "observable",
    "width",
    "relative",
    "confidence",
    "unanimous",
    "patterned_above",
    "classes",
    "initial",
    "add",
)


def read_precision(c: Checker, raw: Any, read: Mapping[str, Any]) -> PrecisionSpec | None:
    """The reader of the ``precision:`` section (a row of
    :data:`nematic_solids.sweep.spec.SECTIONS`): needs the ``seeds`` section read before it.
    ``None`` when there is none (or it has problems, which are added to ``c``)."""
    if raw is None:
        return None
    path: KeyPath = ("precision",)
    if not isinstance(raw, dict):
        c.bad(path, raw, "a mapping with keys " + ", ".join(KEYS))
        return None
    sec = c.mapping(path, raw, KEYS)
    before = len(c.problems)
    n_seeds = len(read.get("seeds") or ())

    observable = sec.get("observable")
    model = read.get("model") or DEFAULT_MODEL
    sources = observable_sources(model)
    observable = read_observable(c, (*path, "observable"), observable, sources, model)
    width, relative, confidence = _interval_rule(c, path, sec)
    unanimous, patterned, classes = _class_rule(c, path, sec, n_seeds, model)
    if width is None and unanimous is None:
        c.add(
            path,
            "no stopping rule; allowed: width (the interval of the seed mean), "
            "unanimous (the pattern class), or both",
        )
    initial, add = _seed_steps(c, path, sec, n_seeds)

    if len(c.problems) > before:
        return None
    return PrecisionSpec(
        observable=observable,
        source=sources[observable],
        width=None if width is None else float(width),
        relative=relative,
        confidence=float(confidence),
        unanimous=unanimous,
        patterned_above=None if patterned is None else float(patterned),
        initial=int(initial),
        add=int(add),
        classes=classes or (),
        patterned=(classifier(get_model(model)).name, classifier(get_model(model)).scalar),
    )


def _interval_rule(c: Checker, path: KeyPath, sec: Mapping[str, Any]) -> tuple[Any, Any, Any]:
    """The rule on the interval of the seed mean: ``width`` (``None``: no such rule),
    ``relative`` and ``confidence``, as given (problems added to ``c``)."""
    width = sec.get("width")
    if width is not None and (not is_finite_number(width) or not width > 0):
        c.bad(
            (*path, "width"),
            width,
            "a number > 0 (the widest acceptable confidence interval of the seed mean)",
        )
    relative = sec.get("relative", True)
    if not isinstance(relative, bool):
        c.bad(
            (*path, "relative"),
            relative,
            "true (width relative to |seed mean|) or false (absolute, in the observable's units)",
        )
    confidence = sec.get("confidence", 0.95)
    if not is_finite_number(confidence) or not 0 < confidence < 1:
        c.bad((*path, "confidence"), confidence, "a number in (0, 1)")
    return width, relative, confidence


def _class_rule(
    c: Checker, path: KeyPath, sec: Mapping[str, Any], n_seeds: int, model: str
) -> tuple[Any, Any, tuple[Threshold, ...] | None]:
    """The rule on the pattern class: ``unanimous`` (``None``: no such rule) and the class,
    ``patterned_above`` or ``classes``, as given (problems added to ``c``)."""
    unanimous = sec.get("unanimous")
    if unanimous is not None and (not is_int(unanimous) or not 2 <= unanimous <= max(n_seeds, 2)):
        c.bad(
            (*path, "unanimous"),
            unanimous,
            f"an integer from 2 to {n_seeds} (the "
            "campaign's seeds): the fewest seeds that stop a point when they all share "
            "the pattern class",
        )
    patterned = sec.get("patterned_above")
    classes = read_classes(c, (*path, "classes"), sec["classes"], model) if "classes" in sec else ()
    if patterned is not None and "classes" in sec:
        c.add(
            (*path, "patterned_above"),
            "not with classes: (each observable of classes has "
            "its threshold); remove one of the two",
        )
    elif unanimous is not None and patterned is None and "classes" not in sec:
        c.add(
            (*path, "patterned_above"),
            "missing; allowed: a number (a run's pattern class is the model's classifying "
            "observable above it; or classes: for several observables); needed by unanimous",
        )
    elif patterned is not None and not is_finite_number(patterned):
        c.bad((*path, "patterned_above"), patterned, "a finite number")
    return unanimous, patterned, classes


def _seed_steps(c: Checker, path: KeyPath, sec: Mapping[str, Any], n_seeds: int) -> tuple[Any, Any]:
    """The seeds every point starts with (``initial``) and those added per round (``add``),
    as given (problems added to ``c``)."""
    initial = sec.get("initial", min(4, n_seeds) or 1)
    if not is_int(initial) or not 1 <= initial <= max(n_seeds, 1):
        c.bad((*path, "initial"), initial, f"an integer from 1 to {n_seeds} (the campaign's seeds)")
    add = sec.get("add", initial)
    if not is_int(add) or add < 1:
        c.bad((*path, "add"), add, "an integer >= 1")
    return initial, add
