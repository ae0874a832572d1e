"""The driver and its workers: a driver on an external scheduler that loses the scheduler or
every worker mid-campaign gives up within execution.give_up_after with a message and a
non-zero exit, and a rerun resumes; the supervisor's worker check and window (a fake
client); TLS of the schedulers the driver starts (a plain tcp client and a TLS client with
other credentials cannot connect); the job logs' last error."""

from __future__ import annotations

import json
import os
import re
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sweep_helpers import kill_group, records, run_ids, start_driver, wait_for, write_campaign

from nematic_solids.sweep.campaign import ClusterSpec, ExecutionSpec
from nematic_solids.sweep.errors import ClusterError
from nematic_solids.sweep.run.clusters import jobqueue_options, make_jobqueue, open_cluster
from nematic_solids.sweep.run.workers import (
    MIN_INFLIGHT,
    ClusterLink,
    Supervisor,
    last_worker_error,
    scheduler_workers,
    window_size,
)


# --------------------------------------------------------------------------- a real scheduler
def spawn(args: list[str], log: Path) -> subprocess.Popen:
    with open(log, "wb") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "dask", *args],
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )


def start_scheduler(folder: Path) -> tuple[subprocess.Popen, str]:
    sched_file = folder / "scheduler.json"
    sched_file.unlink(missing_ok=True)
    proc = spawn(
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
        folder / "scheduler.log",
    )
    wait_for(sched_file.exists, 60, "the dask scheduler")
    return proc, json.loads(sched_file.read_text())["address"]


def start_worker(address: str, folder: Path, name: str) -> subprocess.Popen:
    return spawn(
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
            name,
        ],
        folder / f"{name}.log",
    )


def campaign(folder: Path, name: str) -> Path:
    path = write_campaign(
        folder, name=name, values="[0.1, 0.15, 0.2]", seeds=2, t_final=3.0, workers=1
    )
    # one run per task, so that the cluster is lost with runs in flight (short runs would
    # share a task, and all end at once)
    path.write_text(
        path.read_text().replace(
            "execution: {workers: 1}", "execution: {give_up_after: 8, runs_per_task: 1}"
        )
    )
    return path


def rerun_completes(path: Path, results: Path, folder: Path, done_before: int) -> None:
    scheduler, address = start_scheduler(folder)
    worker = start_worker(address, folder, "again")
    try:
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "nematic_solids.sweep",
                "run",
                str(path),
                "--results",
                str(results),
                "--scheduler",
                address,
                "--no-figures",
            ],
            capture_output=True,
            text=True,
            timeout=300,
            env=dict(os.environ, COLUMNS="300"),
        )
    finally:
        kill_group(worker)
        kill_group(scheduler)
    out = " ".join((proc.stdout + proc.stderr).split())
    assert proc.returncode == 0, out
    # a run whose file was written as its worker went, before its record, is recovered from
    # the file by the rerun and counted done with the others
    recovered = re.search(r"recovered (\d+) unindexed run file", out)
    done_now = done_before + (int(recovered.group(1)) if recovered else 0)
    assert f"{done_now} done" in out, out
    recs = records(results / path.stem / "runs")
    assert sorted(recs) == sorted(run_ids(path))


