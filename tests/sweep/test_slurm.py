"""Campaigns on a real one-node SLURM (scripts/slurm_local.sh) through execution.cluster:
the local run's phase.nc, jobs cancelled mid-campaign (one; all, replaced; one mid-run, its
run redone, not failed; one mid-run past a checkpoint, the run continued from it), workers
retiring before a walltime shorter than the campaign, runs longer than the walltime finished
across jobs from their checkpoints, the
driver as a batch job (the docs' script) stopped by `nematic stop` through scancel and
resubmitted, replacements that keep dying and a wrong `python` (a bounded, non-zero exit
naming the job logs and quoting the worker's error; a rerun resumes). TLS is on (the
default) in all of them.

Marked `slurm` (run with ``pytest -m slurm``; .ci/run does): the fixture installs the
Debian packages and starts the daemons, so it needs root and apt-get; elsewhere the tests
are skipped with the reason.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from sweep_helpers import kill_group, records, run_ids, start_driver, wait_for, write_campaign

pytestmark = pytest.mark.slurm

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "slurm_local.sh"


def _why_not() -> str | None:
    if sys.platform != "linux":
        return "a one-node SLURM is started on Linux only"
    if os.geteuid() != 0:
        return "starting SLURM (apt-get install, daemons) needs root"
    if shutil.which("slurmctld") is None and shutil.which("apt-get") is None:
        return "SLURM is not installed and there is no apt-get to install it"
    return None


@pytest.fixture(scope="module")
def slurm():
    """A running one-node SLURM; stopped afterwards unless it was running before."""
    why = _why_not()
    if why:
        pytest.skip(why)
    was_up = subprocess.run(["bash", str(SCRIPT), "status"], capture_output=True).returncode == 0
    t0 = time.monotonic()
    start = subprocess.run(
        ["bash", str(SCRIPT), "start"], capture_output=True, text=True, timeout=600
    )
    assert start.returncode == 0, start.stdout + start.stderr
    print(f"SLURM started in {time.monotonic() - t0:.0f} s")
    try:
        yield
    finally:
        subprocess.run(["scancel", "-u", "root"], capture_output=True)
        if not was_up:
            subprocess.run(["bash", str(SCRIPT), "stop"], capture_output=True, timeout=120)


CLUSTER = """\
execution:
  give_up_after: {give_up}
  cluster:
    kind: slurm
    {scale}
    cores: 1
    processes: 1
    memory: 1GB
    walltime: "00:10:00"
    interface: lo
    python: {python}
{extra}"""


def slurm_campaign(
    folder: Path,
    name: str,
    *,
    values: str = "[0.1, 0.2]",
    seeds: int = 2,
    t_final: float = 2.0,
    python: str = sys.executable,
    give_up: float = 120,
    extra: str = "",
    scale: str = "jobs: 2",
) -> Path:
    path = write_campaign(folder, name=name, values=values, seeds=seeds, t_final=t_final, workers=1)
    text = path.read_text().replace("execution: {workers: 1}\n", "")
    path.write_text(text + CLUSTER.format(python=python, give_up=give_up, extra=extra, scale=scale))
    return path


def nematic(args: list[object], timeout: float = 300) -> tuple[int, str, float]:
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "nematic_solids.sweep", *map(str, args), "--no-figures"],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, COLUMNS="300"),
    )
    text = proc.stdout + proc.stderr
    assert "Traceback" not in text, text
    return proc.returncode, " ".join(text.split()), time.monotonic() - t0


def queue() -> list[str]:
    out = subprocess.run(
        ["squeue", "-h", "-o", "%i"], capture_output=True, text=True, check=True
    ).stdout
    return out.split()


def cancel_all_jobs() -> list[str]:
    jobs = queue()
    subprocess.run(["scancel", *jobs], check=True)
    return jobs


def run_in_background(path: Path, results: Path, log: Path) -> subprocess.Popen:
    return start_driver(["run", str(path), "--results", str(results), "--no-figures"], log)


def wait_for_records(runs: Path, n: int, driver: subprocess.Popen, log: Path) -> None:
    wait_for(
        lambda: len(list(runs.glob("*.json"))) >= n or driver.poll() is not None,
        180,
        f"{n} finished run(s)",
    )
    assert driver.poll() is None, log.read_text()


def test_slurm_campaign_gives_the_local_phase_nc_with_tls(slurm, tmp_path):
    path = slurm_campaign(tmp_path / "slurm", "twin")
    local = write_campaign(tmp_path / "local", name="twin", values="[0.1, 0.2]", seeds=2, workers=1)
    rc, out, _ = nematic(["run", local, "--results", tmp_path / "local-results"])
    assert rc == 0, out
    rc, out, took = nematic(["run", path, "--results", tmp_path / "results"])
    print(f"SLURM campaign (2 jobs, 4 runs) in {took:.0f} s")
    assert rc == 0, out
    with (
        xr.open_dataset(tmp_path / "local-results" / "twin" / "phase.nc") as a,
        xr.open_dataset(tmp_path / "results" / "twin" / "phase.nc") as b,
    ):
        # bitwise data, dims and coords; but run_time, the runs' wall times
        xr.testing.assert_equal(a.load().drop_vars("run_time"), b.load().drop_vars("run_time"))
    folder = tmp_path / "results" / "twin"
    # the workers ran in the batch jobs, over TLS, with credentials only the owner reads
    hosts = {r["host"] for r in records(folder / "runs").values()}
    assert hosts
    logs = "".join(p.read_text() for p in (folder / "jobs").glob("*.err"))
    assert "Registered to:      tls://" in logs or "Registered to: tls://" in " ".join(
        logs.split()
    ), logs[-2000:]
    assert stat.S_IMODE((folder / "tls").stat().st_mode) == 0o700
    assert not list((folder / "tls").iterdir())  # removed with the cluster
    wait_for(lambda: not queue(), 60, "the jobs to end with the campaign")


def test_one_job_cancelled_mid_campaign(slurm, tmp_path):
    path = slurm_campaign(tmp_path, "one-cancelled", values="[0.1, 0.15, 0.2]", t_final=4.0)
    results, log = tmp_path / "results", tmp_path / "log"
    runs = results / "one-cancelled" / "runs"
    driver = run_in_background(path, results, log)
    try:
        wait_for_records(runs, 1, driver, log)
        victim = queue()[0]
        subprocess.run(["scancel", victim], check=True)
        rc = driver.wait(timeout=240)
    finally:
        kill_group(driver)
    assert rc == 0, log.read_text()
    recs = records(runs)
    assert sorted(recs) == sorted(run_ids(path))
    assert all(r["status"] == "ok" for r in recs.values())


@pytest.mark.parametrize("scale", ["jobs: 2", "adapt: {minimum_jobs: 0, maximum_jobs: 2}"])
def test_every_job_cancelled_is_replaced(slurm, tmp_path, scale):
    # long enough that runs remain when every job is cancelled after the first record
    path = slurm_campaign(
        tmp_path,
        "all-cancelled",
        values="[0.1, 0.12, 0.14, 0.16, 0.18, 0.2]",
        t_final=12.0,
        scale=scale,
    )
    results, log = tmp_path / "results", tmp_path / "log"
    runs = results / "all-cancelled" / "runs"
    driver = run_in_background(path, results, log)
    try:
        wait_for_records(runs, 1, driver, log)
        cancelled = cancel_all_jobs()
        rc = driver.wait(timeout=240)
    finally:
        kill_group(driver)
    text = " ".join(log.read_text().split())
    assert rc == 0, text
    assert "Traceback" not in text, text
    assert "submitting a replacement" in text, text
    for job in cancelled:
        assert f"batch job {job} (" in text, text
    recs = records(runs)
    assert sorted(recs) == sorted(run_ids(path))
    assert all(r["status"] == "ok" for r in recs.values())


def test_replacements_that_keep_dying_end_the_driver_then_a_rerun_resumes(slurm, tmp_path):
    """Once a marker file exists every new job dies in its prologue (a broken node): after
    every job is cancelled the driver gives up quickly, naming the job logs and quoting the
    error; without the marker a rerun completes the campaign."""
    marker = tmp_path / "broken"
    prologue = (
        f"    job_script_prologue: ['if [ -e {marker} ]; then echo \"error: node "
        f"broken ({marker} exists)\" >&2; exit 1; fi']\n"
    )
    path = slurm_campaign(tmp_path, "dying", values="[0.1, 0.15, 0.2]", t_final=4.0, extra=prologue)
    results, log = tmp_path / "results", tmp_path / "log"
    runs = results / "dying" / "runs"
    driver = run_in_background(path, results, log)
    try:
        wait_for_records(runs, 1, driver, log)
        marker.touch()
        cancel_all_jobs()
        t0 = time.monotonic()
        rc = driver.wait(timeout=240)
        took = time.monotonic() - t0
    finally:
        kill_group(driver)
    text = " ".join(log.read_text().split())
    print(f"gave up {took:.0f} s after every job was cancelled")
    assert rc == 2, text
    assert took < 120, text
    assert f"job logs: {results / 'dying' / 'jobs'}" in text, text
    assert f"last worker error: 'error: node broken ({marker} exists)'" in text, text
    assert "rerun the same command" in text
    # a run that a cancelled job finished may have its .nc renamed into place without its
    # record (the job died between the two renames, or after the driver gave up): the rerun
    # adopts it, so count the finished run files once every cancelled job has left the queue
    wait_for(lambda: not queue(), 120, "the cancelled jobs to leave the queue")
    done = len([p for p in runs.glob("*.nc") if not p.name.startswith(".")])
    assert 1 <= done < 6
    marker.unlink()
    rc, out, _ = nematic(["run", path, "--results", results])
    assert rc == 0, out
    assert f"{done} done" in out, out
    assert len(records(runs)) == 6


def test_a_wrong_python_fails_fast_quoting_the_worker_error(slurm, tmp_path):
    bare = tmp_path / "bare"  # an interpreter without the project (nor dask)
    subprocess.run(
        [sys.base_prefix + "/bin/python3", "-m", "venv", "--without-pip", str(bare)], check=True
    )
    path = slurm_campaign(tmp_path, "wrong-python", python=str(bare / "bin" / "python"))
    rc, out, took = nematic(["run", path, "--results", tmp_path / "results"], timeout=240)
    print(f"a wrong python refused in {took:.0f} s")
    assert rc == 2, out
    assert took < 90, out
    assert (
        "every batch job of the dask-jobqueue SLURMCluster ends before its dask worker joins" in out
    ), out
    assert f"job logs: {tmp_path / 'results' / 'wrong-python' / 'jobs'}" in out
    assert "No module named 'distributed'" in out, out
    assert "python or job_script_prologue" in out
    wait_for(lambda: not queue(), 60, "the jobs to end with the campaign")


def docs_slurm_example() -> str:
    """The SLURM campaign of docs/campaigns/clusters.md (the yaml block `name: fig2-slurm`)."""
    text = (ROOT / "docs" / "campaigns" / "clusters.md").read_text()
    start = text.index("```yaml\nname: fig2-slurm\n") + len("```yaml\n")
    return text[start : text.index("```", start)]


def test_the_docs_slurm_example_runs_on_one_machine(slurm, tmp_path):
    """As the docs say for one machine: interface lo, 2 jobs of 1 core, this checkout's venv
    (activated by the prologue), the job logs where the YAML puts them; the grid reduced."""
    venv = Path(sys.prefix)
    text = docs_slurm_example()
    for old, new in [
        ("interface: ib0", "interface: lo"),
        ("jobs: 4 ", "jobs: 2 "),
        ("cores: 8 ", "cores: 1 "),
        ("processes: 8 ", "processes: 1 "),
        ("memory: 16GB", "memory: 1GB"),
        ("/shared/me/nematic-logs", str(tmp_path / "logs")),
        ("/shared/me/nematic/.venv", str(venv)),
        ("num: 17", "num: 2"),
    ]:
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / "fig2-slurm.yaml"
    path.write_text(text)
    rc, out, took = nematic(
        [
            "run",
            path,
            "--results",
            tmp_path / "results",
            "--seeds",
            "1",
            "--set",
            "resolution=32",
            "--set",
            "noise_modes=8",
            "--set",
            "t_final=2",
        ]
    )
    print(f"the docs' SLURM example (reduced) in {took:.0f} s")
    assert rc == 0, out
    assert "2 run(s) in" in out, out
    assert list((tmp_path / "logs").glob("dask-worker-*.err"))


# ----------------------------------------------------------------------------- lost workers
LOW_PRIORITY = "    job_script_prologue: ['renice -n 19 -p $$ >/dev/null']\n"


def test_a_job_cancelled_mid_run_has_its_run_redone_not_failed(slurm, tmp_path):
    """One job, one worker: once a run is recorded the worker is on the next one, so
    cancelling the job cuts a run short; that run goes back to pending and is redone by the
    replacement job, and no run is recorded as failed."""
    path = slurm_campaign(
        tmp_path,
        "cut",
        values="[0.1, 0.12, 0.14, 0.16, 0.18, 0.2]",
        seeds=3,
        t_final=4.0,
        scale="jobs: 1",
        extra=LOW_PRIORITY,
    )
    results, log = tmp_path / "results", tmp_path / "log"
    runs = results / "cut" / "runs"
    driver = run_in_background(path, results, log)
    try:
        wait_for_records(runs, 1, driver, log)
        [victim] = queue()
        subprocess.run(["scancel", victim], check=True)
        rc = driver.wait(timeout=300)
    finally:
        kill_group(driver)
    text = " ".join(log.read_text().split())
    assert rc == 0, text
    assert f"batch job {victim} (" in text, text
    assert "submitting a replacement" in text, text
    recs = records(runs)
    assert sorted(recs) == sorted(run_ids(path))
    assert all(r["status"] == "ok" for r in recs.values()), recs
    assert len({r["pid"] for r in recs.values()}) >= 2  # the replacement's worker did runs


def test_workers_retire_before_a_walltime_shorter_than_the_campaign(slurm, tmp_path):
    """A 20-second walltime (SLURM enforces it as one minute): the workers retire after
    about 14 s (sweep/run/lifetime.py: 20 s less a 1 s stagger and a 5 s grace), before SLURM
    would kill them; their jobs are replaced and a campaign several times longer completes
    with every run ok. (200 runs to t = 16: about a minute of one worker's time here, four
    lifetimes and more, so that a fast machine too sees workers retire: a campaign done
    within the first lifetime would leave nothing to check.)"""
    path = slurm_campaign(
        tmp_path,
        "short-walltime",
        values="{linspace: [0.1, 0.5, 40]}",
        seeds=5,
        t_final=16.0,
        scale="jobs: 1",
        give_up=180,
        extra=LOW_PRIORITY,
    )
    path.write_text(path.read_text().replace('walltime: "00:10:00"', 'walltime: "00:00:20"'))
    results = tmp_path / "results"
    rc, out, took = nematic(["run", path, "--results", results], timeout=900)
    folder = results / "short-walltime"
    logs = sorted((folder / "jobs").glob("*.err"))
    print(f"200 runs under a 20-second walltime in {took:.0f} s, {len(logs)} job(s)")
    assert rc == 0, out[-3000:]
    recs = records(folder / "runs")
    assert sorted(recs) == sorted(run_ids(path))
    assert all(r["status"] == "ok" for r in recs.values())
    jobs = " ".join(p.read_text() for p in logs)
    assert "Reason: worker-lifetime-reached" in jobs, jobs[-3000:]
    assert "DUE TO TIME LIMIT" not in jobs, jobs[-3000:]  # retired, not killed
    # replaced: by the driver ("ended; submitting a replacement") or, when its check comes
    # after dask-jobqueue's own (the retired worker's job dropped and its spec started again),
    # by dask-jobqueue without a line: either way a second job ran the runs
    assert len(logs) >= 2
    assert len({r["pid"] for r in recs.values()}) >= 2


def test_runs_longer_than_the_walltime_finish_across_jobs_from_checkpoints(slurm, tmp_path):
    """Runs of about 30 s of compute under a 30-second walltime (the workers retire after about
    21 s): no run fits in one job, each is continued by the next job's worker from its
    checkpoint (every 3 s of wall time) and finishes; `status` meanwhile shows the runs in
    progress with the time reached and the checkpoint; the result equals the straight run."""
    path = slurm_campaign(
        tmp_path,
        "long-runs",
        values="[0.3]",
        seeds=2,
        t_final=LONG_T_FINAL,
        scale="jobs: 1",
        give_up=180,
        extra=LOW_PRIORITY,
    )
    text = path.read_text().replace('walltime: "00:10:00"', 'walltime: "00:00:30"')
    text = text.replace(
        f"resolution: 32, t_final: {LONG_T_FINAL}, save_every: 0.5, snapshot_times: [1]",
        f"resolution: 64, t_final: {LONG_T_FINAL}, save_every: 5, snapshot_times: [100]",
    )
    assert "resolution: 64" in text
    path.write_text(text + 'store: {checkpoint_every: "3 s"}\n')
    results, log = tmp_path / "results", tmp_path / "log"
    folder = results / "long-runs"
    driver = run_in_background(path, results, log)
    seen: list[dict] = []
    try:
        deadline = time.monotonic() + 900
        while driver.poll() is None and time.monotonic() < deadline:
            status = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "nematic_solids.sweep",
                    "status",
                    str(path),
                    "--results",
                    str(results),
                ]
                + ["--json"],
                capture_output=True,
                text=True,
                timeout=60,
            )
            if status.returncode == 0:
                seen.extend(json.loads(status.stdout)["in_progress"])
            time.sleep(10)  # a status is a process of its own: it competes with the worker
        rc = driver.wait(timeout=60)
    finally:
        kill_group(driver)
    text = " ".join(log.read_text().split())
    assert rc == 0, text[-3000:]
    recs = records(folder / "runs")
    assert sorted(recs) == sorted(run_ids(path))
    jobs = " ".join(p.read_text() for p in sorted((folder / "jobs").glob("*.err")))
    assert "Reason: worker-lifetime-reached" in jobs, jobs[-3000:]
    for rid, rec in recs.items():
        assert rec["status"] == "ok", rec
        resumed = [e for e in rec["lineage"] if e.startswith("checkpoint@")]
        assert resumed, rec["lineage"]  # continued across jobs, not redone from t = 0
        progress = [r for r in seen if r["run_id"] == rid]
        assert progress, "status never showed the run in progress"
        assert all(r["checkpoint"].endswith(f"checkpoints/{rid}.nc") for r in progress)
        assert all(0 < r["t"] < r["t_final"] == LONG_T_FINAL for r in progress)
    assert not list((folder / "checkpoints").glob("*.nc"))
    rid = run_ids(path)[0]
    assert_straight(recs[rid], folder / "runs" / f"{rid}.nc")  # the first run, array by array


def assert_straight(rec: dict, path: Path) -> None:
    """The run file ``path`` holds, array by array, the run of ``rec`` done in one piece."""
    from nematic_solids.model.parameters import Numerics, Parameters
    from nematic_solids.model.simulate import run as simulate

    ref = simulate(
        Parameters.from_dict(rec["parameters"]), Numerics.from_dict(rec["numerics"]), rec["seed"]
    )
    with xr.open_dataset(path) as ds:
        for name in ref.data_vars:
            if name != "wall_time":
                assert np.array_equal(ref[name].values, ds[name].values, equal_nan=True), name


def test_a_job_cancelled_mid_run_continues_the_run_from_its_checkpoint(slurm, tmp_path):
    """scancel of the only job while its run is past its first checkpoint: the replacement
    job's worker continues the run from the checkpoint, and the result equals the straight
    run array by array."""
    path = slurm_campaign(
        tmp_path, "cancel-ckpt", values="[0.3]", seeds=1, t_final=4000.0, scale="jobs: 1"
    )
    text = path.read_text().replace(
        "resolution: 32, t_final: 4000.0, save_every: 0.5, snapshot_times: [1]",
        "resolution: 64, t_final: 4000.0, save_every: 5, snapshot_times: [100]",
    )
    assert "resolution: 64" in text
    path.write_text(text + 'store: {checkpoint_every: "1 s"}\n')
    results, log = tmp_path / "results", tmp_path / "log"
    folder = results / "cancel-ckpt"
    [rid] = run_ids(path)
    ckpt = folder / "checkpoints" / f"{rid}.nc"
    driver = run_in_background(path, results, log)
    try:
        wait_for(lambda: ckpt.exists() or driver.poll() is not None, 300, "a checkpoint")
        assert driver.poll() is None, log.read_text()
        [victim] = queue()
        subprocess.run(["scancel", victim], check=True)
        rc = driver.wait(timeout=600)
    finally:
        kill_group(driver)
    text = " ".join(log.read_text().split())
    assert rc == 0, text[-3000:]
    assert f"batch job {victim} (" in text, text
    rec = records(folder / "runs")[rid]
    assert rec["status"] == "ok", rec
    assert any(e.startswith("checkpoint@") for e in rec["lineage"]), rec["lineage"]
    assert rec["started_at"] > 0
    assert_straight(rec, folder / "runs" / f"{rid}.nc")


#: the end of the runs longer than a walltime: about 30 s each at 64^2 on this machine
#: (3.6 s per 1000 tau, about 1 step per tau)
LONG_T_FINAL = 8000.0


# ----------------------------------------------------------------------------- the driver's job
def docs_driver_script() -> str:
    """The driver's batch script of docs/campaigns/clusters.md (the sh block `#!/bin/bash`)."""
    text = (ROOT / "docs" / "campaigns" / "clusters.md").read_text()
    start = text.index("```sh\n#!/bin/bash\n") + len("```sh\n")
    return text[start : text.index("```", start)]


