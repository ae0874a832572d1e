"""A campaign's ``protocol:`` (nematic_solids.model.protocol) and the sweep axes made of its
numbers.

The section maps a parameter of :data:`nematic_solids.model.protocol.PROTOCOL_PARAMETERS` to its
function of time, in any form :func:`nematic_solids.model.protocol.profile_from` reads. Every number
of a named form (``pulse``: base, level, start, duration; the named ``ramp``: from, to, start,
duration; ``sine``: mean, amplitude, period, start) can be a sweep axis named
``<parameter>_<number>``, e.g. ``alpha_minus_B_level`` or ``eps_period``: at each grid point the
axis value replaces (or supplies) that number. The campaign's parameters then carry the protocol of
the point (``parameters["protocol"]``), which the model validates and the run's identity covers.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from nematic_solids.model.protocol import PROTOCOL_PARAMETERS, PULSE_KEYS, RAMP_KEYS, SINE_KEYS

#: the key of the campaign's parameters that holds the protocol (Parameters.protocol)
PROTOCOL = "protocol"
#: the numbers of each named form, which can be swept
NAMED_KEYS: dict[str, tuple[str, ...]] = {
    "pulse": PULSE_KEYS,
    "ramp": RAMP_KEYS,
    "sine": SINE_KEYS,
}

#: every axis name a protocol can offer -> its long name (phase.nc coordinates)
AXIS_LONG_NAMES = {
    f"{param}_{key}": f"{key} of the function of time of {param} (protocol)"
    for param in PROTOCOL_PARAMETERS
    for keys in NAMED_KEYS.values()
    for key in keys
}


def protocol_axes(parameters: Mapping[str, Any]) -> dict[str, tuple[str, str, str]]:
    """The axis names the protocol of ``parameters`` offers -> (parameter, form, number)."""
    raw = parameters.get(PROTOCOL)
    out: dict[str, tuple[str, str, str]] = {}
    if not isinstance(raw, Mapping):
        return out
    for param, spec in raw.items():
        if not isinstance(spec, Mapping) or len(spec) != 1:
            continue
        form, body = next(iter(spec.items()))
        if form in NAMED_KEYS and isinstance(body, Mapping):
            for key in NAMED_KEYS[form]:
                out[f"{param}_{key}"] = (str(param), str(form), key)
    return out


def with_axis_values(parameters: dict[str, Any], values: Mapping[str, Any]) -> None:
    """Put the swept protocol numbers among ``values`` into ``parameters``' protocol (a
    copy of it: the campaign's own mapping is not changed)."""
    axes = protocol_axes(parameters)
    swept = {name: v for name, v in values.items() if name in axes}
    if not swept:
        return
    protocol = dict(parameters[PROTOCOL])  # the swept functions are new mappings below
    for name, value in swept.items():
        param, form, key = axes[name]
        protocol[param] = {form: {**protocol[param][form], key: value}}
    parameters[PROTOCOL] = protocol


def error_path(name: str, swept: Mapping[str, tuple[str, str, str]]) -> tuple[str, ...] | None:
    """The campaign key path of a model error's name ``protocol.<parameter>[.<form>...]``:
    the sweep axis when the number is swept (or, for the bounds of the function's values, a
    swept number of it), else the place in the ``protocol:`` section; None for another
    name."""
    if not name.startswith(PROTOCOL + "."):
        return None
    parts = name.split(".")
    for axis, (param, form, key) in swept.items():
        # the number itself, or the values of its function (their bounds)
        if parts[1:4] == [param, form, key] or parts[1:] == [param]:
            return ("sweep", "axes", axis)
    clean = [p.split("[")[0].split(" ")[0] for p in parts]
    return tuple(clean[:4])
