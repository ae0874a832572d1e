"""Short runs of the compiled backend grouped into one dask task, so that the machinery's cost
per run (a task's round trip through the scheduler, the driver's handling of it, a folder
sync per file written) is paid per group, not per run.

:func:`group_by_cost` forms the groups from the driver's queue: consecutive runs, each group
about :data:`TASK_SECONDS` of run time predicted by the cost model
(:func:`nematic_solids.sweep.cost.model.model_seconds`), or ``execution.runs_per_task`` runs;
a run predicted to take longer is a task of its own, as is every run with ``runs_per_task:
1``. :func:`execute_group` runs a group on a worker: each run as
:func:`~nematic_solids.sweep.run.task.execute_run` runs it alone (its own run file, written
atomically, and its own record; the same numbers, bit for bit), the run files first, then one
sync of the runs folder, then the records (:func:`write_held`), then one more sync. A record
is thus written only once its run file is durable, as for a run alone.

A worker killed in a group loses the runs of the group that have no record yet (at most the
group's, about :data:`TASK_SECONDS` of work); dask gives the group to another worker, which
takes the records the first one wrote (:attr:`RunGroup.before`) and runs the rest.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from ..errors import StorageError
from ..expand import Expansion
from ..files import fsync_dir
from ..models.interface import cost_seconds
from ..models.registry import get_model
from ..store import CampaignStore, Record
from . import continuation
from .batch import group_runs
from .failures import crash_record
from .task import (
    UNSAVED,
    Held,
    RunTask,
    execute_run,
    finish_record,
    task_store,
    unsaved,
)

#: The predicted run time of one task of grouped runs (seconds): long enough that the cost
#: of a task (about 60 ms on the 2-core VM: benchmarks/bench_overhead.py, 200 tasks against 20)
#: is paid rarely, short enough that a lost worker loses little and the campaign's last tasks
#: end close together.
TASK_SECONDS = 0.5
#: The fewest tasks per worker thread that grouping leaves a campaign (so that the last
#: group to finish is a small part of the campaign).
TASKS_PER_THREAD = 4


@dataclass(frozen=True)
class RunGroup:
    """Runs of one campaign for one task (plain data, cheap to pickle): their run tasks, and
    the stamp ``(mtime_ns, size)`` of each run's record file when the driver planned it (None:
    none), by which a group given again after its worker was lost tells the records that an
    earlier try wrote from older ones."""

    tasks: tuple[RunTask, ...]
    before: tuple[tuple[int, int] | None, ...]


def group_size(predicted: float, runs: int, threads: int, runs_per_task: int | None) -> int:
    """How many runs of ``predicted`` seconds each go in one task: ``runs_per_task`` if the
    campaign gives it, else enough for :data:`TASK_SECONDS` but no more than leaves
    :data:`TASKS_PER_THREAD` tasks per worker thread for the ``runs`` to do (at least 1)."""
    if runs_per_task is not None:
        return max(1, runs_per_task)
    if not math.isfinite(predicted) or predicted <= 0:
        return 1
    by_time = math.floor(TASK_SECONDS / predicted)
    by_balance = math.ceil(runs / (TASKS_PER_THREAD * max(1, threads)))
    return max(1, min(by_time, by_balance))


def group_by_cost(queue: Sequence[int], size_of: Callable[[int], int]) -> list[list[int]]:
    """The runs ``queue`` in order, in groups of consecutive runs: a group ends once it holds
    ``size_of(i)`` runs for a run ``i`` it holds (runs of different sizes: the smallest)."""
    out: list[list[int]] = []
    group: list[int] = []
    limit = 0
    for i in queue:
        size = size_of(i)
        if group and len(group) >= min(limit, size):
            out.append(group)
            group = []
        limit = size if not group else min(limit, size)
        group.append(i)
    if group:
        out.append(group)
    return out


def tasks_of(
    expansion: Expansion, order: list[int], chained: bool, threads: int
) -> list[list[int]]:
    """The runs ``order`` in tasks: a chain's one per task (each waits for its predecessor);
    the accelerated backend's up to ``execution.batch`` seeds of one point per task; the
    compiled backend's grouped by their predicted time (:func:`group_size`; one per task for
    a model without a cost model)."""
    execution = expansion.campaign.execution
    if chained:
        return [[i] for i in order]
    if execution.backend == "accelerated":
        return group_runs(order, lambda i: expansion.run(i).point, execution.batch)
    sizes: dict[int, int] = {}  # per grid point (by identity): its runs alike
    model = get_model(expansion.campaign.model)

    def size_of(i: int) -> int:
        point = expansion.run(i).point
        if id(point) not in sizes:
            predicted = cost_seconds(model, point.parameters, point.numerics)
            sizes[id(point)] = group_size(predicted, len(order), threads, execution.runs_per_task)
        return sizes[id(point)]

    return group_by_cost(order, size_of)


def planned_stamp(records: Mapping[str, Record], run_id: str) -> tuple[int, int] | None:
    """The stamp ``(mtime_ns, size)`` of a run's record file when it was planned."""
    record = records.get(run_id)
    stamp = record.get("stamp") if record is not None else None
    return (int(stamp[0]), int(stamp[1])) if isinstance(stamp, list) and len(stamp) == 2 else None


