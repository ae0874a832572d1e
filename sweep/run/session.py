"""One session of a campaign's runs on a cluster (:class:`Session`): the queue of tasks, the
tasks in flight and what became of each run, the loop that submits through the cluster's window
and takes each result as it arrives (:func:`nematic_solids.sweep.run.driver.run_campaign` makes
one per call); what it reports as it goes (:class:`RunEvents`) and at the end
(:class:`RunSummary`)."""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Callable
from concurrent.futures import CancelledError
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from ..catalogue.recorder import Recorder
from ..chains import in_chain_order
from ..errors import ClusterError
from ..expand import Expansion, RunSpec
from ..store import CampaignStore, Record
from .batch import BatchTask, execute_batch
from .clusters import WORKER_LOSSES, worker_lost
from .failures import FailureLimit, setup_failure_record
from .group import RunGroup, execute_group, planned_stamp, tasks_of
from .task import UNSAVED, RunTask, execute_run, warm_workers
from .todo import Plan
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


class Session:
    """One session of a campaign's runs on a cluster, as an object: the queue of tasks to
    submit (``queue``: the runs of each task, the next task last), the tasks in flight
    (``tasks``), how often each run was submitted (``attempts``) and the summary so far.
    :meth:`run` warms the workers, then submits through the cluster's window, takes each
    finished task's records (:meth:`handle`, :meth:`take`) and stops at the end, an
    interruption, a results folder that takes no more results or the failure limit."""

    def __init__(
        self,
        expansion: Expansion,
        store: CampaignStore,
        client: Client | ClusterLink,
        plan: Plan,
        events: RunEvents | None,
        clock: Callable[[], float],
        limit: FailureLimit | None,
        recorder: Recorder | None,
    ):
        from distributed import as_completed

        self.expansion, self.store, self.plan, self.events = expansion, store, plan, events
        self.clock, self.limit, self.recorder = clock, limit, recorder
        self.campaign = expansion.campaign
        self.link = (
            client if isinstance(client, ClusterLink) else ClusterLink(client, "the dask cluster")
        )
        self.client = self.link.client
        self.summary = RunSummary(
            total=len(expansion), skipped=plan.skipped, failed_before=len(plan.failed)
        )
        self.watch = Supervisor(self.link, self.campaign.execution, clock=clock)
        # a chain's runs go after their predecessors (nematic_solids.sweep.chains)
        self.chained = expansion.chain_parents if self.campaign.chain is not None else None
        self.batched = self.campaign.execution.backend == "accelerated" and self.chained is None
        self.queue: list[list[int]] = []
        self.tasks: dict[Any, list[tuple[RunSpec, RunTask, int]]] = {}
        self.attempts: dict[int, int] = {}
        self.ac = as_completed()
        self.ready = threading.Event()  # set as a task ends

    def run(self, stop: threading.Event | None = None) -> RunSummary:
        """Warm the workers, run every planned run, and return the summary."""
        t0 = self.clock()
        self._start()
        last_manifest = self.clock()
        try:
            self.submit_more()
            going = True
            while going and (self.tasks or self.queue):
                if stop is not None and stop.is_set():
                    raise KeyboardInterrupt
                if self.ac.has_ready():
                    for fut in self.ac.next_batch(block=False):
                        if not self.handle(fut):
                            going = False
                            break
                else:  # until a task ends (POLL at most)
                    self.ready.wait(POLL)
                    self.ready.clear()
                if going and self.clock() - self.watch.last_check >= CHECK_EVERY:
                    try:
                        self.watch.check()
                    except ClusterError:
                        self._cancel_all()
                        raise
                if going:
                    self.submit_more()
                if self.clock() - last_manifest > MANIFEST_EVERY:
                    self.store.scan()
                    last_manifest = self.clock()
        except KeyboardInterrupt:
            self.summary.interrupted = True
            log.info("interrupted: cancelling %d pending run(s)", self.ac.count())
            self._cancel_all()
        self.summary.wall_time = self.clock() - t0
        return self.summary

    def _start(self) -> None:
        """The first worker, the warm-up, the plan's runs in tasks, in order."""
        events, watch, plan = self.events, self.watch, self.plan
        watch.wait_for_first()
        if events:
            events.warming()
        warm0 = self.clock()
        warmed = warm_workers(self.client, self.expansion)
        log.info("warm-up on %d host(s) in %.1f s: %s", len(warmed), self.clock() - warm0, warmed)
        if events:
            events.warmed(warmed, self.clock() - warm0)
        watch.check()
        if events:
            events.started(plan, len(self.expansion), max(1, watch.threads))
        if self.limit is not None:
            self.limit.planned += len(plan.todo)
        chained = self.chained  # by depth, then position
        order = plan.todo if chained is None else in_chain_order(plan.todo, chained)
        units = tasks_of(self.expansion, order, chained is not None, max(1, watch.threads))
        self.queue = list(reversed(units))

    def _cancel_all(self) -> None:
        with contextlib.suppress(Exception):
            self.client.cancel(list(self.ac.futures))

    def next_ready(self) -> int | None:
        """The place in the queue of the next run to submit: the last, or for a chain the
        last whose predecessor is neither queued nor in flight (it has its record)."""
        if self.chained is None:
            return len(self.queue) - 1
        busy = {i for unit in self.queue for i in unit}
        busy |= {i for held in self.tasks.values() for _, _, i in held}
        chained = self.chained
        return next(
            (
                k
                for k in range(len(self.queue) - 1, -1, -1)
                if chained[self.queue[k][0]] not in busy
            ),
            None,
        )

    def submit_more(self) -> None:
        """Submit tasks while the cluster's window has room."""
        queue, summary, expansion = self.queue, self.summary, self.expansion
        while queue and self.ac.count() < self.watch.window:
            k = self.next_ready()
            if k is None:
                if not self.tasks:  # their predecessors stay pending this session
                    log.warning(
                        "%d run(s) of chains wait for runs that stay pending; rerun the "
                        "campaign to go on",
                        len(queue),
                    )
                    summary.lost.extend(expansion.run(i) for unit in queue for i in unit)
                    queue.clear()
                return
            self._submit([self._task(i) for i in queue.pop(k)])

    def _task(self, i: int) -> tuple[RunSpec, RunTask, int]:
        run, campaign, plan = self.expansion.run(i), self.campaign, self.plan
        task = RunTask.from_spec(
            run,
            self.store,
            campaign.name,
            campaign.store,
            plan.history.get(i),
            plan.parents.get(i),
            plan.parent_paths.get(i),
            model=campaign.model,
        )
        return run, task, i

    def _submit(self, held: list[tuple[RunSpec, RunTask, int]]) -> None:
        """One task of the runs ``held``: a batch of seeds, a group of runs, or one run."""
        # a run that goes again (its result was lost) gets a new key: the old one may still
        # be being released
        for _, _, i in held:
            self.attempts[i] = self.attempts.get(i, -1) + 1
        again = self.attempts[held[0][2]]
        key = f"nematic-run-{held[0][0].run_id}" + (f"-{again}" if again else "")
        client = self.client
        if self.batched:  # one task for the seeds held
            one = BatchTask(tuple(t for _, t, _ in held), self.campaign.execution.device)
            fut: Any = client.submit(execute_batch, one, key=f"{key}-b{len(held)}", pure=False)
        elif len(held) > 1:  # one task for the runs held
            stamps = tuple(planned_stamp(self.plan.records, run.run_id) for run, _, _ in held)
            group = RunGroup(tuple(t for _, t, _ in held), stamps)
            fut = client.submit(execute_group, group, key=f"{key}-g{len(held)}", pure=False)
        else:
            fut = client.submit(execute_run, held[0][1], key=key, pure=False)
        self.tasks[fut.key] = held
        fut.add_done_callback(lambda _: self.ready.set())
        self.ac.add(fut)
        self.summary.submitted += len(held)

    def _failed(
        self, held: list[tuple[RunSpec, RunTask, int]], e: BaseException
    ) -> list[tuple[RunSpec, Record]]:
        """The records of the runs ``held``, whose task raised ``e`` (written)."""
        n = len(held) if self.batched else 1
        out = [(run, setup_failure_record(t, e, n)) for run, t, _ in held]
        for _, record in out:
            self.store.write_record(record)
        return out

    def _lost_result(
        self, fut: Any, held: list[tuple[RunSpec, RunTask, int]], e: BaseException
    ) -> list[tuple[RunSpec, Record]]:
        """A task that finished but whose result did not arrive: it went with its worker (a
        batch job ended; dask would recompute it), or the connection to the scheduler broke
        (TimeoutError, CommClosedError). Not the runs' fault: the records on disk say what
        happened, else the runs go again (or stay pending)."""
        with contextlib.suppress(Exception):
            fut.cancel()
        found = [(run, self.store.read_record(run.run_id)) for run, _, _ in held]
        missing = [i for (run, rec), (_, _, i) in zip(found, held, strict=True) if rec is None]
        if missing:
            i0 = missing[0]
            what = f"{len(missing)} run(s) from {self.expansion.run(i0).run_id}"
            if self.client.status != "running":
                self.summary.lost.extend(self.expansion.run(i) for i in missing)
            elif self.attempts.get(i0, 0) < WORKER_LOSSES:
                log.warning(
                    "the result of %s was lost with its worker (%s); it runs again",
                    what,
                    type(e).__name__,
                )
                self.queue.append(missing)
            else:
                log.warning(
                    "the result of %s was lost with its worker %d times; it stays pending",
                    what,
                    self.attempts.get(i0, 0) + 1,
                )
                self.summary.worker_lost.extend(self.expansion.run(i) for i in missing)
        return [(run, rec) for run, rec in found if rec is not None]

    def _cancelled(self, held: list[tuple[RunSpec, RunTask, int]], e: BaseException) -> None:
        """The cluster went away under the runs ``held``: not their fault; they stay pending."""
        summary = self.summary
        (log.debug if summary.lost else log.warning)(
            "run %s was cancelled by dask (%s); rerun to redo it",
            held[0][0].run_id,
            " ".join(str(e).split()),
        )
        summary.lost.extend(run for run, _, _ in held)
        if self.client.status != "running":  # the futures are gone with the connection
            if self.queue or self.tasks:
                log.warning(
                    "the connection to %s is lost (client %s): the %d run(s) left stay pending",
                    self.link.where,
                    self.client.status,
                    sum(map(len, self.queue)) + sum(map(len, self.tasks.values())) + len(held),
                )
            self.queue.clear()  # nothing more can be submitted

    def handle(self, fut: Any) -> bool:
        """Take one finished future (one run, or a batch's runs); ``False`` to stop the
        campaign."""
        held = self.tasks.pop(fut.key)
        try:
            result = fut.result(timeout=RESULT_WAIT)
        except OSError as e:
            if fut.status == "error":  # raised by the task (its setup): its runs failed
                results = self._failed(held, e)
            else:
                results = self._lost_result(fut, held, e)
        except CancelledError as e:
            self._cancelled(held, e)
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
                self.summary.worker_lost.extend(run for run, _, _ in held)
                fut.release()
                return True
            results = self._failed(held, e)
        else:
            records = result if isinstance(result, list) else [result]
            results = [(run, rec) for (run, _, _), rec in zip(held, records, strict=True)]
        fut.release()
        return all(self.take(run, record) for run, record in results)

    def take(self, run: RunSpec, record: Record) -> bool:
        """Count and report one run's record; ``False`` to stop the campaign."""
        summary, limit = self.summary, self.limit
        if record.get("status") == UNSAVED:
            # The results folder cannot take results: stop instead of burning every run.
            # The runs in flight are cancelled: they stay pending, as this one does.
            summary.unsaved.append((run, record))
            summary.storage_error = str(record.get("storage_error") or "")
            self.queue.clear()
            self._cancel_all()
            return False
        if self.recorder is not None:
            self.recorder.add(record)
        if record.get("status") == "ok":
            summary.ok += 1
        else:
            summary.failed.append((run, record))
        wall = record.get("wall_time")
        if isinstance(wall, (int, float)) and math.isfinite(wall):
            summary.run_time += float(wall)
        if self.events:
            self.events.finished_run(run, record)
        if record.get("status") != "ok" and limit is not None and limit.add_failure(record):
            summary.stopped = limit.message()
            self.queue.clear()
            self._cancel_all()
            return False
        return True
