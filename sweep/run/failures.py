"""Failures of runs: the record of a run that failed before it produced a result (a crash, a
MemoryError, a task that could not even be set up on its worker), the bound on failures that
stops a campaign (``nematic run --max-failures``) and the earlier failures a redone run's
record keeps (``previous_failures``)."""

from __future__ import annotations

import math
import socket
import time
import traceback
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, cast

from ..limits import OUT_OF_MEMORY, out_of_memory
from ..store import Record, now_iso

if TYPE_CHECKING:
    from ..expand import RunSpec


class FailedTask(Protocol):
    """What a failure record needs of a run's task
    (:class:`nematic_solids.sweep.run.task.RunTask` is one)."""

    @property
    def run_id(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def numerics(self) -> dict[str, Any]: ...
    @property
    def coords(self) -> dict[str, Any]: ...
    def identity(self) -> dict[str, Any]: ...


def failure_record(task: FailedTask, reason: str, detail: str, tb: str, wall: float) -> Record:
    """The record of a run that failed (or was lost) before it produced a result."""
    return {
        "run_id": task.run_id,
        "status": "failed",
        "reason": reason,
        "detail": detail,
        "t_failed": None,
        "traceback": tb,
        "seed": task.seed,
        "wall_time": wall,
        "nc_bytes": None,
        "scalars": {},
        "code_version": "",
        "git_commit": "",
        "finished": now_iso(),
        "host": socket.gethostname(),
    }


def crash_record(
    task: FailedTask, reason: str, error: Exception, t0: float, seeds: int = 1
) -> Record:
    """The failure record of ``error``, being handled (its traceback), for a run started at
    ``t0`` (``time.perf_counter``); a MemoryError is recorded as :data:`OUT_OF_MEMORY` with
    what the run needed (``seeds``: computed together with it, an accelerated batch)."""
    detail = f"{type(error).__name__}: {error}"
    if isinstance(error, MemoryError):
        reason, detail = OUT_OF_MEMORY, out_of_memory(task.numerics, error, seeds)
    return failure_record(task, reason, detail, traceback.format_exc(), time.perf_counter() - t0)


def describe_run(task: FailedTask) -> str:
    """The run in words: its id, its point (swept values) and its seed."""
    coords = ", ".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in task.coords.items()
    )
    return f"run {task.run_id} ({coords + ', ' if coords else ''}seed {task.seed})"


def setup_failure_record(task: FailedTask, error: BaseException, seeds: int = 1) -> Record:
    """The record of a run whose task raised before its model ran (what the driver gets back
    instead of a record: the task could not be unpickled, its model not imported, its folder
    not opened on the worker). It names the run and where it failed; a MemoryError is
    recorded as :data:`OUT_OF_MEMORY` with what the run needs and what to do, as one raised
    by the run itself (:func:`crash_record`). ``seeds``: the runs its task held."""
    where = (
        f"{describe_run(task)} failed while its task was set up on its worker, before the model ran"
    )
    if isinstance(error, MemoryError):
        reason = OUT_OF_MEMORY
        detail = f"{where}: {out_of_memory(task.numerics, error, seeds)}"
    else:
        reason = "exception"
        detail = f"{where}: {type(error).__name__}: {error}"
    tb = "".join(traceback.format_exception(type(error), error, error.__traceback__))
    record = failure_record(task, reason, detail, tb, math.nan)
    record.update(cast(Record, task.identity()))
    return record


#: What a record's ``previous_failures`` entry keeps of the failure it replaces.
PREVIOUS_FAILURE_KEYS = (
    "reason",
    "detail",
    "t_failed",
    "finished",
    "wall_time",
    "host",
    "pid",
    "code_version",
    "git_commit",
    "traceback",
)


def previous_failures(record: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The failures a new attempt of a failed run keeps: the earlier ones the record carries,
    oldest first, then the record's own failure."""
    earlier = record.get("previous_failures")
    out = [dict(x) for x in earlier if isinstance(x, Mapping)] if isinstance(earlier, list) else []
    out.append({k: record.get(k) for k in PREVIOUS_FAILURE_KEYS})
    return out


@dataclass
class FailureLimit:
    """``--max-failures``: the campaign stops once more runs failed in this session than a
    count (``5``; ``0`` stops at the first failure) or than a fraction (``0.1``) of the runs
    this session set out to do (for an adaptive campaign, the runs of its rounds so far)."""

    count: int | None = None
    fraction: float | None = None
    #: runs this session set out to do, and how many of them failed (by reason)
    planned: int = 0
    failed: int = 0
    reasons: Counter[str] = field(default_factory=Counter)

    @classmethod
    def parse(cls, text: str) -> FailureLimit:
        """A count (a whole number >= 0) or a fraction (a number between 0 and 1, exclusive);
        raises ``ValueError`` with what is allowed."""
        value = text.strip()
        allowed = (
            "a count of runs (a whole number, 0 stops at the first failure) or a "
            "fraction of the runs to do (a number between 0 and 1, e.g. 0.1)"
        )
        if value.isdigit():
            return cls(count=int(value))
        try:
            x = float(value)
        except ValueError:
            raise ValueError(f"--max-failures: got {text!r}; allowed: {allowed}") from None
        if math.isfinite(x) and 0 < x < 1:
            return cls(fraction=x)
        raise ValueError(f"--max-failures: got {text!r}; allowed: {allowed}")

    @property
    def allowed(self) -> float:
        """The failures this session may have without stopping."""
        if self.count is not None:
            return float(self.count)
        return (self.fraction or 0.0) * self.planned

    def add_failure(self, record: Mapping[str, Any]) -> bool:
        """Count a failed run; ``True`` when the bound is now exceeded."""
        self.failed += 1
        self.reasons[str(record.get("reason") or "unknown")] += 1
        return self.exceeded

    @property
    def exceeded(self) -> bool:
        return self.failed > self.allowed

    def describe(self) -> str:
        if self.count is not None:
            return f"--max-failures {self.count}"
        return (
            f"--max-failures {self.fraction:g}: {self.allowed:g} of the {self.planned} run(s) to do"
        )

    def message(self) -> str:
        """Why the campaign stopped (one sentence)."""
        reasons = ", ".join(f"{k}: {v}" for k, v in self.reasons.most_common())
        return (
            f"too many runs failed: {self.failed} failed this session, more than "
            f"{self.describe()} allows ({reasons})"
        )


def describe_failure(run: RunSpec, record: Mapping[str, Any]) -> str:
    """One line: the run, its swept values and seed, why and when it failed."""
    coords = ", ".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in run.coords.items()
    )
    when = record.get("t_failed")
    at = f" at t = {when:.4g}" if isinstance(when, (int, float)) and math.isfinite(when) else ""
    detail = str(record.get("detail") or "").strip().splitlines()
    return f"run {run.run_id} ({coords}) failed: {record.get('reason') or 'unknown'}{at}" + (
        f": {detail[-1]}" if detail else ""
    )
