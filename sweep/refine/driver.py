"""``nematic run`` of a refined campaign (with seeds by precision or not), or of one with seeds
by precision on its grid (whose replay :mod:`nematic_solids.sweep.precision.rounds` gives): rounds
of runs on one dask cluster.

The loop (:func:`drive_rounds`): replay the rounds from the folder
(:func:`nematic_solids.sweep.refine.rounds.replay`), record the plan (``refine.json``) and print a
new round's plan; stop when the replay says the campaign is finished; else run the planned runs that
are not done (:func:`nematic_solids.sweep.run.todo.plan_runs` and
:func:`~nematic_solids.sweep.run.driver.run_campaign`, as for a grid) and go round again. Every
decision is taken by the replay from the files, so an interrupted or killed driver resumes to the
same plan.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable
from typing import Any

from ..campaign import Campaign
from ..campaign_copy import save_campaign_copy
from ..errors import StoreError
from ..expand import Expansion
from ..run.clusters import open_cluster
from ..run.driver import REMOTE_TMP_AGE, RunEvents, RunSummary, dashboard_link, run_campaign
from ..run.failures import FailureLimit
from ..run.todo import Plan, plan_runs
from ..run.workers import ClusterLink
from ..store import CampaignStore
from .report import round_lines
from .rounds import Refinement, replay, write_plan

log = logging.getLogger(__name__)


def _merge(total: RunSummary, part: RunSummary) -> None:
    """Add one round's summary to the session's."""
    total.total = part.total
    total.submitted += part.submitted
    total.ok += part.ok
    total.failed.extend(part.failed)
    total.lost.extend(part.lost)
    total.worker_lost.extend(part.worker_lost)
    total.unsaved.extend(part.unsaved)
    total.storage_error = total.storage_error or part.storage_error
    total.stopped = total.stopped or part.stopped
    total.interrupted = total.interrupted or part.interrupted
    total.wall_time += part.wall_time
    total.run_time += part.run_time


def drive_rounds(
    campaign: Campaign,
    store: CampaignStore,
    *,
    retry_failed: bool = False,
    check_files: bool = False,
    events: RunEvents | None = None,
    dashboard: bool = False,
    say: Callable[[str], None] = print,
    limit: FailureLimit | None = None,
    on_round: Callable[[int], None] | None = None,
    link: ClusterLink | None = None,
    stop: threading.Event | None = None,
) -> tuple[Plan, RunSummary | None, Expansion]:
    """Run a refined campaign to its end (or to an interruption) while holding its lock.

    Returns the plan of what was on disk when it started (for the failures found there), the
    summary of the runs done by this call (``None`` if none was to do) and the union grid of
    the rounds for ``phase.nc``. ``say`` prints each round's plan; ``limit``
    (``--max-failures``) counts the failures over every round of the session; ``on_round``
    is called with the number of each round planned from this call's results, before it
    runs (the command line prints the cost re-estimated from the runs so far). With ``link``
    the rounds run on that cluster, which stays open (the service's); ``stop`` set stops the
    session as Ctrl-C does."""
    local = campaign.execution.mode == "local"
    store.clean_temporaries(min_age=0.0 if local else REMOTE_TMP_AGE)
    save_campaign_copy(store, campaign)
    total: RunSummary | None = None
    first: Plan | None = None
    announced = -1
    stuck_at: tuple[int, int] | None = None
    retry = retry_failed
    replay_fn, record, announce, what, done = _rounds_of(campaign)
    say(f"campaign {campaign.name}: {what} -> {store.root}")
    own = link is None
    with contextlib.ExitStack() as stack:
        try:
            while True:
                ref = replay_fn(campaign, store)
                record(store, ref)
                if ref.current.number > announced:
                    for number in range(announced + 1, ref.current.number + 1):
                        for line in announce(ref, number):
                            say(line)
                    if announced >= 0 and on_round is not None and not ref.finished:
                        on_round(ref.current.number)
                    announced = ref.current.number
                if ref.finished:
                    say(
                        f"{done} finished after round {ref.current.number}: {ref.stop}; "
                        f"{ref.n_runs} runs"
                    )
                    break
                runs = ref.run_list()
                plan = plan_runs(runs, store, retry_failed=retry, check_files=check_files)
                retry = check_files = False
                if first is None:
                    first = plan
                if not plan.todo:
                    # every planned run is on disk: the replay plans the next round; if it
                    # does not move on, the files changed under the driver
                    where = (ref.current.number, len(ref.pending))
                    if where == stuck_at:
                        raise StoreError(
                            f"round {where[0]} of {campaign.name}: "
                            f"{where[1]} run(s) stay unfinished although their "
                            "records are on disk; check the folder "
                            f"{store.root} (nematic status)"
                        )
                    stuck_at = where
                    continue
                stuck_at = None
                if link is None:
                    link = stack.enter_context(
                        open_cluster(
                            campaign.execution, dashboard=dashboard, campaign_dir=store.root
                        )
                    )
                    if dashboard and events is not None:
                        events.dashboard(dashboard_link(link.client))
                summary = run_campaign(runs, store, link, plan, events, limit=limit, stop=stop)
                if total is None:
                    total = RunSummary(
                        total=0, skipped=summary.skipped, failed_before=summary.failed_before
                    )
                _merge(total, summary)
                if (
                    summary.interrupted
                    or summary.storage_error
                    or summary.lost
                    or summary.worker_lost
                    or summary.stopped
                ):
                    break
        except KeyboardInterrupt:  # while the cluster was starting or closing
            if total is None:
                total = RunSummary(total=0, skipped=0)
            total.interrupted = True
        finally:
            if local and own and link is not None:
                stack.close()  # the local workers are gone: clean what they left
                store.clean_temporaries()
    store.scan()
    final = replay_fn(campaign, store)
    with contextlib.suppress(StoreError):
        record(store, final)
    if first is None:
        first = Plan(todo=[], done=[], failed=[], records={})
    return first, total, final.expansion()


def _rounds_of(
    campaign: Campaign,
) -> tuple[Callable[..., Any], Callable[..., None], Callable[[Any, int], list[str]], str, str]:
    """The replay, the plan writer, a round's lines, what the campaign is and what finishes:
    an adaptive campaign's rounds (with seeds by precision or not), or seeds by precision on
    the grid (:mod:`nematic_solids.sweep.precision.rounds`, driven by the same loop: its replay
    gives an object with the same ``current``, ``finished``, ``stop``, ``n_runs``, ``pending``,
    ``run_list`` and ``expansion``)."""
    if campaign.refine is None:
        from ..precision import rounds as precision

        return (
            precision.replay,
            precision.write_plan,
            lambda plan, number: plan.round_lines(number),
            "seeds by precision, in rounds",
            "seeds by precision",
        )
    what = f"adaptive, refining {', '.join(campaign.refine.names)} in rounds" + (
        ", seeds by precision" if campaign.precision is not None else ""
    )
    return replay, _record, round_lines, what, "refinement"


def _record(store: CampaignStore, ref: Refinement) -> None:
    write_plan(store, ref)
    log.info(
        "refine: round %d, %d runs planned, %d pending",
        ref.current.number,
        ref.n_runs,
        len(ref.pending),
    )