def record_stamp(store: CampaignStore, run_id: str) -> tuple[int, int] | None:
    """``(mtime_ns, size)`` of a run's record file, or None without one."""
    try:
        st = os.stat(store.record_path(run_id))
    except OSError:
        return None
    return (st.st_mtime_ns, st.st_size)


def execute_group(group: RunGroup) -> list[Record]:
    """Run a group on a worker; return the records of its runs in the order of
    ``group.tasks`` (see the module docstring). A run whose record an earlier try of this
    group wrote is not run again: its record is returned."""
    records: dict[int, Record] = {}
    held: Held = []
    pending: dict[int, int] = {}  # position in the group -> position in held
    for k, (task, before) in enumerate(zip(group.tasks, group.before, strict=True)):
        store = task_store(task)
        stamp = record_stamp(store, task.run_id)
        if stamp is not None and stamp != before:
            earlier = store.read_record(task.run_id)
            if earlier is not None and earlier.get("status") in ("ok", "failed"):
                records[k] = earlier
                continue
        n, t0 = len(held), time.perf_counter()
        try:
            record = execute_run(task, held)
        except Exception as e:  # noqa: BLE001 - outside the run (its setup): it alone fails
            failed = crash_record(task, "exception", e, t0)
            record = finish_record(task, store, failed, continuation.Start(), t0, held)
        if len(held) > n:
            pending[k] = n
        else:  # not stored (UNSAVED): nothing to write
            records[k] = record
    written = write_held(held)
    for k, n in pending.items():
        records[k] = written[n]
    return [records[k] for k in range(len(group.tasks))]


def write_held(held: Held) -> list[Record]:
    """Write the records ``held`` (their run files are written): sync their folders, write each
    record, sync the folders again, then remove the runs' rolling checkpoints; return the
    records in order, the :data:`~nematic_solids.sweep.run.task.UNSAVED` record of each that
    could not be written (it stays pending)."""
    folders = {store.runs_dir for _, store, _, _ in held}
    for folder in folders:
        fsync_dir(folder)
    out: list[Record] = []
    for task, store, record, t0 in held:
        try:
            store.write_record(record, sync_dir=False)
        except StorageError as e:
            out.append(unsaved(task, e, None, {}, time.perf_counter() - t0))
        else:
            out.append(record)
    for folder in folders:
        fsync_dir(folder)
    for (task, store, _, _), record in zip(held, out, strict=True):
        if record.get("status") != UNSAVED:
            continuation.remove_checkpoint(store, task.run_id)
    return out
