"""Running campaigns for real (model at 32^2, short t_final, a local dask cluster): files and
records, failures, status, phase.nc, resume, grid extension, the lock, SIGKILL and Ctrl-C."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from sweep_helpers import (
    cli_modules,
    file_stamps,
    kill_group,
    records,
    run_ids,
    start_driver,
    wait_for,
    wait_group_gone,
    write_campaign,
)
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.lock import CampaignLock, read_lock_holder
from nematic_solids.sweep.run.task import RunTask, execute_run


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


# `small` (the campaign run once) and `copy_of_small` are in conftest.py: shared with
# tests/sweep/test_faults.py.


def test_failed_runs_are_recorded_and_exit_1(small):
    out = " ".join(small.result.output.split())
    assert small.result.exit_code == 1, small.result.output
    assert "FAILED run" in out
    assert "alpha_minus_B=20" in out
    assert "2 run(s) failed" in out
    recs = records(small.runs)
    assert set(recs) == set(small.ids)
    failed = [r for r in recs.values() if r["status"] == "failed"]
    assert len(failed) == 2
    assert all(r["coords"]["alpha_minus_B"] == 20.0 and r["reason"] for r in failed)


def test_every_run_has_a_complete_self_describing_file(small):
    recs = records(small.runs)
    for rid in small.ids:
        nc = small.runs / f"{rid}.nc"
        assert nc.stat().st_size == recs[rid]["nc_bytes"]
        with xr.open_dataset(nc) as ds:
            assert ds.attrs["run_id"] == rid
            assert ds.attrs["campaign"] == "small"
            assert ds.attrs["seed"] == recs[rid]["seed"]
            assert ds.attrs["status"] == recs[rid]["status"]
            assert math.isclose(
                ds.attrs["param_alpha_minus_B"], recs[rid]["coords"]["alpha_minus_B"]
            )
            assert "num_resolution" in ds.attrs
            assert "git_commit" in ds.attrs
            if recs[rid]["status"] == "ok":
                assert ds.sizes["x"] == 32
                assert float(ds["sigma2_S_final"]) == recs[rid]["scalars"]["sigma2_S_final"]
    assert not list(small.runs.glob(".*"))  # no temporary file left


def test_status_shows_counts_per_value_and_reasons(small):
    result = invoke("status", small.path, "--results", small.results)
    assert result.exit_code == 0, result.output
    out = " ".join(result.output.split())
    assert "4 done" in out
    assert "2 failed" in out
    assert "0 pending of 6" in out
    reason = next(r["reason"] for r in records(small.runs).values() if r["status"] != "ok")
    assert f"{reason}: 2" in out
    as_json = json.loads(invoke("status", small.path, "--results", small.results, "--json").output)
    assert (as_json["done"], as_json["failed"], as_json["pending"]) == (4, 2, 0)
    axis = as_json["per_axis"][0]
    assert axis["labels"] == ["0.1", "0.2", "20"]
    assert axis["done"] == [2, 2, 0]
    assert axis["failed"] == [0, 0, 2]


def test_run_prints_warm_up_dashboard_and_progress_lines(small):
    out = " ".join(small.result.output.split())
    assert "workers ready in" in out
    assert "dask dashboard: http://127.0.0.1:" in out
    assert "progress: 6/6 runs" in out  # without a terminal: lines, not a bar


def test_status_eta_from_the_median_run_time(copy_of_small):
    recs = records(copy_of_small.runs)
    ok = sorted(rid for rid, r in recs.items() if r["status"] == "ok")
    slow = copy_of_small.runs / f"{ok[0]}.json"  # a first run that compiled: 600 s
    rec = json.loads(slow.read_text())
    rec["wall_time"] = 600.0
    slow.write_text(json.dumps(rec))
    for suffix in (".json", ".nc"):  # one run to do
        (copy_of_small.runs / f"{ok[1]}{suffix}").unlink()
    report = json.loads(
        invoke(
            "status",
            copy_of_small.path,
            "--results",
            copy_of_small.results,
            "--json",
            "--workers",
            "2",
        ).output
    )
    times = sorted([600.0] + [recs[r]["wall_time"] for r in ok[2:]])
    assert report["pending"] == 1
    assert report["median_run_time"] == pytest.approx(float(np.median(times)))
    assert report["mean_run_time"] > 200  # the mean is what the 600 s run skews
    assert report["eta_seconds"] == pytest.approx(report["median_run_time"] / 2)
    assert "median run time" in report["eta_basis"]
    text = " ".join(
        invoke("status", copy_of_small.path, "--results", copy_of_small.results).output.split()
    )
    assert f"run time: median {report['median_run_time']:.3g} s" in text


def test_phase_nc(small, tmp_path):
    path = small.results / "small" / "phase.nc"
    recs = records(small.runs)
    with xr.open_dataset(path) as ds:
        ds.load()
    assert ds["sigma2_S"].dims == ("alpha_minus_B", "seed")
    np.testing.assert_array_equal(ds["alpha_minus_B"].values, [0.1, 0.2, 20.0])
    np.testing.assert_array_equal(ds["seed"].values, [0, 1])
    assert ds["seed"].attrs["standard_name"] == "realization"
    assert ds["status"].attrs["flag_meanings"] == "missing ok failed"
    np.testing.assert_array_equal(ds["status"].values, [[1, 1], [1, 1], [2, 2]])
    for name in ("sigma2_S", "mean_S", "cos2theta", "lambda_peak", "t_peak"):
        for suffix in ("", "_mean", "_std", "_count"):
            var = ds[name + suffix]
            assert var.attrs["long_name"]
            assert var.attrs["units"] == "1"
    # values come from the run files; failed runs are NaN
    for i in range(3):
        for j in range(2):
            rid = str(ds["run_id"].values[i, j])
            if recs[rid]["status"] == "ok":
                with xr.open_dataset(small.runs / f"{rid}.nc") as run:
                    assert ds["sigma2_S"].values[i, j] == float(run["sigma2_S_final"])
                    assert ds["t_peak"].values[i, j] == float(run["t_peak"])
            else:
                assert np.isnan(ds["sigma2_S"].values[i, j])
    s = ds["sigma2_S"].values
    np.testing.assert_allclose(ds["sigma2_S_mean"].values[:2], s[:2].mean(axis=1), rtol=1e-14)
    np.testing.assert_allclose(ds["sigma2_S_std"].values[:2], s[:2].std(axis=1, ddof=1), rtol=1e-12)
    np.testing.assert_array_equal(ds["sigma2_S_count"].values, [2, 2, 0])
    assert np.isnan(ds["sigma2_S_mean"].values[2])
    # provenance
    assert ds.attrs["Conventions"].startswith("CF-")
    assert ds.attrs["campaign_yaml"] == small.path.read_text()
    assert ds.attrs["code_version"]
    assert ds.attrs["git_commit"]
    assert ds.attrs["created"]
    assert (ds.attrs["n_ok"], ds.attrs["n_failed"], ds.attrs["n_missing"]) == (4, 2, 0)
    assert ds.attrs["param_noise_modes"] == 8
    assert ds.attrs["num_resolution"] == 32
    # round trip
    again = tmp_path / "again.nc"
    ds.to_netcdf(again)
    with xr.open_dataset(again) as back:
        xr.testing.assert_identical(back.load(), ds)


def test_resume_skips_finished_runs(copy_of_small):
    before = file_stamps(copy_of_small.runs)
    result = invoke("run", copy_of_small.path, "--results", copy_of_small.results, "--no-figures")
    out = " ".join(result.output.split())
    assert result.exit_code == 1  # the two failures are still failures
    assert "4 done, 2 failed" in out
    assert "0 to run" in out
    assert file_stamps(copy_of_small.runs) == before


def test_retry_failed_and_grid_extension(copy_of_small):
    before = file_stamps(copy_of_small.runs)
    old_records = records(copy_of_small.runs)
    text = copy_of_small.path.read_text().replace("[0.1, 0.2, 20.0]", "[0.1, 0.15, 0.2, 20.0]")
    copy_of_small.path.write_text(text)
    result = invoke(
        "run",
        copy_of_small.path,
        "--results",
        copy_of_small.results,
        "--retry-failed",
        "--no-figures",
    )
    assert result.exit_code == 1, result.output  # alpha - B = 20 fails again
    out = " ".join(result.output.split())
    assert "8 runs" in out
    assert "4 done" in out
    assert "4 to run" in out
    after = file_stamps(copy_of_small.runs)
    ok_before = [r for r, rec in old_records.items() if rec["status"] == "ok"]
    assert all(after[r] == before[r] for r in ok_before)  # finished runs not recomputed
    recs = records(copy_of_small.runs)
    assert len(recs) == 8
    new = [r for r in recs if r not in old_records]
    assert len(new) == 2
    assert all(recs[r]["coords"]["alpha_minus_B"] == 0.15 for r in new)
    redone = [r for r, rec in old_records.items() if rec["status"] == "failed"]
    assert all(recs[r]["finished"] >= old_records[r]["finished"] for r in redone)
    assert all(recs[r]["pid"] != old_records[r]["pid"] for r in redone)
    with xr.open_dataset(copy_of_small.results / "small" / "phase.nc") as ds:
        assert ds.sizes["alpha_minus_B"] == 4


def test_a_run_file_without_its_record_is_adopted(copy_of_small):
    old = records(copy_of_small.runs)
    rid = next(r for r, rec in old.items() if rec["status"] == "ok")
    (copy_of_small.runs / f"{rid}.json").unlink()  # the worker died between the two renames
    before = file_stamps(copy_of_small.runs)
    result = invoke("run", copy_of_small.path, "--results", copy_of_small.results, "--no-figures")
    assert result.exit_code == 1  # the two failures remain
    assert "recovered 1 unindexed run file" in " ".join(result.output.split())
    assert file_stamps(copy_of_small.runs) == before
    adopted = records(copy_of_small.runs)[rid]
    assert adopted["status"] == "ok"
    assert adopted["scalars"] == old[rid]["scalars"]


def test_a_second_driver_is_refused(copy_of_small):
    lock = CampaignLock(copy_of_small.results / "small" / ".lock")
    lock.acquire(command="nematic run small.yaml")
    try:
        result = invoke("run", copy_of_small.path, "--results", copy_of_small.results)
        assert result.exit_code == 2
        out = " ".join(result.output.split())
        assert "in use by another driver" in out
        assert f"pid {os.getpid()}" in out
        result = invoke("aggregate", copy_of_small.path, "--results", copy_of_small.results)
        assert result.exit_code == 2
        status = invoke("status", copy_of_small.path, "--results", copy_of_small.results)
        assert status.exit_code == 0
        assert f"running: pid {os.getpid()}" in status.output
    finally:
        lock.release()
    assert read_lock_holder(lock.path) is None


@pytest.mark.slow
def test_two_driver_processes_on_one_folder(tmp_path):
    """Two real drivers of one campaign on one results folder, the second started while the
    first holds the lock: the second is refused (exit 2, naming the holder); the first ends
    with every run's arrays bit-identical to a campaign run alone."""
    alone = write_campaign(tmp_path / "alone", name="two", values="[0.1, 0.2]", t_final=20)
    assert invoke("run", alone, "--results", tmp_path / "alone" / "results").exit_code == 0
    path = write_campaign(tmp_path / "both", name="two", values="[0.1, 0.2]", t_final=20)
    results = tmp_path / "both" / "results"
    lock = results / "two" / ".lock"
    first = start_driver(["run", str(path), "--results", str(results)], tmp_path / "first.log")
    try:
        wait_for(
            lambda: read_lock_holder(lock) is not None or first.poll() is not None,
            120,
            "the first driver's lock",
            interval=0.02,
        )
        assert first.poll() is None, (tmp_path / "first.log").read_text()
        second = start_driver(
            ["run", str(path), "--results", str(results)], tmp_path / "second.log"
        )
        try:
            assert second.wait(timeout=120) == 2
        finally:
            kill_group(second)
        said = " ".join((tmp_path / "second.log").read_text().split())
        assert "in use by another driver" in said
        assert f"pid {first.pid}" in said
        assert first.wait(timeout=300) == 0, (tmp_path / "first.log").read_text()
    finally:
        kill_group(first)
    runs, want = results / "two" / "runs", tmp_path / "alone" / "results" / "two" / "runs"
    assert sorted(records(runs)) == sorted(records(want))
    for got in runs.glob("*.nc"):
        with xr.open_dataset(got) as a, xr.open_dataset(want / got.name) as b:
            for name in a.data_vars:
                if name != "wall_time":
                    assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name


