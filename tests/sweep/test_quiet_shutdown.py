"""A campaign that succeeds prints no traceback, on a loaded machine too: a real small
campaign on a local cluster, as a separate ``nematic run`` process, while busy processes
keep every core loaded; its output (stdout and stderr) holds no traceback and no line of
distributed's heartbeat failures (``sweep/run/clusters.py``: the local cluster's shutdown).
The filter that drops that one message in the workers as the cluster closes, in real worker
processes: that message goes, every other stays."""

from __future__ import annotations

import logging
import os
import subprocess
import sys

from sweep_helpers import records, run_ids, write_campaign

#: Busy processes: one per core (at least 2), for the whole campaign.
LOAD = max(2, len(os.sched_getaffinity(0)))


def test_a_campaign_that_succeeds_under_load_prints_no_traceback(tmp_path):
    path = write_campaign(tmp_path, name="loaded", values="[0.1, 0.2]", seeds=2, t_final=1.0)
    results = tmp_path / "results"
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(LOAD)]
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
            ]
            + ["--no-figures", "--no-dashboard"],
            capture_output=True,
            text=True,
            timeout=300,
            env=dict(os.environ, COLUMNS="200"),
        )
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    recs = records(results / "loaded" / "runs")
    assert sorted(recs) == sorted(run_ids(path))
    assert all(r["status"] == "ok" for r in recs.values())
    assert "Traceback" not in out, out
    assert not [line for line in out.splitlines() if "heartbeat" in line.lower()], out


def test_the_closing_workers_drop_the_heartbeat_failure_and_nothing_else(capfd):
    from distributed import Client, LocalCluster

    from nematic_solids.sweep.run.clusters import HEARTBEAT_FAILURE, quiet_heartbeats

    say = logging.getLogger("distributed.worker").error  # in the worker processes
    cluster = LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        scheduler_kwargs={"dashboard": False},
        silence_logs=logging.ERROR,
    )
    with cluster, Client(cluster) as client:
        client.run(say, f"{HEARTBEAT_FAILURE}. (before)")
        quiet_heartbeats(client)
        client.run(say, f"{HEARTBEAT_FAILURE}. (after)")
        client.run(say, "another error of the worker (after)")
    err = capfd.readouterr().err
    assert f"{HEARTBEAT_FAILURE}. (before)" in err  # what the workers print otherwise
    assert f"{HEARTBEAT_FAILURE}. (after)" not in err
    assert "another error of the worker (after)" in err
