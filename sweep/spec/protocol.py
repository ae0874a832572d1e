"""The ``protocol:`` section (nematic_solids.sweep.protocols): its structure checked here, with the
key path of every mistake; the functions' values are checked by the model at every grid point
(:func:`nematic_solids.sweep.spec.points.check_points`), where the sweep axes of its numbers are
known."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from nematic_solids.model.protocol import FORMS, PROTOCOL_PARAMETERS

from ..campaign import AMB, DEFAULT_MODEL
from ..models.registry import get_model
from ..protocols import PROTOCOL
from .checker import Checker


def read_protocol(c: Checker, raw: Any, read: Mapping[str, Any]) -> dict[str, Any]:
    """``protocol:`` -> the base parameters with it (``parameters["protocol"]``); a parameter
    given a function of time is not also a constant under ``parameters:``."""
    params = dict(read["parameters"])
    if raw is None:
        return params
    model = get_model(read.get("model") or DEFAULT_MODEL)
    if not model.capabilities.protocols:
        c.add(
            (PROTOCOL,),
            f"the model {model.name} takes no time protocols (its settings are constants of a "
            "run); drop 'protocol:'",
        )
        return params
    if not isinstance(raw, Mapping) or not raw:
        c.bad((PROTOCOL,), raw, "a mapping {parameter: function of time}")
        return params
    good: dict[str, Any] = {}
    for name, spec in raw.items():
        path = (PROTOCOL, str(name))
        if name not in PROTOCOL_PARAMETERS:
            c.unknown(path, name, PROTOCOL_PARAMETERS)
            continue
        clash = [k for k in ((name, "alpha") if name == AMB else (name,)) if k in params]
        if clash:
            c.add(
                path,
                f"set in both 'parameters:' ({clash[0]}) and 'protocol:'; keep one of them "
                "(a constant is a function of time too: [[0, value]])",
            )
            continue
        if isinstance(spec, Mapping):
            if len(spec) != 1 or next(iter(spec)) not in FORMS:
                c.bad(path, dict(spec), "exactly one of " + ", ".join(FORMS))
                continue
        elif isinstance(spec, str) or not isinstance(spec, Sequence):
            c.bad(path, spec, "a list of [time, value] pairs or one of " + ", ".join(FORMS))
            continue
        good[str(name)] = spec
    if good:
        params[PROTOCOL] = good
    return params
