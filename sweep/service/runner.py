"""The service's runner: a thread that takes campaigns from the queue
(:class:`~nematic_solids.sweep.service.queue.QueueStore`) one at a time and runs each through the
driver (:func:`nematic_solids.sweep.run.driver.drive`, or
:func:`nematic_solids.sweep.refine.driver.drive_rounds` for rounds), on the cluster it keeps
warm between campaigns (:class:`ClusterPool`), then writes what ``nematic run`` writes after
the runs (phase.nc, fits, figures, report.html). A campaign holds its folder's lock while it
runs, as ``nematic run`` does, so a driver and the service never run it together."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..campaign import Campaign, ExecutionSpec
from ..errors import CampaignError, CampaignLocked, ClusterError, StoreError
from ..expand import Expansion, RunSpec
from ..figures.failed import read_failed
from ..run.clusters import open_cluster
from ..run.todo import Plan
from ..run.workers import ClusterLink
from ..store import CampaignStore, Record
from .queue import CANCELLED, DONE, FAILED, Entry, QueueStore

log = logging.getLogger(__name__)

#: How long the cluster stays up with nothing to run before the service closes it (seconds):
#: a campaign submitted within it finds warm workers; a cluster's batch jobs are not held for
#: ever.
IDLE_CLOSE = 600.0
#: How long a campaign whose folder another driver holds waits before it is tried again (s).
LOCKED_RETRY = 10.0


class Changes:
    """A counter of what changed in the service (a run finished, a campaign moved in the
    queue), which the dashboard's event stream watches; thread-safe."""

    def __init__(self) -> None:
        self._value = 0
        self._lock = threading.Lock()

    def bump(self) -> None:
        with self._lock:
            self._value += 1

    @property
    def value(self) -> int:
        return self._value


class ClusterPool:
    """The one cluster the service keeps: opened for a campaign's ``execution:`` section, kept
    (warm workers) for the next campaign with the same section, closed and opened again for
    another, closed after :data:`IDLE_CLOSE` seconds idle."""

    def __init__(self, folder: Path, clock: Callable[[], float] = time.monotonic):
        self.folder = folder
        self.clock = clock
        self.execution: ExecutionSpec | None = None
        self.link: ClusterLink | None = None
        self._stack: contextlib.ExitStack | None = None
        self.idle_since: float | None = None

    def link_for(self, execution: ExecutionSpec) -> ClusterLink:
        if (
            self.link is not None
            and execution == self.execution
            and self.link.client.status == "running"
        ):
            self.idle_since = None
            return self.link
        self.close()
        stack = contextlib.ExitStack()
        self.link = stack.enter_context(open_cluster(execution, campaign_dir=self.folder))
        self._stack, self.execution, self.idle_since = stack, execution, None
        return self.link

    def idle(self) -> None:
        """Nothing to run: close the cluster once it has been idle :data:`IDLE_CLOSE` s."""
        if self.link is None:
            return
        now = self.clock()
        if self.idle_since is None:
            self.idle_since = now
        elif now - self.idle_since > IDLE_CLOSE:
            log.info("closing the idle cluster")
            self.close()

    def close(self) -> None:
        if self._stack is not None:
            with contextlib.suppress(Exception):
                self._stack.close()
        self._stack = self.link = self.execution = self.idle_since = None

    @property
    def state(self) -> dict[str, Any]:
        if self.link is None:
            return {"open": False}
        workers = 0
        with contextlib.suppress(Exception):
            workers = len(self.link.client.scheduler_info(n_workers=-1).get("workers", {}))
        return {"open": True, "where": self.link.where, "workers": workers}


class Progress:
    """The running campaign's counts, kept by the driver's events (:class:`ServiceEvents`)."""

    def __init__(self, entry: Entry) -> None:
        self.entry_id = entry.id
        self.name = entry.name
        self.total = 0
        self.done = 0
        self.failed = 0
        self.to_do = 0
        self.finished_this_session = 0
        self.phase = "starting"

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class ServiceEvents:
    """What the driver reports, kept as :class:`Progress` and counted in :class:`Changes`."""

    def __init__(self, progress: Progress, changes: Changes):
        self.progress, self.changes = progress, changes

    def dashboard(self, link: str | None) -> None:
        pass

    def planned(self, plan: Plan, expansion: Expansion) -> None:
        p = self.progress
        p.total = len(expansion)
        p.done, p.failed, p.to_do = len(plan.done), len(plan.failed), len(plan.todo)
        self.changes.bump()

    def warming(self) -> None:
        self.progress.phase = "warming"
        self.changes.bump()

    def warmed(self, infos: list[dict[str, Any]], seconds: float) -> None:
        self.progress.phase = "running"
        self.changes.bump()

    def started(self, plan: Plan, total: int, workers: int) -> None:
        self.progress.total = max(self.progress.total, total)
        self.progress.phase = "running"
        self.changes.bump()

    def finished_run(self, run: RunSpec, record: Record) -> None:
        p = self.progress
        if record.get("status") == "ok":
            p.done += 1
        else:
            p.failed += 1
        p.finished_this_session += 1
        self.changes.bump()


