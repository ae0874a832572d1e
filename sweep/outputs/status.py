"""Where a campaign stands: done / failed / pending overall and per sweep value, the failures'
reasons, an ETA. Reads the manifest, the directory listing and one ``stat`` per run file
(a file whose size or mtime differs from its record is checksummed: the driver's check,
:meth:`~nematic_solids.sweep.store.CampaignStore.check_run_file`), so it answers in about 3 s for
10^5 runs (``benchmarks/status_100k.py``)."""

from __future__ import annotations

import datetime as _dt
import math
from collections import Counter
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..campaign import local_worker_count
from ..expand import Expansion
from ..lock import read_lock_holder
from ..store import RETRYABLE_REASONS, CampaignStore

DONE, FAILED, PENDING = "done", "failed", "pending"
MAX_EXAMPLES = 10


@dataclass
class AxisCounts:
    """Counts for each value of one sweep dim (a zip group lists all its axes' values)."""

    dim: str
    labels: list[str]
    done: list[int]
    failed: list[int]
    pending: list[int]


@dataclass
class StatusReport:
    campaign: str
    folder: str
    total: int
    done: int
    failed: int
    pending: int
    per_axis: list[AxisCounts] = field(default_factory=list)
    reasons: dict[str, int] = field(default_factory=dict)
    examples: list[dict[str, Any]] = field(default_factory=list)
    #: one entry per failure reason, most frequent first: ``reason``, ``count`` and the first
    #: failed run of that reason (in the campaign's run order): ``run_id``, ``coords`` (swept
    #: values and seed), ``parameters`` (the full set, from its record), ``t_failed`` (model
    #: time), ``finished`` (when), ``detail``, ``record`` (its JSON, with the traceback) and
    #: ``run_file`` (its partial time series, ``None`` when the run left none)
    failure_groups: list[dict[str, Any]] = field(default_factory=list)
    mean_run_time: float | None = None
    #: the median of the successful runs' wall times: the ETA's basis (a first run that
    #: compiled the kernels, or a few slow ones, barely move it)
    median_run_time: float | None = None
    eta_seconds: float | None = None
    eta_basis: str = ""
    running: dict[str, Any] | None = None
    foreign_runs: int = 0
    #: runs whose file is missing, truncated or corrupt (counted as pending: redone by `run`)
    unreadable: int = 0
    unreadable_examples: list[dict[str, str]] = field(default_factory=list)
    #: pending runs with a rolling checkpoint (in progress, or interrupted): ``run_id``,
    #: ``coords``, ``t`` (the time reached), ``t_final``, ``checkpoint`` (its path), ``written``
    in_progress: list[dict[str, Any]] = field(default_factory=list)
    #: done runs another campaign of the results root made, taken in place: campaign -> how
    #: many (:mod:`nematic_solids.sweep.catalogue.reuse`)
    reused: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _label(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _parse_time(text: Any) -> float | None:
    try:
        return _dt.datetime.fromisoformat(str(text)).timestamp()
    except ValueError:
        return None


def _group(store: CampaignStore, example: dict[str, Any], count: int) -> dict[str, Any]:
    """A failure reason's entry of :attr:`StatusReport.failure_groups` (reads one record)."""
    rid = example["run_id"]
    full = store.read_record(rid) or {}
    return {
        "reason": example["reason"],
        "count": count,
        "run_id": rid,
        "coords": example["coords"],
        "parameters": full.get("parameters") or {},
        "t_failed": example["t_failed"],
        "finished": example["finished"],
        "detail": example["detail"],
        "record": str(store.record_path(rid)),
        "run_file": str(store.nc_path(rid)) if example["has_file"] else None,
    }


def campaign_status(
    expansion: Expansion, store: CampaignStore, *, workers: int | None = None
) -> StatusReport:
    """The status of every run of ``expansion`` as recorded in ``store``."""
    campaign = expansion.campaign
    records = store.scan()
    n = len(expansion)
    state = np.full(n, 2, dtype=np.int8)  # 0 done, 1 failed, 2 pending
    reasons: Counter[str] = Counter()
    reused: Counter[str] = Counter()
    examples: list[dict[str, Any]] = []
    first: dict[str, dict[str, Any]] = {}  # reason -> its first failed run
    times: list[float] = []
    finished: list[tuple[str, str]] = []  # (finish time, host:pid)
    unreadable: list[dict[str, str]] = []
    n_unreadable = 0
    planned = getattr(expansion, "planned", None)  # a refined campaign: its planned runs
    for i, rid in enumerate(expansion.run_ids):
        rec = records.get(rid)
        if rec is None or (planned is not None and not planned[i]):
            continue
        problem = store.check_run_file(rid, rec)
        if problem is not None:  # the driver will redo it: pending
            if len(unreadable) < MAX_EXAMPLES:
                unreadable.append({"run_id": rid, "problem": problem})
            n_unreadable += 1
            continue
        if rec.get("status") != "ok" and rec.get("reason") in RETRYABLE_REASONS:
            continue
        if rec.get("status") == "ok":
            state[i] = 0
            if rec.get("reused_from"):
                reused[str(rec["reused_from"])] += 1
            wall = rec.get("wall_time")
            if isinstance(wall, (int, float)) and math.isfinite(wall):
                times.append(float(wall))
        else:
            state[i] = 1
            reason = str(rec.get("reason") or "unknown")
            reasons[reason] += 1
            if len(examples) < MAX_EXAMPLES or reason not in first:
                run = expansion.run(i)
                example = {
                    "run_id": rid,
                    "coords": run.coords,
                    "reason": reason,
                    "detail": rec.get("detail") or "",
                    "t_failed": rec.get("t_failed"),
                }
                if len(examples) < MAX_EXAMPLES:
                    examples.append(example)
                if reason not in first:
                    first[reason] = {
                        **example,
                        "finished": rec.get("finished"),
                        "has_file": rec.get("nc_bytes") is not None,
                    }
        if rec.get("finished"):
            finished.append((str(rec["finished"]), f"{rec.get('host')}:{rec.get('pid')}"))
    if planned is not None:
        state[~planned] = 3
        n = int(planned.sum())
    done, failed = int((state == 0).sum()), int((state == 1).sum())
    pending = n - done - failed

    shaped = state.reshape(*campaign.shape, len(campaign.seeds))
    per_axis = []
    for k, d in enumerate(campaign.dims):
        other = tuple(j for j in range(shaped.ndim) if j != k)
        labels = [" / ".join(_label(a.values[i]) for a in d.axes) for i in range(len(d))]
        name = " / ".join(a.name for a in d.axes)
        per_axis.append(
            AxisCounts(
                dim=name,
                labels=labels,
                done=[int(x) for x in (shaped == 0).sum(axis=other)],
                failed=[int(x) for x in (shaped == 1).sum(axis=other)],
                pending=[int(x) for x in (shaped == 2).sum(axis=other)],
            )
        )

    report = StatusReport(
        campaign=campaign.name,
        folder=str(store.root),
        total=n,
        done=done,
        failed=failed,
        pending=pending,
        per_axis=per_axis,
        reasons=dict(reasons.most_common()),
        examples=examples,
        failure_groups=[_group(store, first[r], k) for r, k in reasons.most_common()],
        foreign_runs=len(set(records) - set(expansion.position)),
        unreadable=n_unreadable,
        unreadable_examples=unreadable,
        reused=dict(sorted(reused.items())),
    )
    report.running = read_lock_holder(store.lock_path)
    for rid, info in store.in_progress().items():
        pos = expansion.position.get(rid)
        if pos is not None and state[pos] == 2:
            run = expansion.run(pos)
            report.in_progress.append(
                {"run_id": rid, "coords": run.coords, "t_final": run.point.numerics.t_final, **info}
            )
    if times:
        report.mean_run_time = float(np.mean(times))
        report.median_run_time = float(np.median(times))
    if pending == 0:
        report.eta_seconds = 0.0
        return report
    w = workers or local_worker_count(campaign.execution)
    concurrency = f"{w} worker(s)"
    if report.running and report.running.get("started") and not workers:
        # the processes that finished runs since the running driver started
        start = _parse_time(report.running["started"])
        procs = {
            who
            for f, who in finished
            if start is not None and (t := _parse_time(f)) is not None and t >= start
        }
        if procs:
            w = len(procs)
            concurrency = f"{w} worker(s) seen since the driver started"
    if report.median_run_time is not None:
        report.eta_seconds = pending * report.median_run_time / w
        report.eta_basis = f"median run time {report.median_run_time:.3g} s over {concurrency}"
    return report
