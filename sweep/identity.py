"""Run identity: ``run_id`` = hash of the canonical, normalised parameters + numerics + seed +
identity schema version (after signac's ``calc_id``).

Canonical form (:func:`canonical_json`): the *complete* parameter and numerics dicts (the
model's defaults filled in, ``alpha_minus_B`` resolved into ``alpha``), each value normalised
(floats to :data:`~nematic_solids.sweep.campaign.SIGNIFICANT_DIGITS` significant digits and written
as strings, so ``0.3`` and ``0.30000000000000004``, ``1e-5`` and ``0.00001``, ``1`` and ``1.0`` are
one value; ``-0.0`` is ``0``), keys sorted, compact JSON. The id is the first :data:`ID_LENGTH` hex
digits of its SHA-256.

Anything that changes a run's result or its file changes the id, so an id names one file's
content; the code version and the backend (:data:`EXECUTION_ONLY`: compiled or numpy, equal
to rounding) do not enter (they are recorded in the file instead).
Bump :data:`SCHEMA_VERSION` only when the canonical form itself changes.

A run's end (``t_final``) is part of its id: a run file holds one run to one end, and no
result of one ``t_final`` is read as another's. The runs of one trajectory to different ends
share a :func:`trajectory_id` (the id without ``t_final``), by which a longer run finds the
shorter finished run whose end state it continues.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.protocol import RAMP_STEP_FRACTION, SINE_STEP_FRACTION

from .campaign import DEFAULT_MODEL, SIGNIFICANT_DIGITS

SCHEMA_VERSION = 1
ID_LENGTH = 16
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


def canonical_value(value: Any) -> Any:
    """One value in canonical form (JSON-ready): floats as ``'%.12g'`` strings."""
    kind = type(value)  # the common exact types first (the grid check canonicalises each point)
    if kind is float:
        return _canonical_float(value)
    if kind is str:
        return value
    if kind is dict:
        return {str(k): canonical_value(v) for k, v in value.items()}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return _canonical_float(float(value))
    if isinstance(value, str):
        return value
    if value is None:
        return None
    if isinstance(value, Mapping):
        return {str(k): canonical_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [canonical_value(v) for v in value]
    raise TypeError(f"cannot canonicalise {value!r} of type {type(value).__name__}")


@functools.lru_cache(maxsize=2**14)  # a grid's points share most of their values
def _canonical_float(x: float) -> str:
    if not math.isfinite(x):
        return str(x)
    text = f"{x:.{SIGNIFICANT_DIGITS}g}"
    return "0" if float(text) == 0 else text


def _dumps(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True)


def canonical_json(
    parameters: Mapping[str, Any],
    numerics: Mapping[str, Any],
    seed: int,
    start: Mapping[str, str] | None = None,
    model: str = DEFAULT_MODEL,
) -> str:
    """The canonical text that is hashed. The mappings are taken as given: pass complete
    dicts (``Parameters.to_dict()``), or use :func:`run_id_for`. ``start`` names the state
    a run begins from (``{"run": parent run id, "time": "end" or the time}``,
    :class:`nematic_solids.sweep.expand.Parents`); absent for a run from the seeded texture.
    ``model`` (the campaign's ``model:``) enters the text only where it is not the default
    model, so every run of the default model keeps its id."""
    payload = _point_payload(parameters, numerics, model)
    payload["seed"] = canonical_value(int(seed))
    if start is not None:
        payload["start"] = canonical_value(dict(start))
        # the paper's finite strain only (another model's numerics name no mechanics)
        guess = start_guess(numerics, start) if model == DEFAULT_MODEL else None
        if guess is not None:
            payload["start_guess"] = guess
    return _dumps(payload)


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


def _point_payload(
    parameters: Mapping[str, Any], numerics: Mapping[str, Any], model: str = DEFAULT_MODEL
) -> dict[str, Any]:
    """What the canonical text holds of a grid point (all its keys sort before ``seed``)."""
    payload: dict[str, Any] = {
        "numerics": canonical_value(identity_numerics(numerics)),
        "parameters": canonical_value(identity_parameters(parameters)),
        "schema": SCHEMA_VERSION,
    }
    rule = protocol_step_rule(parameters, numerics)
    if rule is not None:
        payload["protocol_steps"] = rule
    if model != DEFAULT_MODEL:
        payload["model"] = model
    return payload


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


def hash_canonical(
    parameters: Mapping[str, Any],
    numerics: Mapping[str, Any],
    seed: int,
    start: Mapping[str, str] | None = None,
    model: str = DEFAULT_MODEL,
) -> str:
    """run_id of complete parameter / numerics dicts (no defaults filled in) of ``model``."""
    text = canonical_json(parameters, numerics, seed, start, model)
    return hashlib.sha256(text.encode("ascii")).hexdigest()[:ID_LENGTH]


def run_id_for(
    parameters: Parameters | Mapping[str, Any], numerics: Numerics | Mapping[str, Any], seed: int
) -> str:
    """run_id of one run; mappings go through the model's objects first (defaults filled in,
    ``alpha_minus_B`` resolved, values validated)."""
    p = parameters if isinstance(parameters, Parameters) else Parameters.from_dict(parameters)
    n = numerics if isinstance(numerics, Numerics) else Numerics.from_dict(numerics)
    return hash_canonical(p.to_dict(), n.to_dict(), seed)


#: the keys of a run's ``start`` that enter its identity: the parent ``run``, the ``time`` ("end"
#: or the time) and, when it is not the exact end state or an exact snapshot, the ``state``
START_KEYS = ("run", "time", "state")
#: what a run begins from when it is not its parent's exact state (:func:`start_state`)
SNAPSHOT = "snapshot"


def start_state(time: str, end_state: bool, dtype: str, fields: tuple[str, ...] | None) -> str:
    """The ``state`` of a run of ``initial.from`` as its identity names it: "" for the parent's
    exact end state (``time`` "end", the parent keeps end states) or a float64 snapshot of every
    field at ``time`` (the exact fields then); else ``"snapshot (<precision>, <fields>)"``: a
    run begun from it computes other numbers, so it has another id (and its record a
    warning). Chains always begin from exact end states (their validation asks for them)."""
    exact_snapshot = dtype == "float64" and fields is None
    if (time == "end" and end_state) or (time != "end" and exact_snapshot):
        return ""
    kept = f"{dtype}, {'all fields' if fields is None else ' '.join(fields)}"
    return f"{SNAPSHOT} ({kept})"


def identity_start(start: Mapping[str, Any] | None) -> dict[str, str] | None:
    """The part of a run's ``start`` that enters its identity (:data:`START_KEYS`)."""
    if start is None:
        return None
    return {k: str(start[k]) for k in START_KEYS if start.get(k)}


