"""What the ``refine:`` and ``precision:`` sections may name as their observable
(:func:`observable_sources`: the phase.nc observables, their run scalars, and ``growth``) and
their ``classes:`` (a run's class: which thresholds of which observables it is above)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..campaign import DEFAULT_MODEL, Threshold
from ..models.interface import classifier
from ..models.registry import get_model
from .checker import Checker, KeyPath, is_finite_number, suggest

#: The derived observable read from the run files (the stability fit's criterion).
GROWTH = "growth"


def observable_sources(model: str = DEFAULT_MODEL) -> dict[str, str]:
    """``model``'s observable name -> the run scalar it is read from (phase.nc names and the
    scalars themselves), plus ``growth``."""
    out = {o.name: o.scalar for o in get_model(model).observables}
    out.update({src: src for src in list(out.values())})
    out[GROWTH] = GROWTH
    return out


def read_observable(
    c: Checker, path: KeyPath, value: Any, sources: Mapping[str, str], model: str = DEFAULT_MODEL
) -> str:
    """The observable a section names (one of ``sources``, :func:`observable_sources`); the
    model's classifying observable when it is not one (the problem is added to ``c``), so that
    the rest of the section is still checked."""
    if isinstance(value, str) and value in sources:
        return value
    c.bad(
        path,
        value,
        "one of "
        + ", ".join(sorted(sources))
        + (suggest(value, list(sources)) if isinstance(value, str) else ""),
    )
    return classifier(get_model(model)).name


def read_classes(
    c: Checker, path: KeyPath, raw: Any, model: str = DEFAULT_MODEL
) -> tuple[Threshold, ...] | None:
    """A ``classes:`` mapping (observable -> threshold) as thresholds, in the order written;
    ``None`` (problems added to ``c``) when it is not one."""
    sources = observable_sources(model)
    if not isinstance(raw, Mapping) or not raw:
        c.bad(
            path,
            raw,
            "a mapping observable -> threshold (a run's class is which "
            "thresholds it is above), e.g. {sigma2_S: 1.0e-6, cos2theta: 0.5}",
        )
        return None
    out: list[Threshold] = []
    ok = True
    for name, above in raw.items():
        if not isinstance(name, str) or name not in sources:
            c.bad(
                (*path, str(name)),
                name,
                "an observable: one of "
                + ", ".join(sorted(sources))
                + (suggest(name, list(sources)) if isinstance(name, str) else ""),
            )
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