@pytest.mark.parametrize("lose", ["scheduler", "workers"])
def test_a_driver_that_loses_its_cluster_gives_up_in_bounded_time(tmp_path, lose):
    """The scheduler killed, or every worker killed (nobody restarts them): exit 2 within
    execution.give_up_after (8 s) plus the time to notice, saying so; a rerun resumes."""
    path = campaign(tmp_path, f"lose-{lose}")
    results, log = tmp_path / "results", tmp_path / "driver.log"
    runs = results / path.stem / "runs"
    scheduler, address = start_scheduler(tmp_path)
    worker = start_worker(address, tmp_path, "w0")
    try:
        driver = start_driver(
            ["run", str(path), "--results", str(results), "--scheduler", address, "--no-figures"],
            log,
        )
        wait_for(
            lambda: len(list(runs.glob("*.json"))) >= 1 or driver.poll() is not None,
            120,
            "a finished run",
        )
        assert driver.poll() is None, log.read_text()
        victims = [scheduler] if lose == "scheduler" else [worker]
        for v in victims:
            os.killpg(v.pid, signal.SIGKILL)
        t0 = time.monotonic()
        try:
            rc = driver.wait(timeout=120)
        finally:
            kill_group(driver)
        took = time.monotonic() - t0
    finally:
        kill_group(worker)
        kill_group(scheduler)
    text = " ".join(log.read_text().split())
    assert "Traceback" not in text, text
    assert took < 60, (took, text)
    if lose == "scheduler":  # dask cancels the runs in flight at once
        assert rc == 1, text
        # the lost scheduler is named: by the driver, or, when every task it had was cancelled
        # before it saw the connection go (short runs share a task: one may hold all that
        # remain), by the cancellations' reason
        assert (
            f"the connection to the dask scheduler at {address} is lost" in text
            or "scheduler-connection-lost" in text
        ), text
        assert (
            "were cancelled by dask (the scheduler or cluster went away); rerun the same "
            "command to do them" in text
        ), text
    else:
        assert rc == 2, text
        assert f"no worker is left in the dask scheduler at {address}" in text, text
        assert "none came back within 8 s (execution.give_up_after)" in text, text
        assert "rerun the same command to resume" in text
    done = len(list(runs.glob("*.json")))
    assert 1 <= done < 6
    rerun_completes(path, results, tmp_path, done)


# --------------------------------------------------------------------------- the supervisor
class FakeClient:
    """What the supervisor asks of a dask client: workers come and go, answer the check."""

    def __init__(self) -> None:
        self.status = "running"
        self.workers: dict[str, dict] = {}
        self.answers: dict[str, object] = {}
        self.retired: list[str] = []

    def join(self, addr: str, nthreads: int, answer: object) -> None:
        self.workers[addr] = {"nthreads": nthreads, "name": addr}
        self.answers[addr] = answer

    @property
    def scheduler(self) -> FakeClient:
        return self

    def identity(self, n_workers: int = 0) -> dict:
        return {"workers": dict(self.workers) if n_workers else {}}

    def sync(self, fn, **kwargs):
        return fn(**kwargs)

    def run(self, fn, workers, on_error):
        return {a: self.answers[a] for a in workers if a in self.workers}

    def retire_workers(self, addrs, close_workers):
        self.retired += addrs
        for a in addrs:
            self.workers.pop(a, None)


