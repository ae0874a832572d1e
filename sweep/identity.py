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

from .campaign import DEFAULT_MODEL, SIGNIFICANT_DIGITS
from .models.interface import IdentityRules
from .models.registry import get_model

SCHEMA_VERSION = 1
ID_LENGTH = 16


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
        rules = _rules(model)
        if rules is not None:
            payload.update(rules.start_identity(numerics, start))
    return _dumps(payload)


@functools.cache
def _rules(model: str) -> IdentityRules | None:
    m = get_model(model)
    return m if isinstance(m, IdentityRules) else None


@functools.cache
def _execution(model: str) -> frozenset[str]:
    return frozenset(s.name for s in get_model(model).settings if s.execution)


def identity_settings(
    parameters: Mapping[str, Any], numerics: Mapping[str, Any], model: str = DEFAULT_MODEL
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """The parameters and numerics as they enter the canonical text, and what else the
    model's point adds to it: by the model's own rules
    (:class:`~nematic_solids.sweep.models.interface.IdentityRules`), else every setting but
    those that choose only how a run executes (``Setting.execution``)."""
    rules = _rules(model)
    if rules is not None:
        return rules.identity_settings(parameters, numerics)
    drop = _execution(model)
    return (
        {k: v for k, v in parameters.items() if k not in drop},
        {k: v for k, v in numerics.items() if k not in drop},
        {},
    )


def _point_payload(
    parameters: Mapping[str, Any], numerics: Mapping[str, Any], model: str = DEFAULT_MODEL
) -> dict[str, Any]:
    """What the canonical text holds of a grid point (all its keys sort before ``seed``)."""
    p, n, extra = identity_settings(parameters, numerics, model)
    payload: dict[str, Any] = {
        "numerics": canonical_value(n),
        "parameters": canonical_value(p),
        "schema": SCHEMA_VERSION,
        **extra,
    }
    if model != DEFAULT_MODEL:
        payload["model"] = model
    return payload


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
    parameters: Any,
    numerics: Any,
    seed: int,
    model: str = DEFAULT_MODEL,
) -> str:
    """run_id of one run of ``model``; mappings go through the model's objects first
    (:meth:`~nematic_solids.sweep.models.interface.Model.point`: defaults filled in, values
    validated)."""
    if not (hasattr(parameters, "to_dict") and hasattr(numerics, "to_dict")):  # plain dicts
        parameters, numerics = get_model(model).point(
            parameters.to_dict() if hasattr(parameters, "to_dict") else parameters,
            numerics.to_dict() if hasattr(numerics, "to_dict") else numerics,
        )
    return hash_canonical(parameters.to_dict(), numerics.to_dict(), seed, model=model)


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

    def __init__(self, model: str = DEFAULT_MODEL) -> None:
        self.model = model
        self._numerics: dict[Any, dict[str, Any]] = {}

    def __call__(self, parameters: Any, numerics: Any) -> tuple[str, str, str]:
        n = self._numerics.get(numerics)
        if n is None:
            n = self._numerics[numerics] = numerics.to_dict()
        p, n, extra = identity_settings(parameters.to_dict(), n, self.model)
        return _dumps(canonical_value(p)), _dumps(canonical_value(n)), _dumps(extra)


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