#: The numerics a run can be continued past (nematic_solids.model.checkpoint.MAY_DIFFER): left out
#: of its trajectory's id.
CONTINUABLE = ("t_final", "snapshot_times")


def trajectory_id(
    parameters: Mapping[str, Any],
    numerics: Mapping[str, Any],
    seed: int,
    start: Mapping[str, str] | None = None,
    model: str = DEFAULT_MODEL,
) -> str:
    """The id of a run's trajectory: the hash of its canonical text without ``t_final`` and
    ``snapshot_times``, shared by the runs of one (parameters, numerics, seed) to different
    ends, so a longer run finds
    the shorter ones it continues (:mod:`nematic_solids.sweep.run.continuation`). Complete dicts, as
    for :func:`hash_canonical`; never a run_id (a run's canonical numerics always holds
    ``t_final``)."""
    return hash_canonical(
        parameters, {k: v for k, v in numerics.items() if k not in CONTINUABLE}, seed, start, model
    )


class PointIdentity:
    """A key of grid points that is equal for two points exactly when their runs (one seed, from
    the seeded texture) have one :func:`hash_canonical` id: the canonical text's parts, not
    hashed, the numerics canonicalised once per distinct value (a grid's points mostly share
    them). The validation's check that no two grid points are one run
    (``sweep.spec.points``) keys every point by it."""

    def __init__(self) -> None:
        self._numerics: dict[Numerics, tuple[dict[str, Any], str]] = {}

    def __call__(self, parameters: Parameters, numerics: Numerics) -> tuple[str, str, str | None]:
        known = self._numerics.get(numerics)
        if known is None:
            n = numerics.to_dict()
            known = self._numerics[numerics] = (n, _dumps(canonical_value(identity_numerics(n))))
        p = parameters.to_dict()
        text = _dumps(canonical_value(identity_parameters(p)))
        return text, known[1], protocol_step_rule(p, known[0])


class PointHasher:
    """run_ids of many seeds at one grid point, hashing the shared prefix once.

    Equal to :func:`hash_canonical` ("seed" is the last key in sorted order, so the canonical
    text is ``prefix + '"seed":"<seed>"}'``); checked by the tests.
    """

    def __init__(
        self,
        parameters: Mapping[str, Any],
        numerics: Mapping[str, Any],
        model: str = DEFAULT_MODEL,
    ):
        head = _dumps(_point_payload(parameters, numerics, model))
        self._prefix = hashlib.sha256((head[:-1] + ',"seed":').encode("ascii"))

    def __call__(self, seed: int) -> str:
        return self.many([seed])[0]

    def many(self, seeds: Iterable[int]) -> list[str]:
        out = []
        for suffix in seed_suffixes(tuple(seeds)):
            h = self._prefix.copy()
            h.update(suffix)
            out.append(h.hexdigest()[:ID_LENGTH])
        return out


@functools.lru_cache(maxsize=8)
def seed_suffixes(seeds: tuple[int, ...]) -> list[bytes]:
    """The canonical text's tail for each seed: ``'"<seed>"}'``."""
    return [(_dumps(canonical_value(int(s))) + "}").encode("ascii") for s in seeds]