def test_the_workers_are_asked_of_the_scheduler_not_of_the_clients_cache():
    """distributed's client refreshes its scheduler_info() cache without the workers every
    2 s; that refresh can land between a scheduler_info(n_workers=-1) call's own refresh and
    its return, and every worker would seem to have left. scheduler_workers asks the
    scheduler: with the refresh every 5 ms, 3,000 calls all see both workers."""
    import dask
    from distributed import Client, LocalCluster

    with (
        dask.config.set({"distributed.client.scheduler-info-interval": "5ms"}),
        LocalCluster(n_workers=2, processes=False, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        seen = [len(scheduler_workers(client)) for _ in range(3000)]
    assert set(seen) == {2}


MINE = {"code_version": "1.0", "git_commit": "abc"}


def supervisor(client: FakeClient, now: list[float], **execution) -> Supervisor:
    return Supervisor(
        ClusterLink(client, "the test cluster"),  # type: ignore[arg-type]
        ExecutionSpec(**execution),
        clock=lambda: now[0],
        mine=dict(MINE),
    )


def test_the_window_follows_the_workers_as_they_join_and_leave():
    client, now = FakeClient(), [0.0]
    watch = supervisor(client, now, give_up_after=30)
    client.join("tcp://a:1", 2, dict(MINE))
    watch.wait_for_first()
    assert watch.window == window_size(2) == MIN_INFLIGHT
    for i in range(2, 6):
        client.join(f"tcp://b:{i}", 4, dict(MINE))
    watch.check()
    assert watch.threads == 18
    assert watch.window == 4 * 18
    for i in range(2, 6):
        del client.workers[f"tcp://b:{i}"]
    watch.check()
    assert watch.window == MIN_INFLIGHT
    del client.workers["tcp://a:1"]
    watch.check()  # none left: the clock starts
    now[0] = 29.0
    watch.check()
    client.join("tcp://c:1", 1, dict(MINE))  # one came back in time
    now[0] = 31.0
    watch.check()
    assert watch.threads == 1
    del client.workers["tcp://c:1"]
    watch.check()
    now[0] = 62.0
    with pytest.raises(
        ClusterError, match="no worker is left in the test cluster and none came back within 30 s"
    ):
        watch.check()


@pytest.mark.parametrize(
    ("answer", "reason"),
    [
        (
            ModuleNotFoundError("No module named 'model'"),
            "it cannot run the model (ModuleNotFoundError: No module named 'model')",
        ),
        (
            {"code_version": "0.9", "git_commit": "abc"},
            "its code version is '0.9', the driver's is '1.0'",
        ),
        (
            {"code_version": "1.0", "git_commit": "def"},
            "its code is at commit def, the driver's at abc",
        ),
    ],
)
def test_a_worker_that_cannot_run_the_campaign_is_refused(answer, reason):
    client, now = FakeClient(), [0.0]
    client.join("tcp://bad:1", 1, answer)
    watch = supervisor(client, now)
    with pytest.raises(ClusterError, match="refusing the workers of the test cluster") as e:
        watch.wait_for_first()
    assert reason in str(e.value)
    assert client.retired == ["tcp://bad:1"]
    # beside a good worker, a bad one is only retired
    client, now = FakeClient(), [0.0]
    client.join("tcp://good:1", 1, dict(MINE))
    client.join("tcp://bad:1", 1, answer)
    watch = supervisor(client, now)
    watch.wait_for_first()
    assert list(watch.accepted) == ["tcp://good:1"]
    assert client.retired == ["tcp://bad:1"]


def test_the_last_worker_error_of_the_job_logs(tmp_path):
    assert last_worker_error(tmp_path) is None
    old = tmp_path / "dask-worker-1.err"
    old.write_text("INFO - Start worker\nslurmstepd: error: *** JOB 1 CANCELLED ***\n")
    new = tmp_path / "dask-worker-2.err"
    new.write_text(
        "/usr/bin/python3: Error while finding module specification for "
        "'distributed.cli.dask_worker' (ModuleNotFoundError: No module named "
        "'distributed')\n"
    )
    (tmp_path / "dask-worker-2.out").write_text("")
    t = time.time()
    os.utime(old, (t - 10, t - 10))
    found = last_worker_error(tmp_path)
    assert found is not None
    line, where = found
    assert where == new
    assert "No module named 'distributed'" in line


# --------------------------------------------------------------------------- security
def test_the_local_scheduler_takes_only_clients_with_the_campaign_credentials():
    from distributed import Client, Security

    with open_cluster(ExecutionSpec(workers=1)) as link:
        client = link.client
        assert client is not None
        assert client.scheduler is not None
        address = client.scheduler.address
        assert address is not None
        assert address.startswith("tls://127.0.0.1:")
        assert client.submit(sum, [1, 2]).result(timeout=60) == 3
        assert client.cluster is not None
        http = client.cluster.scheduler.http_server  # dashboard, health, metrics
        assert {s.getsockname()[0] for s in http._sockets.values()} == {"127.0.0.1"}
        with pytest.raises(OSError, match="Connection reset|timed out|Timed out"):
            Client(address.replace("tls://", "tcp://"), timeout=3)  # plain tcp
        with pytest.raises(OSError, match="TLS certificate does not match"):
            Client(address, security=Security.temporary(), timeout=3)  # another CA


def test_tls_can_be_turned_off_only_with_a_reason(tmp_path):
    from nematic_solids.sweep.errors import CampaignError
    from nematic_solids.sweep.spec import parse_campaign

    base = "name: x\nsweep: {axes: {chi: [1]}}\nseeds: 1\n"
    with pytest.raises(
        CampaignError, match="execution.security.tls: turning TLS off needs a stated reason"
    ):
        parse_campaign(base + "execution: {security: {tls: false}}\n")
    c = parse_campaign(
        base + "execution: {workers: 1, security: {tls: false, reason: 'a private network'}}\n"
    )
    assert (c.execution.tls, c.execution.insecure_reason) == (False, "a private network")
    with open_cluster(c.execution) as link:
        client = link.client
        assert client is not None
        assert client.scheduler is not None
        assert str(client.scheduler.address).startswith("tcp://127.0.0.1:")
    with pytest.raises(CampaignError, match="'tcp://' is not encrypted"):
        parse_campaign(base + "execution: {cluster: {kind: slurm, protocol: 'tcp://'}}\n")
    with pytest.raises(CampaignError, match="execution.give_up_after"):
        parse_campaign(base + "execution: {give_up_after: 0}\n")


def test_batch_jobs_get_credentials_only_the_owner_can_read(tmp_path):
    """The jobqueue scheduler: TLS, credential files 0600 in <campaign>/tls (0700) named in
    the job script, dashboard on 127.0.0.1, job logs in <campaign>/jobs. No job submitted."""
    spec = ClusterSpec(
        kind="slurm", jobs=1, options={"cores": 1, "memory": "1GB", "interface": "lo"}
    )
    options, logs = jobqueue_options(spec, ExecutionSpec(cluster=spec), tmp_path)
    assert logs == tmp_path / "jobs"
    assert options["scheduler_options"]["dashboard_address"] == "127.0.0.1:0"
    cluster = make_jobqueue(spec, options)
    try:
        script = cluster.job_script()
        assert cluster.scheduler_address.startswith("tls://")
        folder = tmp_path / "tls"
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700
        files = list(folder.iterdir())
        assert len(files) == 3  # the CA, the worker's certificate and key
        for f in files:
            assert stat.S_IMODE(f.stat().st_mode) == 0o600
            assert str(f) in script
        assert f"--tls-ca-file {folder}" in script
        assert f"#SBATCH -e {tmp_path / 'jobs'}" in script
        http = cluster.scheduler.http_server
        assert {s.getsockname()[0] for s in http._sockets.values()} == {"127.0.0.1"}
    finally:
        cluster.close()


def test_a_tls_scheduler_without_credentials_is_refused(tmp_path):
    """What a stranger on the cluster network gets from the jobqueue scheduler."""
    from distributed import Client, Security

    spec = ClusterSpec(
        kind="slurm", jobs=1, options={"cores": 1, "memory": "1GB", "interface": "lo"}
    )
    options, _ = jobqueue_options(spec, ExecutionSpec(cluster=spec), tmp_path)
    cluster = make_jobqueue(spec, options)
    try:
        address = cluster.scheduler_address
        with pytest.raises(OSError, match="Connection reset|timed out|Timed out"):
            Client(address.replace("tls://", "tcp://"), timeout=3)  # plain tcp
        with pytest.raises(OSError, match="TLS certificate does not match"):
            Client(address, security=Security.temporary(), timeout=3)  # another CA
        with Client(cluster, timeout=10) as client:  # the campaign's own credentials
            assert client.status == "running"
    finally:
        cluster.close()


def test_the_docs_slurm_example_is_a_valid_campaign(tmp_path):
    from test_slurm import docs_slurm_example

    from nematic_solids.sweep.spec import load_campaign

    path = tmp_path / "fig2-slurm.yaml"
    path.write_text(docs_slurm_example())
    c = load_campaign(path)
    assert c.execution.cluster is not None
    assert c.execution.cluster.options["job_script_prologue"] == [
        "source /shared/me/nematic/.venv/bin/activate"
    ]
    assert (c.execution.give_up_after, c.execution.tls) == (300, True)