def test_the_driver_as_a_batch_job_and_nematic_stop(slurm, tmp_path, monkeypatch):
    """The docs' batch script runs the driver in a job of its own (its worker jobs beside
    it); `nematic status` names the job; `nematic stop` from another host (as a login node
    is) stops it through scancel: exit 130 in its log, the runs not finished pending; the
    same script submitted again completes the campaign."""
    from typer.testing import CliRunner

    from nematic_solids.sweep.cli import app

    venv = Path(sys.prefix)
    campaign = slurm_campaign(
        tmp_path,
        "fig2-slurm",
        values="{linspace: [0.1, 0.5, 20]}",
        seeds=4,
        t_final=4.0,
        scale="jobs: 1",
        extra=LOW_PRIORITY,
    )
    script = docs_driver_script()
    for old, new in [
        ("/shared/me/nematic/.venv", str(venv)),
        ("fig2-driver-%j.log", str(tmp_path / "driver-%j.log")),
    ]:
        assert old in script, old
        script = script.replace(old, new)
    (tmp_path / "driver.sh").write_text(script)
    results = tmp_path / "results"
    env = dict(os.environ, NEMATIC_RESULTS=str(results), COLUMNS="300")

    def submit() -> str:
        return subprocess.run(
            ["sbatch", "--parsable", str(tmp_path / "driver.sh")],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()

    runs = results / "fig2-slurm" / "runs"
    job = submit()
    wait_for(
        lambda: len(list(runs.glob("*.json"))) >= 1 or job not in queue(), 300, "a finished run"
    )
    assert job in queue(), (tmp_path / f"driver-{job}.log").read_text()
    status = CliRunner().invoke(app, ["status", str(campaign), "--results", str(results)])
    assert f"SLURM job {job}" in status.output, status.output
    monkeypatch.setattr("nematic_solids.sweep.run.detach.socket.gethostname", lambda: "login-node")
    stop = CliRunner().invoke(app, ["stop", "fig2-slurm", "--results", str(results)])
    text = " ".join(stop.output.split())
    assert stop.exit_code == 0, text
    assert f"(scancel --batch --signal=TERM {job})" in text, text
    wait_for(lambda: job not in queue(), 120, "the driver's job to end")
    log = " ".join((tmp_path / f"driver-{job}.log").read_text().split())
    assert "interrupted after" in log, log[-3000:]
    done = len(records(runs))
    assert 1 <= done < 80
    assert all(r["status"] == "ok" for r in records(runs).values())
    again = submit()
    wait_for(lambda: again not in queue(), 600, "the resubmitted driver to finish")
    log = " ".join((tmp_path / f"driver-{again}.log").read_text().split())
    assert "phase diagram:" in log, log[-3000:]
    recs = records(runs)
    assert sorted(recs) == sorted(run_ids(campaign))
    assert all(r["status"] == "ok" for r in recs.values())
    wait_for(lambda: not queue(), 60, "the worker jobs to end with the campaign")
