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
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from ..campaign import ExecutionSpec
from ..campaign_copy import save_campaign_copy
from ..catalogue.recorder import Recorder
from ..expand import Expansion
from ..store import CampaignStore
from .clusters import make_cluster as make_cluster  # where it was first
from .clusters import open_cluster
from .failures import FailureLimit
from .session import RunEvents, RunSummary, Session
from .task import check_device
from .todo import Plan, parents_not_done, plan_runs
from .workers import ClusterLink

if TYPE_CHECKING:
    from distributed import Client

log = logging.getLogger(__name__)


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
        session = Session(expansion, store, client, plan, events, clock, limit, recorder)
        return session.run(stop)
    finally:
        if recorder is not None:
            recorder.close()


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