def estimate_of(campaign: Campaign, store: CampaignStore) -> dict[str, Any] | None:
    """The cost before launch (:func:`nematic_solids.sweep.cost.estimate.estimate`) as the
    dashboard compares it with the cost so far; ``None`` where it cannot be made (logged)."""
    from ..cost.estimate import estimate

    try:
        e = estimate(campaign, store)
    except Exception:
        log.warning("no cost estimate for %s", campaign.name, exc_info=True)
        return None
    return {
        "runs_to_do": e.to_do,
        "runs_done": e.done,
        "cpu_seconds": list(e.cpu),
        "wall_seconds": [w + e.overhead for w in e.wall],
        "basis": e.basis,
        "workers": e.workers,
        "made": time.time(),
    }


def load_entry(entry: Entry) -> Campaign:
    """The queued campaign, validated again from its text (with its overrides; relative paths
    in it are read from its file's folder)."""
    from ..spec import Overrides, parse_campaign

    o = entry.overrides
    overrides = Overrides(
        settings=o.get("settings") or {}, seeds=o.get("seeds"), name=o.get("name")
    )
    return parse_campaign(entry.text, entry.source, overrides, default_name=Path(entry.source).stem)


class Runner(threading.Thread):
    """Runs the queue's campaigns one after the other (see the module's docstring) until
    :meth:`shutdown`; a running campaign is then stopped as Ctrl-C stops ``nematic run`` and
    goes back to the queue, to resume at the next start."""

    def __init__(
        self,
        root: Path,
        queue: QueueStore,
        pool: ClusterPool,
        changes: Changes,
    ):
        super().__init__(name="nematic-service-runner", daemon=True)
        self.root, self.queue, self.pool, self.changes = root, queue, pool, changes
        self._stopping = threading.Event()
        self._wake = threading.Event()
        self._current: tuple[int, threading.Event] | None = None
        self.progress: Progress | None = None
        #: campaigns whose folder another driver holds: id -> when to try again
        self._waiting: dict[int, float] = {}

    # ------------------------------------------------------------------ control
    def wake(self) -> None:
        """Something was submitted: look at the queue now."""
        self._wake.set()

    def cancel(self, entry_id: int) -> None:
        """Stop the campaign ``entry_id`` if it is the one running (the queue marks it)."""
        current = self._current
        if current is not None and current[0] == entry_id:
            current[1].set()
        self._wake.set()

    def shutdown(self, timeout: float | None = None) -> None:
        self._stopping.set()
        current = self._current
        if current is not None:
            current[1].set()
        self._wake.set()
        self.join(timeout)

    # ------------------------------------------------------------------ the loop
    def run(self) -> None:
        try:
            while not self._stopping.is_set():
                now = time.monotonic()
                self._waiting = {k: t for k, t in self._waiting.items() if t > now}
                entry = self.queue.next(skip=set(self._waiting))
                if entry is None:
                    self.pool.idle()
                    self._wake.wait(1.0)
                    self._wake.clear()
                    continue
                self.run_entry(entry)
        finally:
            self.pool.close()

    def run_entry(self, entry: Entry) -> None:
        if entry.cancel_requested:
            self.queue.finish(entry.id, CANCELLED, "cancelled")
            self.changes.bump()
            return
        try:
            campaign = load_entry(entry)
        except CampaignError as e:
            self.queue.finish(entry.id, FAILED, f"invalid campaign: {e}")
            self.changes.bump()
            return
        store = CampaignStore(self.root, campaign.name)
        lock = store.lock()
        try:
            store.ensure()
            lock.acquire(command=f"nematic serve {self.root} (queue entry {entry.id})")
        except CampaignLocked as e:
            self._waiting[entry.id] = time.monotonic() + LOCKED_RETRY
            self.queue.note(entry.id, f"waiting: {e}")
            self.changes.bump()
            return
        except StoreError as e:
            self.queue.finish(entry.id, FAILED, str(e))
            self.changes.bump()
            return
        stop = threading.Event()
        self._current = (entry.id, stop)
        try:
            self.queue.start(entry, estimate_of(campaign, store))
            self.progress = Progress(entry)
            self.changes.bump()
            state, message, outcome = self._drive(campaign, store, stop)
        except Exception as e:  # noqa: BLE001 - one campaign's bug never ends the service
            log.error("campaign %s: %s", campaign.name, traceback.format_exc())
            state, message, outcome = FAILED, f"internal error: {type(e).__name__}: {e}", None
        finally:
            self._current = None
            lock.release()
        if state is None:  # the service stops: back to the queue
            self.queue.requeue(entry.id, message)
        elif self.queue.get(entry.id).cancel_requested and state != DONE:
            self.queue.finish(entry.id, CANCELLED, message, outcome)
        else:
            self.queue.finish(entry.id, state, message, outcome)
        self.progress = None
        self.changes.bump()

    def _drive(
        self, campaign: Campaign, store: CampaignStore, stop: threading.Event
    ) -> tuple[str | None, str, dict[str, Any] | None]:
        """Run the campaign: (final state or ``None`` when stopped by the service's end, a
        message, the outcome's counts)."""
        from ..expand import expand
        from ..refine.driver import drive_rounds
        from ..run.driver import drive

        assert self.progress is not None
        progress = self.progress
        events = ServiceEvents(progress, self.changes)
        try:
            link = self.pool.link_for(campaign.execution)
            if campaign.verify is not None and campaign.verify.before:
                progress.phase = "verification (before)"
                if self._verify(campaign, store, link, stop, before=True):
                    return self._stopped(None)
            progress.phase = "planning"
            if campaign.refine is None and campaign.precision is None:
                expansion = expand(campaign)
                plan, summary = drive(expansion, store, events=events, link=link, stop=stop)
            else:
                plan, summary, expansion = drive_rounds(
                    campaign, store, events=events, link=link, stop=stop, say=log.info
                )
        except (ClusterError, StoreError, CampaignError) as e:
            self.pool.close()  # a cluster that failed is not kept
            return FAILED, str(e), None
        outcome: dict[str, Any] = {
            "total": len(expansion),
            "failed_before": len(plan.failed),
            "ok": 0 if summary is None else summary.ok,
            "failed": 0 if summary is None else len(summary.failed),
            "wall_time": 0.0 if summary is None else summary.wall_time,
            "run_time": 0.0 if summary is None else summary.run_time,
        }
        if summary is not None and summary.interrupted:
            return self._stopped(outcome)
        if summary is not None and summary.storage_error is not None:
            return FAILED, f"results cannot be written: {summary.storage_error}", outcome
        if summary is not None and (summary.lost or summary.worker_lost):
            n = len(summary.lost) + len(summary.worker_lost)
            self.pool.close()
            return FAILED, f"{n} run(s) lost their workers; resubmit to do them", outcome
        progress.phase = "writing phase.nc, fits, figures, report"
        self.changes.bump()
        if self._products(campaign, expansion, store, link, stop):
            return self._stopped(outcome)
        failed = outcome["failed"] + outcome["failed_before"]
        runs = f"{failed} run(s) failed" if failed else "all runs ok"
        products = read_failed(store.root)
        if products:  # as nematic run's exit 4: a campaign whose products failed is no success
            outcome["failed_products"] = products
            return (
                FAILED,
                f"{runs}, but {len(products)} fit(s) or figure(s) failed "
                f"({', '.join(products)}); nematic figures {campaign.name} redraws them",
                outcome,
            )
        return DONE, runs, outcome

    def _stopped(
        self, outcome: dict[str, Any] | None
    ) -> tuple[str | None, str, dict[str, Any] | None]:
        if self._stopping.is_set():
            return None, "the service stopped: resumes at its next start", outcome
        return CANCELLED, "cancelled while running: its runs not finished stay pending", outcome

    def _verify(
        self,
        campaign: Campaign,
        store: CampaignStore,
        link: ClusterLink,
        stop: threading.Event,
        *,
        before: bool,
    ) -> bool:
        """The campaign's ``verify:`` runs on the service's cluster and ``verify.nc``, as
        ``nematic run`` does them; ``True`` when they were interrupted."""
        from ..verify.driver import run_verification

        try:
            outcome = run_verification(
                campaign, store, before=before, say=log.info, link=link, stop=stop
            )
        except (ClusterError, StoreError) as e:
            log.warning("verification of %s not done: %s", campaign.name, e)
            return False
        return outcome.interrupted and stop.is_set()

    def _products(
        self,
        campaign: Campaign,
        expansion: Expansion,
        store: CampaignStore,
        link: ClusterLink,
        stop: threading.Event,
    ) -> bool:
        """phase.nc, fits, the verification (``verify:``), figures and report.html, as
        ``nematic run`` writes them after the runs; a figure or report that cannot be drawn is
        logged, not fatal. ``True`` when the verification was interrupted."""
        from ..figures.produce import regenerate
        from ..outputs.aggregate import write_phase
        from ..outputs.tables import CampaignResults
        from ..report import write_report

        write_phase(expansion, store)
        if campaign.verify is not None and not campaign.verify.before:
            regenerate(campaign, self.root, draw_figures=False)  # the fits pick the sample
            if self._verify(campaign, store, link, stop, before=False):
                return True
            regenerate(campaign, self.root, fits=False)
        else:
            regenerate(campaign, self.root)
        try:
            write_report(CampaignResults(campaign, self.root))
        except Exception:
            log.warning("report not written for %s", campaign.name, exc_info=True)
        return False