def test_aggregate_command(copy_of_small):
    phase = copy_of_small.results / "small" / "phase.nc"
    phase.unlink()
    result = invoke("aggregate", copy_of_small.path, "--results", copy_of_small.results)
    assert result.exit_code == 0, result.output
    assert "4 ok, 2 failed, 0 missing of 6 runs" in " ".join(result.output.split())
    assert phase.exists()


def test_aggregate_in_a_fresh_process_writes_the_phase_nc_the_run_wrote(copy_of_small):
    """``nematic aggregate`` as its own process (the collector paused, xarray without
    dask.array: sweep/startup.py) writes what the driver wrote after the run: the same
    variables, values, encodings and attributes but the time stamps."""
    with xr.open_dataset(copy_of_small.phase) as ds:
        before = ds.load()
    modules, out = cli_modules("aggregate", copy_of_small.path, "--results", copy_of_small.results)
    assert "4 ok, 2 failed, 0 missing of 6 runs" in " ".join(out.split()), out
    assert "dask.array" not in modules
    with xr.open_dataset(copy_of_small.phase) as ds:
        after = ds.load()
    assert after.equals(before)
    for name, var in before.variables.items():
        assert str(after[name].dtype) == str(var.dtype), name
        assert after[name].attrs.keys() == var.attrs.keys(), name
        assert after[name].encoding.get("dtype") == var.encoding.get("dtype"), name
    stamps = {"created", "history"}
    assert {k: v for k, v in after.attrs.items() if k not in stamps} == {
        k: v for k, v in before.attrs.items() if k not in stamps
    }


