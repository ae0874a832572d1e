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

from ..campaign import Campaign, local_worker_count
from ..expand import Expansion
from ..lock import read_lock_holder
from ..store import RETRYABLE_REASONS, CampaignStore, Record

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


@dataclass
class _Tally:
    """What the records of a campaign's runs say, added run by run (:func:`campaign_status`):
    each run's state, the failures' reasons with examples and each reason's first run, the
    done runs other campaigns made, the wall times, who finished when, the unreadable runs."""

    #: per run of the expansion: 0 done, 1 failed, 2 pending (3: not planned)
    state: np.ndarray
    reasons: Counter[str] = field(default_factory=Counter)
    reused: Counter[str] = field(default_factory=Counter)
    examples: list[dict[str, Any]] = field(default_factory=list)
    #: reason -> its first failed run
    first: dict[str, dict[str, Any]] = field(default_factory=dict)
    times: list[float] = field(default_factory=list)
    #: (finish time, host:pid)
    finished: list[tuple[str, str]] = field(default_factory=list)
    unreadable: list[dict[str, str]] = field(default_factory=list)
    n_unreadable: int = 0

    def add(
        self, i: int, rid: str, rec: Record, expansion: Expansion, store: CampaignStore
    ) -> None:
        """Add run ``i`` (``rid``) of ``expansion`` from its record ``rec``."""
        problem = store.check_run_file(rid, rec)
        if problem is not None:  # the driver will redo it: pending
            if len(self.unreadable) < MAX_EXAMPLES:
                self.unreadable.append({"run_id": rid, "problem": problem})
            self.n_unreadable += 1
            return
        if rec.get("status") != "ok" and rec.get("reason") in RETRYABLE_REASONS:
            return
        if rec.get("status") == "ok":
            self.state[i] = 0
            if rec.get("reused_from"):
                self.reused[str(rec["reused_from"])] += 1
            wall = rec.get("wall_time")
            if isinstance(wall, (int, float)) and math.isfinite(wall):
                self.times.append(float(wall))
        else:
            self.state[i] = 1
            self._failed(i, rid, rec, expansion)
        if rec.get("finished"):
            self.finished.append((str(rec["finished"]), f"{rec.get('host')}:{rec.get('pid')}"))

    def _failed(self, i: int, rid: str, rec: Record, expansion: Expansion) -> None:
        reason = str(rec.get("reason") or "unknown")
        self.reasons[reason] += 1
        if len(self.examples) < MAX_EXAMPLES or reason not in self.first:
            run = expansion.run(i)
            example = {
                "run_id": rid,
                "coords": run.coords,
                "reason": reason,
                "detail": rec.get("detail") or "",
                "t_failed": rec.get("t_failed"),
            }
            if len(self.examples) < MAX_EXAMPLES:
                self.examples.append(example)
            if reason not in self.first:
                self.first[reason] = {
                    **example,
                    "finished": rec.get("finished"),
                    "has_file": rec.get("nc_bytes") is not None,
                }


def campaign_status(
    expansion: Expansion, store: CampaignStore, *, workers: int | None = None
) -> StatusReport:
    """The status of every run of ``expansion`` as recorded in ``store``."""
    campaign = expansion.campaign
    records = store.scan()
    n = len(expansion)
    tally = _Tally(np.full(n, 2, dtype=np.int8))
    planned = getattr(expansion, "planned", None)  # a refined campaign: its planned runs
    for i, rid in enumerate(expansion.run_ids):
        rec = records.get(rid)
        if rec is None or (planned is not None and not planned[i]):
            continue
        tally.add(i, rid, rec, expansion, store)
    state = tally.state
    if planned is not None:
        state[~planned] = 3
        n = int(planned.sum())
    done, failed = int((state == 0).sum()), int((state == 1).sum())
    pending = n - done - failed
    report = StatusReport(
        campaign=campaign.name,
        folder=str(store.root),
        total=n,
        done=done,
        failed=failed,
        pending=pending,
        per_axis=_per_axis(campaign, state),
        reasons=dict(tally.reasons.most_common()),
        examples=tally.examples,
        failure_groups=[_group(store, tally.first[r], k) for r, k in tally.reasons.most_common()],
        foreign_runs=len(set(records) - set(expansion.position)),
        unreadable=tally.n_unreadable,
        unreadable_examples=tally.unreadable,
        reused=dict(sorted(tally.reused.items())),
    )
    report.running = read_lock_holder(store.lock_path)
    for rid, info in store.in_progress().items():
        pos = expansion.position.get(rid)
        if pos is not None and state[pos] == 2:
            run = expansion.run(pos)
            report.in_progress.append(
                {"run_id": rid, "coords": run.coords, "t_final": run.point.numerics.t_final, **info}
            )
    if tally.times:
        report.mean_run_time = float(np.mean(tally.times))
        report.median_run_time = float(np.median(tally.times))
    if pending == 0:
        report.eta_seconds = 0.0
        return report
    _estimate_eta(report, workers or local_worker_count(campaign.execution), not workers, tally)
    return report


def _per_axis(campaign: Campaign, state: np.ndarray) -> list[AxisCounts]:
    """The done, failed and pending runs for each value of each sweep dim."""
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
    return per_axis


def _estimate_eta(report: StatusReport, w: int, seen: bool, tally: _Tally) -> None:
    """The ETA of the pending runs of ``report``: their median run time over ``w`` workers,
    or (``seen``: no worker count was given) over the processes that finished runs since the
    running driver started, when there are some."""
    concurrency = f"{w} worker(s)"
    if report.running and report.running.get("started") and seen:
        # the processes that finished runs since the running driver started
        start = _parse_time(report.running["started"])
        procs = {
            who
            for f, who in tally.finished
            if start is not None and (t := _parse_time(f)) is not None and t >= start
        }
        if procs:
            w = len(procs)
            concurrency = f"{w} worker(s) seen since the driver started"
    if report.median_run_time is not None:
        report.eta_seconds = report.pending * report.median_run_time / w
        report.eta_basis = f"median run time {report.median_run_time:.3g} s over {concurrency}"
