"""How the nematic model's points enter run identity (:mod:`nematic_solids.sweep.identity`):
the rules that keep every run made before a setting existed under its id, the protocol's step
bound and the first guess of a finite-strain run begun from an end state
(:class:`~.interface.IdentityRules`, implemented by :class:`~.nematic.Nematic`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from nematic_solids.model.protocol import RAMP_STEP_FRACTION, SINE_STEP_FRACTION

#: Numerics fields that change nothing while early stop is off (``steady_tol = 0``): left
#: out of the canonical text then, so a run keeps the id it had before they existed.
EARLY_STOP = ("steady_tol", "steady_window")
#: Numerics fields that choose how a run is executed, not what it computes (the backends
#: agree to rounding): recorded in the run file, never part of the identity.
EXECUTION_ONLY = ("backend",)
#: Numerics fields added later whose default changes nothing: left out of the canonical text
#: at that default, so earlier runs keep their ids (``precision``: float64, what every run
#: computed before the field existed; float32 enters the id).
LATER_NUMERICS_DEFAULTS = {"precision": "float64"}
#: The parameter that chooses the initial texture: left out of the canonical text at its
#: original value ("band", the only texture before the field existed), so those runs keep their
#: ids; with "per_node" the band's ``noise_modes`` changes nothing and is left out instead.
TEXTURE, TEXTURE_ORIGINAL = "initial", "band"
#: Parameters added later whose default changes nothing: left out of the canonical text at
#: that default, so earlier runs keep their ids.
LATER_DEFAULTS = {"texture_resolution": 0, "coupling": "trP"}


def identity_parameters(parameters: Mapping[str, Any]) -> dict[str, Any]:
    """The parameters as they enter the canonical text: without ``initial`` while it is
    "band", without the unused ``noise_modes`` while it is "per_node", without
    ``texture_resolution`` while it is 0."""
    out = dict(parameters)
    for name, default in LATER_DEFAULTS.items():
        if name in out and out[name] == default:
            del out[name]
    if out.get(TEXTURE, TEXTURE_ORIGINAL) == TEXTURE_ORIGINAL:
        out.pop(TEXTURE, None)
    else:
        out.pop("noise_modes", None)
    return out


def identity_numerics(numerics: Mapping[str, Any]) -> dict[str, Any]:
    """The numerics as they enter the canonical text: without the execution-only fields,
    without ``precision`` while it is float64, and without the early-stop fields while early
    stop is off."""
    out = {k: v for k, v in numerics.items() if k not in EXECUTION_ONLY}
    for name, default in LATER_NUMERICS_DEFAULTS.items():
        if name in out and out[name] == default:
            del out[name]
    if not out.get("steady_tol"):
        for name in EARLY_STOP:
            out.pop(name, None)
    return out


#: The first guess of the displacement of a finite-strain run begun from an exact end state (a
#: chain's successor, a run of ``initial.from`` at ``time: end``), as it enters the canonical
#: text: the end state's own displacement spectrum, bit for bit.
EXACT_GUESS = "end state displacement spectrum"


def start_guess(numerics: Mapping[str, Any], start: Mapping[str, Any]) -> str | None:
    """:data:`EXACT_GUESS` where a run's force balance at t = 0 is solved from the exact end
    state's displacement spectrum: finite strain, from an end state (``time`` "end", no
    snapshot ``state``). Runs made before began from the end snapshot's displacement, and
    Newton's solve stops at an iterate that depends on its first guess (numbers apart by
    rounding, up to the Newton tolerance): those runs have the ids without it. None where
    nothing changed: linear strain (no guess), a start from a snapshot, the seeded texture."""
    if start.get("time") != "end" or start.get("state"):
        return None
    return EXACT_GUESS if numerics.get("mechanics", "finite") == "finite" else None


def protocol_step_rule(parameters: Mapping[str, Any], numerics: Mapping[str, Any]) -> str | None:
    """The bound on the step that a run's sine or ramp imposes
    (:data:`~nematic_solids.model.protocol.SINE_STEP_FRACTION` of a period,
    :data:`~nematic_solids.model.protocol.RAMP_STEP_FRACTION` of a ramp piece) as it enters the
    canonical text, where it can change the steps, so the numbers: where the shortest such bound
    is below the largest step the run may take otherwise (``dt_max``, or ``dt`` for fixed
    steps). Runs made before the bound existed then have other ids. None where no bound is
    below it (a slow sine, a run with steps and pulses only, which land on their switch
    times): the id is unchanged."""
    protocol = parameters.get("protocol") or {}
    bounds = [math.inf]
    for spec in protocol.values():
        if not isinstance(spec, Mapping):
            continue
        if "sine" in spec:
            bounds.append(float(spec["sine"]["period"]) * SINE_STEP_FRACTION)
        if "ramp" in spec:
            times = [float(t) for t, _ in spec["ramp"]]
            bounds += [(b - a) * RAMP_STEP_FRACTION for a, b in zip(times, times[1:], strict=False)]
    largest = numerics.get("dt_max" if numerics.get("adaptive", True) else "dt", math.inf)
    if not min(bounds) < float(largest):
        return None
    return f"sine {SINE_STEP_FRACTION:.12g}, ramp {RAMP_STEP_FRACTION:.12g}"


def identity_settings(
    parameters: Mapping[str, Any], numerics: Mapping[str, Any]
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """The parameters and numerics as they enter the canonical text, and the protocol's step
    bound where it changes the steps (``protocol_steps``)."""
    extra: dict[str, Any] = {}
    rule = protocol_step_rule(parameters, numerics)
    if rule is not None:
        extra["protocol_steps"] = rule
    return identity_parameters(parameters), identity_numerics(numerics), extra


def start_identity(numerics: Mapping[str, Any], start: Mapping[str, Any]) -> dict[str, Any]:
    """What a run's start adds to the canonical text: the first guess (:func:`start_guess`)."""
    guess = start_guess(numerics, start)
    return {} if guess is None else {"start_guess": guess}
