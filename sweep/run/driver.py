"""The driver that fans a campaign's runs out over dask.

The driver (:func:`run_campaign`) plans from what is on disk (:func:`.todo.plan_runs`), submits
the remaining runs (the worker task :func:`.task.execute_run`) through a bounded window, reports
each result as it arrives and can be interrupted at any point: everything it needs to resume is on
disk, nothing is kept in dask.

Clusters (:mod:`nematic_solids.sweep.run.workers`): an embedded ``LocalCluster`` (default), an
existing scheduler (``execution.scheduler`` / ``--scheduler``) or a dask-jobqueue cluster
(``execution.cluster``), watched while the runs go (workers checked as they join, lost batch jobs
replaced, a bounded give-up). The results folder must be visible at the same path from every worker
(a shared filesystem).
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import CancelledError
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ..campaign import ExecutionSpec
from ..campaign_copy import save_campaign_copy
from ..catalogue.recorder import Recorder
from ..chains import in_chain_order
from ..errors import ClusterError
from ..expand import Expansion, RunSpec
from ..store import CampaignStore, Record
from .batch import BatchTask, execute_batch
from .clusters import WORKER_LOSSES, open_cluster, worker_lost
from .clusters import make_cluster as make_cluster  # where it was first
from .failures import FailureLimit, setup_failure_record
from .group import RunGroup, execute_group, planned_stamp, tasks_of
from .task import UNSAVED, RunTask, check_device, execute_run, warm_workers
from .todo import Plan, parents_not_done, plan_runs
from .workers import CHECK_EVERY, ClusterLink, Supervisor

if TYPE_CHECKING:
    from distributed import Client

log = logging.getLogger(__name__)

#: How long the driver waits at most for a task to end when no result is ready (seconds).
POLL = 0.2
#: How long the driver waits for the result of a finished run to arrive (seconds).
RESULT_WAIT = 10.0
#: How often the driver refreshes the manifest while running (seconds).
MANIFEST_EVERY = 300.0


# --------------------------------------------------------------------------- clusters
@contextlib.contextmanager
def dask_client(
    execution: ExecutionSpec,
    *,
    timeout: float = 30.0,
    dashboard: bool = False,
    campaign_dir: Path | None = None,
) -> Iterator[Client]:
    """A dask ``Client`` for the campaign's execution section (closed on exit); see
    :func:`nematic_solids.sweep.run.clusters.open_cluster`."""
    with open_cluster(
        execution, timeout=timeout, dashboard=dashboard, campaign_dir=campaign_dir
    ) as link:
        yield link.client


# --------------------------------------------------------------------------- the driver
def dashboard_link(client: Client, timeout: float = 30.0) -> str | None:
    """The link of the dask dashboard if it answers from here within ``timeout`` seconds,
    else ``None`` (started without it, bokeh not installed where the scheduler runs, or not
    reachable: the scheduler's HTTP server then answers 404 for the page, or not at all). A
    refused connection answers at once; the first render of the page takes seconds on a
    loaded machine (more than 5 s measured under a full test suite), hence the long wait."""
    import urllib.error
    import urllib.request

    try:
        link = str(client.dashboard_link)
        with urllib.request.urlopen(link, timeout=timeout) as response:  # an http link
            return link if response.status == 200 else None
    except (OSError, ValueError, urllib.error.URLError):
        return None


class RunEvents(Protocol):
    """What the driver reports (the command line prints it and draws the progress bar from
    it: :class:`nematic_solids.sweep.cli.progress.ProgressEvents`)."""

    def dashboard(self, link: str | None) -> None:
        """The dask dashboard's link (``None``: none answers from here)."""

    def warming(self) -> None:
        """The workers start loading (or compiling) the model's kernels."""

    def warmed(self, infos: list[dict[str, Any]], seconds: float) -> None:
        """The workers are ready: what each host's warm-up reported, and how long it took."""

    def started(self, plan: Plan, total: int, workers: int) -> None:
        """The runs of ``plan`` are submitted: ``total`` runs in all, on ``workers``."""

    def finished_run(self, run: RunSpec, record: Record) -> None:
        """A run ended, ok or failed, with its record."""


@dataclass
class RunSummary:
    total: int
    skipped: int
    submitted: int = 0
    ok: int = 0
    failed: list[tuple[RunSpec, Record]] = field(default_factory=list)
    failed_before: int = 0
    #: runs whose dask task was cancelled under them (scheduler or cluster gone): no record
    lost: list[RunSpec] = field(default_factory=list)
    #: runs whose worker was lost under them more than ``WORKER_LOSSES`` times (batch jobs
    #: cancelled, preempted or past their walltime; or a run that kills its worker): no
    #: record, they stay pending
    worker_lost: list[RunSpec] = field(default_factory=list)
    #: why results cannot be stored (the driver stopped: the runs left stay pending)
    storage_error: str | None = None
    #: results that could not be written where they belong (kept elsewhere if possible)
    unsaved: list[tuple[RunSpec, Record]] = field(default_factory=list)
    #: why the driver stopped early because too many runs failed (``--max-failures``): the
    #: runs not finished stay pending
    stopped: str | None = None
    interrupted: bool = False
    wall_time: float = 0.0
    run_time: float = 0.0

    @property
    def completed(self) -> int:
        return self.ok + len(self.failed)


def run_campaign(
    expansion: Expansion,
    store: CampaignStore,
    client: Client | ClusterLink,
    plan: Plan,
    events: RunEvents | None = None,
    *,
    clock: Callable[[], float] = time.monotonic,
    limit: FailureLimit | None = None,
    stop: threading.Event | None = None,
    record: bool = True,
) -> RunSummary:
    """Run ``plan.todo`` on the cluster; return when all are done or on Ctrl-C
    (``KeyboardInterrupt`` is caught: pending runs are cancelled and ``interrupted`` set).
    A run redone after a failure gets its earlier failures (``plan.history``) in its record.
    With ``limit``, once more runs failed than it allows the runs in flight are cancelled
    (they stay pending: a record is written whole or not at all) and ``stopped`` says why.
    ``stop`` set (from another thread: the service cancelling the campaign, or stopping)
    stops the campaign as Ctrl-C does.

    Waits (bounded) for the first worker, checks every worker that joins and sizes the
    submission window from the accepted workers
    (:class:`~nematic_solids.sweep.run.workers.Supervisor`). Raises :class:`ClusterError` when the
    workers cannot run the model or none is left for ``execution.give_up_after`` seconds (the runs
    in flight stay pending). With ``record``, each record goes into the root's catalogue
    (:class:`~nematic_solids.sweep.catalogue.recorder.Recorder`; never fails a run)."""
    recorder = Recorder(store) if record else None
    try:
        return _run_campaign(expansion, store, client, plan, events, clock, limit, recorder, stop)
    finally:
        if recorder is not None:
            recorder.close()


def _run_campaign(
    expansion: Expansion,
    store: CampaignStore,
    client: Client | ClusterLink,
    plan: Plan,
    events: RunEvents | None,
    clock: Callable[[], float],
    limit: FailureLimit | None,
    recorder: Recorder | None,
    stop: threading.Event | None = None,
) -> RunSummary:
    from distributed import as_completed

    campaign = expansion.campaign
    link = client if isinstance(client, ClusterLink) else ClusterLink(client, "the dask cluster")
    client = link.client
    t0 = clock()
    summary = RunSummary(
        total=len(expansion),
        skipped=plan.skipped,
        failed_before=len(plan.failed),
    )
    watch = Supervisor(link, campaign.execution, clock=clock)
    watch.wait_for_first()
    if events:
        events.warming()
    warm0 = clock()
    warmed = warm_workers(client, expansion)
    log.info("warm-up on %d host(s) in %.1f s: %s", len(warmed), clock() - warm0, warmed)
    if events:
        events.warmed(warmed, clock() - warm0)
    watch.check()
    if events:
        events.started(plan, len(expansion), max(1, watch.threads))
    if limit is not None:
        limit.planned += len(plan.todo)
    # a chain's runs go after their predecessors (nematic_solids.sweep.chains): by depth, then
    # position
    chained = expansion.chain_parents if campaign.chain is not None else None
    order = plan.todo if chained is None else in_chain_order(plan.todo, chained)
    units = tasks_of(expansion, order, chained is not None, max(1, watch.threads))
    batched = campaign.execution.backend == "accelerated" and chained is None
    queue = list(reversed(units))  # the runs of each task, the next task last
    tasks: dict[Any, list[tuple[RunSpec, RunTask, int]]] = {}
    attempts: dict[int, int] = {}
    ac = as_completed()
    ready = threading.Event()  # set as a task ends
    last_manifest = clock()

    def next_ready() -> int | None:
        """The place in the queue of the next run to submit: the last, or for a chain the
        last whose predecessor is neither queued nor in flight (it has its record)."""
        if chained is None:
            return len(queue) - 1
        busy = {i for unit in queue for i in unit}
        busy |= {i for held in tasks.values() for _, _, i in held}
        return next(
            (k for k in range(len(queue) - 1, -1, -1) if chained[queue[k][0]] not in busy), None
        )

    def submit_more() -> None:
        while queue and ac.count() < watch.window:
            k = next_ready()
            if k is None:
                if not tasks:  # their predecessors stay pending this session
                    log.warning(
                        "%d run(s) of chains wait for runs that stay pending; rerun the "
                        "campaign to go on",
                        len(queue),
                    )
                    summary.lost.extend(expansion.run(i) for unit in queue for i in unit)
                    queue.clear()
                return
            held = []
            for i in queue.pop(k):
                run = expansion.run(i)
                task = RunTask.from_spec(
                    run,
                    store,
                    campaign.name,
                    campaign.store,
                    plan.history.get(i),
                    plan.parents.get(i),
                    plan.parent_paths.get(i),
                    model=campaign.model,
                )
                held.append((run, task, i))
            # a run that goes again (its result was lost) gets a new key: the old one may
            # still be being released
            for _, _, i in held:
                attempts[i] = attempts.get(i, -1) + 1
            again = attempts[held[0][2]]
            key = f"nematic-run-{held[0][0].run_id}" + (f"-{again}" if again else "")
            if batched:  # one task for the seeds held
                one = BatchTask(tuple(t for _, t, _ in held), campaign.execution.device)
                fut: Any = client.submit(execute_batch, one, key=f"{key}-b{len(held)}", pure=False)
            elif len(held) > 1:  # one task for the runs held
                stamps = tuple(planned_stamp(plan.records, run.run_id) for run, _, _ in held)
                group = RunGroup(tuple(t for _, t, _ in held), stamps)
                fut = client.submit(execute_group, group, key=f"{key}-g{len(held)}", pure=False)
            else:
                fut = client.submit(execute_run, held[0][1], key=key, pure=False)
            tasks[fut.key] = held
            fut.add_done_callback(lambda _: ready.set())
            ac.add(fut)
            summary.submitted += len(held)

    def handle(fut: Any) -> bool:
        """Take one finished future (one run, or a batch's runs); ``False`` to stop the
        campaign."""
        held = tasks.pop(fut.key)

        def failed(e: BaseException) -> list[tuple[RunSpec, Record]]:
            """The records of the runs ``held``, whose task raised ``e`` (written)."""
            out = [
                (run, setup_failure_record(t, e, len(held) if batched else 1)) for run, t, _ in held
            ]
            for _, record in out:
                store.write_record(record)
            return out

        try:
            result = fut.result(timeout=RESULT_WAIT)
        except OSError as e:
            if fut.status == "error":  # raised by the task (its setup): its runs failed
                results = failed(e)
            else:
                # Finished, but its result did not arrive: it went with its worker (a batch job
                # ended; dask would recompute it), or the connection to the scheduler broke
                # (TimeoutError, CommClosedError). Not the runs' fault: the records on disk say
                # what happened, else the runs go again (or stay pending).
                with contextlib.suppress(Exception):
                    fut.cancel()
                found = [(run, store.read_record(run.run_id)) for run, _, _ in held]
                missing = [
                    i for (run, rec), (_, _, i) in zip(found, held, strict=True) if rec is None
                ]
                if missing:
                    i0 = missing[0]
                    what = f"{len(missing)} run(s) from {expansion.run(i0).run_id}"
                    if client.status != "running":
                        summary.lost.extend(expansion.run(i) for i in missing)
                    elif attempts.get(i0, 0) < WORKER_LOSSES:
                        log.warning(
                            "the result of %s was lost with its worker (%s); it runs again",
                            what,
                            type(e).__name__,
                        )
                        queue.append(missing)
                    else:
                        log.warning(
                            "the result of %s was lost with its worker %d times; it stays pending",
                            what,
                            attempts.get(i0, 0) + 1,
                        )
                        summary.worker_lost.extend(expansion.run(i) for i in missing)
                results = [(run, rec) for run, rec in found if rec is not None]
        except CancelledError as e:  # the cluster went away under the run: not its fault
            (log.debug if summary.lost else log.warning)(
                "run %s was cancelled by dask (%s); rerun to redo it",
                held[0][0].run_id,
                " ".join(str(e).split()),
            )
            summary.lost.extend(run for run, _, _ in held)
            if client.status != "running":  # the futures are gone with the connection
                if queue or tasks:
                    log.warning(
                        "the connection to %s is lost (client %s): the %d run(s) left stay pending",
                        link.where,
                        client.status,
                        sum(map(len, queue)) + sum(map(len, tasks.values())) + len(held),
                    )
                queue.clear()  # nothing more can be submitted
            return True
        except Exception as e:  # noqa: BLE001 - killed workers, errors outside the run
            if worker_lost(e):  # not the runs' failure: they stay pending (no record)
                log.warning(
                    "run %s lost its worker %d times (batch jobs cancelled, "
                    "preempted or past their walltime, or the run kills its worker: "
                    "memory?); it stays pending",
                    held[0][0].run_id,
                    WORKER_LOSSES + 1,
                )
                summary.worker_lost.extend(run for run, _, _ in held)
                fut.release()
                return True
            results = failed(e)
        else:
            records = result if isinstance(result, list) else [result]
            results = [(run, rec) for (run, _, _), rec in zip(held, records, strict=True)]
        fut.release()
        return all(take(run, record) for run, record in results)

    def take(run: RunSpec, record: Record) -> bool:
        """Count and report one run's record; ``False`` to stop the campaign."""
        if record.get("status") == UNSAVED:
            # The results folder cannot take results: stop instead of burning every run.
            # The runs in flight are cancelled: they stay pending, as this one does.
            summary.unsaved.append((run, record))
            summary.storage_error = str(record.get("storage_error") or "")
            queue.clear()
            with contextlib.suppress(Exception):
                client.cancel(list(ac.futures))
            return False
        if recorder is not None:
            recorder.add(record)
        if record.get("status") == "ok":
            summary.ok += 1
        else:
            summary.failed.append((run, record))
        wall = record.get("wall_time")
        if isinstance(wall, (int, float)) and math.isfinite(wall):
            summary.run_time += float(wall)
        if events:
            events.finished_run(run, record)
        if record.get("status") != "ok" and limit is not None and limit.add_failure(record):
            summary.stopped = limit.message()
            queue.clear()
            with contextlib.suppress(Exception):
                client.cancel(list(ac.futures))
            return False
        return True

    try:
        submit_more()
        going = True
        while going and (tasks or queue):
            if stop is not None and stop.is_set():
                raise KeyboardInterrupt
            if ac.has_ready():
                for fut in ac.next_batch(block=False):
                    if not handle(fut):
                        going = False
                        break
            else:  # until a task ends (POLL at most)
                ready.wait(POLL)
                ready.clear()
            if going and clock() - watch.last_check >= CHECK_EVERY:
                try:
                    watch.check()
                except ClusterError:
                    with contextlib.suppress(Exception):
                        client.cancel(list(ac.futures))
                    raise
            if going:
                submit_more()
            if clock() - last_manifest > MANIFEST_EVERY:
                store.scan()
                last_manifest = clock()
    except KeyboardInterrupt:
        summary.interrupted = True
        log.info("interrupted: cancelling %d pending run(s)", ac.count())
        with contextlib.suppress(Exception):
            client.cancel(list(ac.futures))
    summary.wall_time = clock() - t0
    return summary


class DriveEvents(RunEvents, Protocol):
    def planned(self, plan: Plan, expansion: Expansion) -> None: ...


#: Temporary files younger than this may belong to a cancelled run still finishing on a
#: remote worker: a driver on a remote cluster leaves them (seconds).
REMOTE_TMP_AGE = 600.0


def drive(
    expansion: Expansion,
    store: CampaignStore,
    *,
    retry_failed: bool = False,
    check_files: bool = False,
    events: DriveEvents | None = None,
    dashboard: bool = False,
    limit: FailureLimit | None = None,
    link: ClusterLink | None = None,
    stop: threading.Event | None = None,
) -> tuple[Plan, RunSummary | None]:
    """What ``nematic run`` does while holding the campaign's lock: clean up, record the
    campaign text, plan from disk, run what remains on the campaign's dask cluster and
    refresh the manifest. Returns the plan and the summary (``None`` if nothing was to do;
    ``interrupted`` set on Ctrl-C, or once ``stop`` is set). With ``link`` the runs go to
    that cluster, which stays open (the service's warm workers), else to the campaign's own.
    Raises :class:`~nematic_solids.sweep.errors.ClusterError` if the cluster cannot be used."""
    campaign = expansion.campaign
    local = campaign.execution.mode == "local"
    store.clean_temporaries(min_age=0.0 if local else REMOTE_TMP_AGE)
    save_campaign_copy(store, campaign)
    plan = plan_runs(expansion, store, retry_failed=retry_failed, check_files=check_files)
    waiting = parents_not_done(expansion, store.results_root, plan.todo)
    if waiting is not None:  # a campaign whose runs begin from another's that is not done
        raise waiting
    if events:
        events.planned(plan, expansion)
    summary = None
    if plan.todo and local and campaign.execution.backend == "accelerated":
        check_device(campaign.execution.device, campaign.model)  # one message before workers
    if plan.todo and link is not None:
        summary = run_campaign(expansion, store, link, plan, events, limit=limit, stop=stop)
    elif plan.todo:
        try:
            with open_cluster(
                campaign.execution, dashboard=dashboard, campaign_dir=store.root
            ) as own:
                if dashboard and events:
                    events.dashboard(dashboard_link(own.client))
                summary = run_campaign(expansion, store, own, plan, events, limit=limit, stop=stop)
        except KeyboardInterrupt:  # while the cluster was starting or closing
            summary = RunSummary(
                total=len(expansion),
                skipped=plan.skipped,
                failed_before=len(plan.failed),
                interrupted=True,
            )
        finally:
            if local:  # the local workers are gone: whatever they left half-written goes
                store.clean_temporaries()
    store.scan()
    return plan, summary
