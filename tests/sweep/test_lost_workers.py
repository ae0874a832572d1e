"""A run whose worker is lost more often than the scheduler retries it (dask's KilledWorker,
after ``nematic_solids.sweep.run.clusters.WORKER_LOSSES`` losses) stays pending: no record, not a
failure."""

from __future__ import annotations

from types import SimpleNamespace

from sweep_helpers import write_campaign

import nematic_solids.sweep.run.driver as driver
import nematic_solids.sweep.run.session as execute
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.outputs.status import campaign_status
from nematic_solids.sweep.run.todo import plan_runs
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.store import CampaignStore


def test_a_run_whose_worker_is_lost_too_often_stays_pending(tmp_path, monkeypatch):
    from distributed import Client, KilledWorker, LocalCluster

    path = write_campaign(tmp_path, values="[0.1, 0.2]", seeds=1, t_final=1.0, workers=1)
    expansion = expand(load_campaign(path))
    store = CampaignStore(tmp_path / "results", expansion.campaign.name)
    store.ensure()
    plan = plan_runs(expansion, store)
    victim = expansion.run_ids[0]
    real = execute.execute_run

    def lost_with_its_worker(task):  # what the scheduler reports after the last retry
        if task.run_id == victim:
            raise KilledWorker(f"nematic-run-{victim}", SimpleNamespace(address="tls://lost:1"), 3)  # type: ignore[arg-type]
        return real(task)

    monkeypatch.setattr(execute, "execute_run", lost_with_its_worker)
    with (
        LocalCluster(
            n_workers=1, processes=False, threads_per_worker=1, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        summary = driver.run_campaign(expansion, store, client, plan)
    assert [r.run_id for r in summary.worker_lost] == [victim]
    assert summary.ok == 1
    assert not summary.failed
    assert store.read_record(victim) is None
    report = campaign_status(expansion, store)
    assert (report.done, report.failed, report.pending) == (1, 0, 1)


def test_a_result_lost_with_its_worker_runs_again_then_stays_pending(tmp_path):
    """A task that finished but whose result did not arrive (its worker went; the future is
    not in error): runs without a record go again, until they were lost WORKER_LOSSES times;
    a run whose record is on disk is taken from it."""
    from nematic_solids.sweep.run.clusters import WORKER_LOSSES

    path = write_campaign(tmp_path, values="[0.1, 0.2]", seeds=1, t_final=1.0, workers=1)
    expansion = expand(load_campaign(path))
    store = CampaignStore(tmp_path / "results", expansion.campaign.name)
    store.ensure()
    done = {"run_id": expansion.run_ids[1], "status": "ok", "scalars": {}}
    store.write_record(done)  # type: ignore[arg-type]
    held = [(expansion.run(i), None, i) for i in (0, 1)]
    s = execute.Session.__new__(execute.Session)
    s.store, s.expansion, s.queue, s.attempts = store, expansion, [], {0: 0, 1: 0}
    s.client = SimpleNamespace(status="running")  # type: ignore[assignment]
    s.summary = execute.RunSummary(total=2, skipped=0)
    fut = SimpleNamespace(cancel=lambda: None)
    taken = s._lost_result(fut, held, OSError("gone"))  # type: ignore[arg-type]
    assert [run.run_id for run, _ in taken] == [expansion.run_ids[1]]
    assert s.queue == [[0]]  # the run without a record goes again
    s.queue, s.attempts[0] = [], WORKER_LOSSES
    s._lost_result(fut, held, OSError("gone"))  # type: ignore[arg-type]
    assert s.queue == []
    assert [run.run_id for run in s.summary.worker_lost] == [expansion.run_ids[0]]
