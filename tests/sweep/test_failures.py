"""Failure triage: `nematic status` groups failures by reason (count, first run, its files),
`--retry-failed` keeps the earlier failure in the run's record, `--max-failures` stops a
campaign early with exit 3 (real model runs at 32^2, a local dask cluster)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sweep_helpers import records, write_campaign
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.cli.app import EXIT_TOO_MANY_FAILURES
from nematic_solids.sweep.run.failures import FailureLimit, previous_failures


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def test_max_failures_takes_a_count_or_a_fraction():
    assert FailureLimit.parse("5").count == 5
    assert FailureLimit.parse(" 0 ").count == 0
    assert FailureLimit.parse("0.1").fraction == pytest.approx(0.1)
    for bad in ("-1", "1.5", "1.0", "0.0", "nan", "many", ""):
        with pytest.raises(ValueError, match="--max-failures: got"):
            FailureLimit.parse(bad)


def test_the_limit_is_exceeded_by_more_failures_than_allowed():
    count = FailureLimit.parse("1")
    assert not count.add_failure({"reason": "nan"})
    assert count.add_failure({"reason": "J<=0"})
    assert "2 failed this session, more than --max-failures 1" in count.message()
    assert "nan: 1" in count.message()
    assert "J<=0: 1" in count.message()
    fraction = FailureLimit.parse("0.25")
    fraction.planned = 8  # two failures are allowed
    assert not fraction.add_failure({"reason": "nan"})
    assert not fraction.add_failure({"reason": "nan"})
    fraction.planned += 4  # an adaptive campaign's next round: three are allowed
    assert not fraction.add_failure({"reason": "nan"})
    assert fraction.add_failure({"reason": "nan"})
    assert "of the 12 run(s) to do" in fraction.message()


def test_previous_failures_accumulate_oldest_first():
    first = {
        "status": "failed",
        "reason": "nan",
        "detail": "NaN in q",
        "t_failed": 1.5,
        "finished": "2026-01-01T00:00:00+00:00",
        "traceback": "",
        "host": "a",
    }
    second = {
        "status": "failed",
        "reason": "exception",
        "detail": "boom",
        "t_failed": None,
        "finished": "2026-01-02T00:00:00+00:00",
        "traceback": "Traceback ...",
        "previous_failures": previous_failures(first),
    }
    kept = previous_failures(second)
    assert [f["reason"] for f in kept] == ["nan", "exception"]
    assert kept[0]["detail"] == "NaN in q"
    assert kept[0]["t_failed"] == 1.5
    assert kept[1]["traceback"] == "Traceback ..."
    assert kept[0]["finished"] < kept[1]["finished"]


def test_status_groups_failures_by_reason_with_the_first_run(small):
    recs = records(small.runs)
    failed = [rid for rid in small.ids if recs[rid]["status"] == "failed"]
    reason = recs[failed[0]]["reason"]
    report = json.loads(invoke("status", small.path, "--results", small.results, "--json").output)
    (group,) = report["failure_groups"]
    assert group["reason"] == reason
    assert group["count"] == 2
    assert group["run_id"] == failed[0]  # the first in the campaign's run order
    assert group["coords"] == {"alpha_minus_B": 20.0, "seed": recs[failed[0]]["seed"]}
    assert group["parameters"] == recs[failed[0]]["parameters"]
    assert group["t_failed"] == recs[failed[0]]["t_failed"]
    assert group["finished"] == recs[failed[0]]["finished"]
    assert Path(group["record"]) == small.runs / f"{failed[0]}.json"
    assert group["run_file"] is None or Path(group["run_file"]).exists()
    text = flat(invoke("status", small.path, "--results", small.results).output)
    assert f"{reason}: 2 run(s); first: {failed[0]} (alpha_minus_B=20, seed=" in text
    assert f"record (with traceback): {small.runs / failed[0]}.json" in text


def test_retry_failed_keeps_the_earlier_failure_in_the_record(copy_of_small):
    old = records(copy_of_small.runs)
    failed = [rid for rid, rec in old.items() if rec["status"] == "failed"]
    result = invoke(
        "run",
        copy_of_small.path,
        "--results",
        copy_of_small.results,
        "--retry-failed",
        "--no-figures",
        "--workers",
        "1",
    )
    assert result.exit_code == 1, result.output  # alpha - B = 20 fails again
    new = records(copy_of_small.runs)
    for rid in failed:
        assert new[rid]["finished"] >= old[rid]["finished"]
        (earlier,) = new[rid]["previous_failures"]
        for key in ("reason", "detail", "t_failed", "finished", "host", "pid", "traceback"):
            assert earlier[key] == old[rid].get(key), key
    assert all("previous_failures" not in new[rid] for rid in new if rid not in failed)


def test_max_failures_stops_the_campaign_with_exit_3(tmp_path):
    # one worker runs them in order: the failing runs first; of the 15 runs at most the
    # submission window (8) is ever submitted before the first failure is seen
    path = write_campaign(
        tmp_path,
        name="stops",
        values="[20.0, 0.1, 0.15, 0.2, 0.25]",
        seeds=3,
        t_final=2.0,
        workers=1,
    )
    # one run per task, so that the window counts runs (short runs share a task by default)
    path.write_text(path.read_text().replace("{workers: 1}", "{workers: 1, runs_per_task: 1}"))
    results = tmp_path / "results"
    result = invoke("run", path, "--results", results, "--max-failures", "0", "--no-figures")
    out = flat(result.output)
    assert result.exit_code == EXIT_TOO_MANY_FAILURES, result.output
    assert "Traceback" not in result.output
    assert (
        "error: stopped: too many runs failed: 1 failed this session, more than "
        "--max-failures 0 allows" in out
    )
    assert "the runs not finished stay pending" in out
    runs = results / "stops" / "runs"
    assert not list(runs.glob(".*"))  # nothing half-written
    assert not (results / "stops" / "phase.nc").exists()
    report = json.loads(invoke("status", path, "--results", results, "--json").output)
    assert report["failed"] >= 1
    assert report["pending"] >= 7
    assert report["done"] + report["failed"] + report["pending"] == 15
    bad = invoke("run", path, "--results", results, "--max-failures", "2.5")
    assert bad.exit_code == 2
    assert "error: --max-failures: got '2.5'; allowed:" in flat(bad.output)


@pytest.mark.parametrize(
    ("error", "reason", "says"),
    [
        (
            MemoryError("Unable to allocate 3.00 GiB"),
            "out_of_memory",
            [
                "the run needed more memory than its process has",
                "MemoryError: Unable to allocate 3.00 GiB",
                "allowed: a lower resolution, or more memory per run",
            ],
        ),
        (RuntimeError("no such model module"), "exception", ["RuntimeError: no such model module"]),
        # an OSError raised by the task is its failure, not a result lost on the way back
        (
            PermissionError(13, "Permission denied", "/results/runs"),
            "exception",
            ["PermissionError: [Errno 13] Permission denied: '/results/runs'"],
        ),
    ],
)
def test_a_task_that_fails_before_its_model_runs_is_recorded_with_its_run(
    tmp_path, monkeypatch, error, reason, says
):
    """A task that raises while it is set up on its worker (its folder opened, its model
    imported: outside the run's own try) reaches the driver as an exception instead of a
    record; its record names the run, its point and the stage, and a MemoryError there is
    ``out_of_memory`` with what the run needs and what to do, as in the run itself."""
    from distributed import Client, LocalCluster

    import nematic_solids.sweep.run.driver as driver
    import nematic_solids.sweep.run.task as task_module
    from nematic_solids.sweep.expand import expand
    from nematic_solids.sweep.run.todo import plan_runs
    from nematic_solids.sweep.spec import load_campaign
    from nematic_solids.sweep.store import CampaignStore

    path = write_campaign(tmp_path, values="[0.1, 0.2]", seeds=1, t_final=1.0, workers=1)
    expansion = expand(load_campaign(path))
    store = CampaignStore(tmp_path / "results", expansion.campaign.name)
    store.ensure()
    victim = expansion.run(0)
    real = task_module.task_store

    def setup_fails(task):
        if task.run_id == victim.run_id:
            raise error
        return real(task)

    monkeypatch.setattr(task_module, "task_store", setup_fails)
    with (
        LocalCluster(
            n_workers=1, processes=False, threads_per_worker=1, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        summary = driver.run_campaign(expansion, store, client, plan_runs(expansion, store))
    assert summary.ok == 1
    assert [run.run_id for run, _ in summary.failed] == [victim.run_id]
    record = store.read_record(victim.run_id)
    assert record is not None
    assert record["status"] == "failed"
    assert record["reason"] == reason
    detail = flat(record["detail"])
    assert f"run {victim.run_id} (alpha_minus_B=0.1, seed 0)" in detail, detail
    assert "failed while its task was set up on its worker, before the model ran" in detail
    for words in says:
        assert words in detail, detail
    assert record["coords"] == {"alpha_minus_B": 0.1}  # the run's identity, as any record
    assert type(error).__name__ in record["traceback"]
