"""The worker task of the accelerated backend (``execution: {backend: accelerated, batch: N}``):
several seeds of one grid point in one task, advanced together on a device by
:meth:`run_batch` of the campaign's model (the nematic model's:
:func:`nematic_solids.model.accelerated.datasets.batch_datasets`), each seed written as its own run
(its run file and record, by :func:`nematic_solids.sweep.run.task.save_result`, exactly as a
compiled run's), so that identity, aggregation, resumption and the failure rules stay per run.

:func:`group_runs` forms the batches (the driver's queue order kept, only runs of one point
together); :func:`execute_batch` runs one. A seed that fails (its own reason and time, from the
device) fails alone: its batch-mates' files are those they have when the batch has no failing
seed. Checkpoints and continuation are a compiled run's: each seed hands its state to its own
rolling checkpoint at the times ``store.checkpoint_every`` makes due and keeps its end state in
its run file (``store.end_state``); seeds that start from states (their checkpoints, or the end
states of finished shorter runs of their trajectories: of either backend) continue from them,
those at one time in one batch (a batch advances to common save times), the others from t = 0.
A batch continued from its own states ends bitwise as the batch that never stopped.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ..campaign import DEFAULT_MODEL
from ..models.interface import batched
from ..models.registry import get_model
from ..store import Record
from . import continuation
from .failures import crash_record
from .task import (
    RunTask,
    execute_run,
    finish_record,
    request,
    save_result,
    task_store,
)


@dataclass(frozen=True)
class BatchTask:
    """Seeds of one point (plain data, cheap to pickle): their run tasks, the device."""

    tasks: tuple[RunTask, ...]
    device: str = "auto"


def group_runs(
    queue: Sequence[int], point_of: Callable[[int], object], size: int
) -> list[list[int]]:
    """The runs ``queue`` in batches of at most ``size`` runs of one point each (the point of a
    run: ``point_of(i)``, compared by identity), in the order of each batch's first run."""
    open_batches: dict[int, list[int]] = {}
    out: list[list[int]] = []
    for i in queue:
        key = id(point_of(i))
        batch = open_batches.get(key)
        if batch is None or len(batch) >= size:
            batch = open_batches[key] = []
            out.append(batch)
        batch.append(i)
    return out


def execute_batch(batch: BatchTask) -> list[Record]:
    """Run a batch on a worker; return the records of its runs in the order of
    ``batch.tasks`` (see the module docstring). A batch that raises (the device, a bug) gives
    every seed it held a failure record with the traceback; a result that cannot be stored
    gives that seed the :data:`nematic_solids.sweep.run.task.UNSAVED` record, as
    :func:`execute_run` does."""
    from .workers import import_model

    import_model(batch.tasks[0].model if batch.tasks else DEFAULT_MODEL)
    t0 = time.perf_counter()
    records: dict[int, Record] = {}
    groups: dict[float | None, list[tuple[int, RunTask, continuation.Start]]] = {}
    for k, task in enumerate(batch.tasks):
        try:
            start = continuation.starting_state(task, task_store(task))
        except Exception:  # noqa: BLE001 - its parent failed, or a bad file: execute_run says
            records[k] = execute_run(task)
            continue
        at = None if start.state is None else float(start.state.t)
        groups.setdefault(at, []).append((k, task, start))
    for held in groups.values():
        records.update(_run_together(held, batch.device, t0))
    return [records[k] for k in range(len(batch.tasks))]


def _run_together(
    held: list[tuple[int, RunTask, continuation.Start]], device: str, t0: float
) -> dict[int, Record]:
    """The seeds ``held`` (all from t = 0: their seeded textures or another campaign's fields;
    or all from states at one time) advanced as one batch, each stored as its own run, with
    its rolling checkpoints on the way and its end state."""
    model = batched(get_model(held[0][1].model))
    requests = [request(task, start, task_store(task)) for _, task, start in held]
    try:
        out = model.run_batch(requests, device)
    except Exception as e:  # noqa: BLE001 - the batch's crash fails each of its seeds
        return {
            k: finish_record(
                task, task_store(task), crash_record(task, "exception", e, t0, len(held)), start, t0
            )
            for k, task, start in held
        }
    return {
        k: save_result(task, task_store(task), o.dataset, o.end_state, start, t0)
        for (k, task, start), o in zip(held, out, strict=True)
    }