def test_aggregate_marks_missing_runs(copy_of_small):
    victim = copy_of_small.ids[0]
    (copy_of_small.runs / f"{victim}.json").unlink()
    (copy_of_small.runs / f"{victim}.nc").unlink()
    assert (
        invoke("aggregate", copy_of_small.path, "--results", copy_of_small.results).exit_code == 0
    )
    with xr.open_dataset(copy_of_small.results / "small" / "phase.nc") as ds:
        assert int(ds["status"].values[0, 0]) == 0
        assert np.isnan(ds["sigma2_S"].values[0, 0])
        assert int(ds["sigma2_S_count"].values[0]) == 1
        assert np.isnan(ds["sigma2_S_std"].values[0])


def test_a_crashing_run_is_recorded_with_its_traceback(tmp_path):
    runs = tmp_path / "results" / "crash" / "runs"
    runs.mkdir(parents=True)
    task = RunTask(
        run_id="0123456789abcdef",
        seed=0,
        parameters={"K": -1.0},
        numerics={"resolution": 32},
        runs_dir=str(runs),
        campaign="crash",
    )
    record = execute_run(task)
    assert record["status"] == "failed"
    assert record["reason"] == "exception"
    assert "ParameterError" in record["traceback"]
    assert "'K'" in record["detail"]
    assert json.loads((runs / "0123456789abcdef.json").read_text())["reason"] == "exception"
    assert not (runs / "0123456789abcdef.nc").exists()


