"""Failure triage: the bound on failures that stops a campaign (``nematic run
--max-failures``) and the earlier failures a redone run's record keeps
(``previous_failures``)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..expand import RunSpec

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
