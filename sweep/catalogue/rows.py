"""A run as the catalogue holds it: the rows of one run record (``runs/<run_id>.json``) or of
one cell of a phase.nc, model-agnostic (every parameter, numeric, scalar and swept value goes
into JSON documents and key/value rows, whatever its name).

:class:`RunRow` is what the catalogue writes for one run of one campaign; the recorder, the
indexer and the reuse of runs across campaigns all build it here.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

#: numerics keys that say how far a run went (its ``t_final``), looked up in this order
T_FINAL_KEYS = ("t_final",)


def clean(value: Any) -> Any:
    """``value`` as JSON that SQLite and PostgreSQL both take: non-finite floats as None,
    numpy scalars as Python numbers, tuples as lists."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, Mapping):
        return {str(k): clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # a numpy scalar
        value = value.item()
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return str(value)


def _number(value: Any) -> float | None:
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, (int, float)):
        x = float(value)
        return x if math.isfinite(x) else None
    return None


def value_rows(run_id: str, space: str, values: Mapping[str, Any] | None) -> list[dict[str, Any]]:
    """The key/value rows of one JSON document: numbers as ``num_value``, words as
    ``text_value``; lists, mappings and missing values are left to the document."""
    out = []
    for key, value in (values or {}).items():
        num = _number(value)
        if num is not None:
            out.append(
                {
                    "run_id": run_id,
                    "space": space,
                    "key": str(key),
                    "num_value": num,
                    "text_value": None,
                }
            )
        elif isinstance(value, str):
            out.append(
                {
                    "run_id": run_id,
                    "space": space,
                    "key": str(key),
                    "num_value": None,
                    "text_value": value,
                }
            )
    return out


def _started(finished: Any, wall: Any) -> str | None:
    """When the run started: its end less its wall time (ISO 8601), if both are known."""
    w = _number(wall)
    if not isinstance(finished, str) or w is None:
        return None
    try:
        end = _dt.datetime.fromisoformat(finished)
    except ValueError:
        return None
    return (end - _dt.timedelta(seconds=w)).isoformat(timespec="seconds")


@dataclass
class RunRow:
    """One run of one campaign as the catalogue records it."""

    run_id: str
    campaign: str
    status: str
    source: str = "record"
    origin: str = "made"
    path: str | None = None
    trajectory_id: str | None = None
    reason: str | None = None
    detail: str | None = None
    started: str | None = None
    finished: str | None = None
    wall_time: float | None = None
    t_final: float | None = None
    end_state: float | None = None
    seed: int | None = None
    code_version: str | None = None
    parameters: dict[str, Any] = field(default_factory=dict)
    numerics: dict[str, Any] = field(default_factory=dict)
    scalars: dict[str, Any] = field(default_factory=dict)
    coords: dict[str, Any] = field(default_factory=dict)
    #: ``(parent run id, kind)``, kind in :data:`..schema.LINEAGE_KINDS`
    parents: list[tuple[str, str]] = field(default_factory=list)

    def run_values(self) -> dict[str, Any]:
        """The row of ``runs``, without ``seq``."""
        return {
            "run_id": self.run_id,
            "trajectory_id": self.trajectory_id,
            "status": self.status,
            "reason": self.reason,
            "detail": (self.detail or "")[:2000] or None,
            "started": self.started,
            "finished": self.finished,
            "wall_time": _number(self.wall_time),
            "t_final": _number(self.t_final),
            "end_state": _number(self.end_state),
            "seed": self.seed,
            "path": self.path,
            "source": self.source,
            "code_version": self.code_version,
            "parameters": clean(self.parameters),
            "numerics": clean(self.numerics),
            "scalars": clean(self.scalars),
        }

    def key_values(self) -> list[dict[str, Any]]:
        """The rows of ``run_values``."""
        out = []
        for space, doc in (
            ("parameters", self.parameters),
            ("numerics", self.numerics),
            ("scalars", self.scalars),
            ("coords", self.coords),
        ):
            out.extend(value_rows(self.run_id, space, doc))
        return out


def parse_origin(text: Any) -> tuple[str, str] | None:
    """``(campaign, run_id)`` of a run file's ``initial_from`` text ``campaign/run@time``."""
    if not isinstance(text, str) or "/" not in text:
        return None
    campaign, _, rest = text.partition("/")
    run_id = rest.split("@")[0]
    return (campaign, run_id) if campaign and run_id else None


def row_from_record(
    record: Mapping[str, Any], campaign: str, path: str | None, origin: str = "made"
) -> RunRow:
    """The row of one run record (a full ``runs/<id>.json``, or the record the worker
    returned); ``path``: its file relative to the results root (None: no file)."""
    numerics = dict(record.get("numerics") or {})
    t_final = next((numerics[k] for k in T_FINAL_KEYS if k in numerics), None)
    parents: list[tuple[str, str]] = []
    if record.get("continued_from"):
        parents.append((str(record["continued_from"]), "continued"))
    started_from = parse_origin(record.get("initial_from"))
    if started_from is not None:
        made_by = str(record.get("campaign") or campaign)
        kind = "chain" if started_from[0] == made_by else "initial_from"
        parents.append((started_from[1], kind))
    seed = record.get("seed")
    return RunRow(
        run_id=str(record["run_id"]),
        campaign=campaign,
        status=str(record.get("status") or "failed"),
        origin=origin,
        path=path if record.get("nc_bytes") is not None else None,
        trajectory_id=str(record.get("trajectory") or "") or None,
        reason=str(record.get("reason") or "") or None,
        detail=str(record.get("detail") or "") or None,
        started=_started(record.get("finished"), record.get("wall_time")),
        finished=record.get("finished") if isinstance(record.get("finished"), str) else None,
        wall_time=record.get("wall_time"),
        t_final=t_final,
        end_state=record.get("end_state"),
        seed=int(seed) if isinstance(seed, (int, float)) and not isinstance(seed, bool) else None,
        code_version=str(record.get("code_version") or "") or None,
        parameters=dict(record.get("parameters") or {}),
        numerics=numerics,
        scalars=dict(record.get("scalars") or {}),
        coords=dict(record.get("coords") or {}),
        parents=parents,
    )