def test_sigkill_of_the_driver_then_resume(tmp_path):
    # 8 runs: after the driver's SIGKILL each of the 2 workers may still finish the run it is
    # doing and the one it holds (dask gives a worker of 1 thread up to 2), so 2 + 4 < 8
    # leaves runs pending for the resume
    path = write_campaign(
        tmp_path, name="killed", values="[0.1, 0.15, 0.2, 0.25]", seeds=2, t_final=2.5
    )
    results = tmp_path / "results"
    runs = results / "killed" / "runs"
    ids = run_ids(path)
    proc = start_driver(
        ["run", str(path), "--results", str(results), "--no-figures"], tmp_path / "log"
    )
    try:
        wait_for(
            lambda: len(list(runs.glob("*.json"))) >= 2 or proc.poll() is not None,
            120,
            "two finished runs",
        )
        assert proc.poll() is None, (tmp_path / "log").read_text()
        proc.send_signal(signal.SIGKILL)  # the driver alone, mid-campaign
        proc.wait(timeout=10)
        # its orphaned workers may still finish a run: the folder is read once they are gone
        wait_group_gone(proc.pid)
    finally:
        kill_group(proc)
    done = sorted(records(runs))
    assert 2 <= len(done) < len(ids)
    # Plant damage: truncate a finished file; put garbage where a pending run's file goes.
    truncated = done[0]
    nc = runs / f"{truncated}.nc"
    nc.write_bytes(nc.read_bytes()[: nc.stat().st_size // 2])
    pending = next(r for r in ids if r not in done)
    (runs / f"{pending}.nc").write_bytes(b"CDF\x01 not really netCDF")
    before = file_stamps(runs)

    result = invoke("run", path, "--results", results, "--no-figures")
    assert result.exit_code == 0, result.output
    recs = records(runs)
    assert sorted(recs) == sorted(ids)
    after = file_stamps(runs)
    # every intact run file is kept: the finished runs', and a file whose worker died before
    # it wrote the record (adopted); the truncated one, the garbage and the rest are redone
    untouched = [r for r in before if r not in (truncated, pending)]
    assert set(done) - {truncated} <= set(untouched)
    assert all(after[r] == before[r] for r in untouched)  # not recomputed
    recomputed = [r for r in ids if after[r] != before.get(r)]
    assert sorted(recomputed) == sorted(set(ids) - set(untouched))
    for rid in (truncated, pending):
        assert (runs / f"{rid}.nc").stat().st_size == recs[rid]["nc_bytes"]
        with xr.open_dataset(runs / f"{rid}.nc") as ds:
            assert ds.attrs["run_id"] == rid
    assert not list(runs.glob(".*"))


def test_ctrl_c_stops_cleanly(tmp_path):
    path = write_campaign(
        tmp_path, name="interrupted", values="[0.1, 0.15, 0.2]", seeds=2, t_final=2.5
    )
    results = tmp_path / "results"
    runs = results / "interrupted" / "runs"
    log = tmp_path / "log"
    proc = start_driver(["run", str(path), "--results", str(results), "--no-figures"], log)
    try:
        wait_for(
            lambda: len(list(runs.glob("*.json"))) >= 1 or proc.poll() is not None,
            120,
            "a finished run",
        )
        assert proc.poll() is None, log.read_text()
        os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does
        rc = proc.wait(timeout=60)
        wait_group_gone(proc.pid)  # the driver closed its workers: nothing writes any more
    finally:
        kill_group(proc)
    assert rc == 130, log.read_text()
    assert "rerun the same command to resume" in " ".join(log.read_text().split())
    assert read_lock_holder(results / "interrupted" / ".lock") is None
    assert not list(runs.glob(".*"))
    n_done = len(records(runs))
    assert 1 <= n_done < 6
    # the folder is consistent: what finished is done, the rest pending (the SIGKILL test
    # shows a rerun completing such a folder)
    status = json.loads(invoke("status", path, "--results", results, "--json").output)
    assert (status["done"], status["failed"], status["pending"]) == (n_done, 0, 6 - n_done)


# ----------------------------------------------------------------------------- a real cluster
@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """A real `dask scheduler` and two `dask worker` processes on 127.0.0.1."""
    folder = tmp_path_factory.mktemp("cluster")
    sched_file = folder / "scheduler.json"
    dask = [sys.executable, "-m", "dask"]  # the `dask` command of this environment
    procs: list[subprocess.Popen] = []

    def spawn(args: list[str], name: str) -> subprocess.Popen:
        with open(folder / f"{name}.log", "wb") as log:
            p = subprocess.Popen(
                [*dask, *args], stdout=log, stderr=subprocess.STDOUT, start_new_session=True
            )
        procs.append(p)
        return p

    try:
        spawn(
            [
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(sched_file),
            ],
            "scheduler",
        )
        wait_for(sched_file.exists, 60, "the dask scheduler")
        address = json.loads(sched_file.read_text())["address"]
        workers = [
            spawn(
                [
                    "worker",
                    address,
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    "--host",
                    "127.0.0.1",
                    "--no-dashboard",
                    "--name",
                    f"w{i}",
                ],
                f"worker{i}",
            )
            for i in range(2)
        ]
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        yield SimpleNamespace(address=address, workers=workers, folder=folder)
    finally:
        for p in procs:
            kill_group(p)


def test_cluster_run_gives_the_local_phase_nc(small, dask_cluster, tmp_path):
    results = tmp_path / "results"
    result = invoke(
        "run", small.path, "--results", results, "--scheduler", dask_cluster.address, "--no-figures"
    )
    assert result.exit_code == 1, result.output  # the same two failures
    with (
        xr.open_dataset(small.results / "small" / "phase.nc") as local,
        xr.open_dataset(results / "small" / "phase.nc") as remote,
    ):
        # the runs' wall times (run_time) differ; the rest is bitwise the same
        local, remote = local.load().drop_vars("run_time"), remote.load().drop_vars("run_time")
        differ = {
            n: (local[n].values, remote[n].values)
            for n in local.data_vars
            if not local[n].equals(remote[n])
        }
        # bitwise: the model is deterministic across processes (same seed, same numerics)
        assert not differ, differ
        xr.testing.assert_equal(local, remote)  # data, dims and coords
        assert local.attrs["campaign_yaml"] == remote.attrs["campaign_yaml"]
    pids = {r["pid"] for r in records(results / "small" / "runs").values()}
    assert pids <= {p.pid for p in dask_cluster.workers}  # ran on the cluster's workers


def test_a_worker_killed_mid_campaign(dask_cluster, tmp_path):
    path = write_campaign(
        tmp_path, name="worker-killed", values="[0.1, 0.15, 0.2]", seeds=2, t_final=3.0
    )
    results = tmp_path / "results"
    runs = results / "worker-killed" / "runs"
    log = tmp_path / "log"
    driver = start_driver(
        [
            "run",
            str(path),
            "--results",
            str(results),
            "--scheduler",
            dask_cluster.address,
            "--no-figures",
        ],
        log,
    )
    try:
        wait_for(
            lambda: len(list(runs.glob("*.json"))) >= 1 or driver.poll() is not None,
            120,
            "a finished run",
        )
        assert driver.poll() is None, log.read_text()
        victim = dask_cluster.workers[0]
        victim.send_signal(signal.SIGKILL)
        victim.wait(timeout=10)
        rc = driver.wait(timeout=180)
    finally:
        kill_group(driver)
    assert rc == 0, log.read_text()
    recs = records(runs)
    assert sorted(recs) == sorted(run_ids(path))
    assert all(r["status"] == "ok" for r in recs.values())
    assert {r["pid"] for r in recs.values()} <= {victim.pid, dask_cluster.workers[1].pid}


def test_store_section_keeps_the_chosen_snapshot_fields(tmp_path):
    from nematic_solids.sweep.expand import expand
    from nematic_solids.sweep.spec import parse_campaign
    from nematic_solids.sweep.store import CampaignStore

    campaign = parse_campaign(
        "name: stored\nparameters: {noise_modes: 8, alpha_minus_B: 0.1}\n"
        "numerics: {resolution: 32, t_final: 1}\nseeds: 1\n"
        "store: {snapshot_times: [0.5], snapshot_fields: [q1, A], snapshot_dtype: float32}\n"
    )
    run = next(iter(expand(campaign)))
    store = CampaignStore(tmp_path, "stored")
    store.ensure()
    record = execute_run(RunTask.from_spec(run, store, campaign.name, campaign.store))
    assert record["status"] == "ok", record
    with xr.open_dataset(store.nc_path(run.run_id)) as ds:
        snapshots = {n for n, v in ds.data_vars.items() if "snapshot_time" in v.dims}
        assert snapshots == {"q1", "A"}
        assert ds["q1"].dtype == np.float32
        np.testing.assert_allclose(ds["snapshot_time"].values, [0.5, 1.0])
        assert ds.attrs["run_id"] == run.run_id
        assert ds["q1"].encoding.get("zlib")


def test_workers_reuse_freed_heap_memory_despite_the_nannys_trim_setting():
    """dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536, which makes glibc map and unmap every
    large temporary array anew (a page fault per page, every time); execute_run restores heap
    reuse. Counted in page faults (work), in a process started as the nanny starts workers."""
    import subprocess
    import sys

    code = """
import resource, sys
import numpy as np
from nematic_solids.sweep.run.task import restore_heap_reuse

def faults():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(100):
        a = np.empty(2 << 17)  # 2 MB, as a 128^2 tangent
        a[:] = 1.0
        del a
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

plain = faults()
ok = restore_heap_reuse()
print(plain, faults(), ok)
"""
    env = dict(os.environ, MALLOC_TRIM_THRESHOLD_="65536")
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    ).stdout.split()
    plain, tuned, ok = int(out[0]), int(out[1]), out[2] == "True"
    if not ok:
        pytest.skip("not glibc: mallopt is not available")
    assert plain > 100 * 400  # ~512 faults per array without reuse
    assert tuned < plain / 20
