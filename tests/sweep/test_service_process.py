"""The service as users run it: a real ``nematic serve`` process. A tiny campaign submitted
with ``nematic submit`` runs to the end (phase.nc, report) and ``nematic run`` hands a campaign
to the service; a second service of the same root is refused; SIGTERM stops it cleanly. A
``kill -9`` of the service in the middle of a campaign, then a restart: the queue is taken up,
the runs continue from their checkpoints, and every run file equals the uninterrupted run's,
bit for bit. Every wait polls the service's state (no fixed sleep is a synchronisation)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
from pathlib import Path

import pytest
from sweep_helpers import kill_group, records, start_driver, wait_for, wait_group_gone
from test_continuation import assert_equal_runs, campaign, straight, tasks_of
from typer.testing import CliRunner

from nematic_solids.model.checkpoint import load
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.service.client import ServiceClient
from nematic_solids.sweep.service.paths import ServicePaths
from nematic_solids.sweep.store import CampaignStore

TINY = """\
name: {name}
description: service test
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: 0.5, save_every: 0.25, mechanics: linear}}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2]
seeds: 2
execution: {{workers: 1}}
"""


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def start_service(root: Path, log: Path) -> subprocess.Popen:
    """``nematic serve ROOT --port 0`` in a session of its own; returns once it answers."""
    proc = start_driver(["serve", str(root), "--port", "0"], log)
    paths = ServicePaths(root)
    wait_for(
        lambda: paths.running() is not None or proc.poll() is not None, 120, "the service to start"
    )
    assert proc.poll() is None, log.read_text()
    return proc


def entry_state(root: Path, entry_id: int) -> dict:
    client = ServiceClient.for_root(root)
    assert client is not None
    return next(e for e in client.queue()["entries"] if e["id"] == entry_id)


def wait_state(root: Path, entry_id: int, states: tuple[str, ...], timeout: float) -> dict:
    wait_for(lambda: entry_state(root, entry_id)["state"] in states, timeout, f"state {states}")
    return entry_state(root, entry_id)


@pytest.mark.slow  # about 40 s: a cluster, a campaign, its phase.nc, fits, figures, report
def test_serve_submit_watch_stop(tmp_path):
    root = tmp_path / "results"
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY.format(name="tiny"))
    proc = start_service(root, tmp_path / "serve.log")
    try:
        info = ServicePaths(root).running()
        assert info is not None
        assert info["url"].startswith("http://127.0.0.1:")
        assert oct(ServicePaths(root).token.stat().st_mode & 0o777) == "0o600"
        # one service per root
        again = invoke("serve", root, "--port", "0")
        assert again.exit_code == 2
        assert "a service already runs" in again.output
        result = invoke("submit", path, "--results", root)
        assert result.exit_code == 0, result.output
        entry_id = int(result.output.split(" as ")[1].split()[0])
        done = wait_state(root, entry_id, ("done", "failed"), 300)
        assert done["state"] == "done", (done, (tmp_path / "serve.log").read_text())
        assert done["message"] == "all runs ok"
        assert done["estimate"]["runs_to_do"] == 4
        recs = records(root / "tiny" / "runs")
        assert len(recs) == 4
        assert all(r["status"] == "ok" for r in recs.values())
        assert (root / "tiny" / "phase.nc").exists()
        assert (root / "tiny" / "report.html").exists()
        # nematic run hands a campaign to the service of its root; its folder is held by
        # another driver (the test), so it waits in the queue, and is cancelled there
        path2 = tmp_path / "tiny2.yaml"
        path2.write_text(TINY.format(name="tiny2"))
        other = CampaignStore(root, "tiny2").lock()
        other.acquire(command="another driver")
        try:
            refused = invoke("run", path2, "--results", root, "--retry-failed")
            assert refused.exit_code == 2
            assert "--no-service" in refused.output
            handed = invoke("run", path2, "--results", root)
            assert handed.exit_code == 0, handed.output
            assert "handed to it" in handed.output
            entry2 = int(handed.output.split(" as ")[1].split()[0])
            wait_for(
                lambda: entry_state(root, entry2)["message"].startswith("waiting"),
                120,
                "the campaign to wait for its folder",
            )
            assert "another driver" in entry_state(root, entry2)["message"]
            listed = json.loads(invoke("queue", "--results", root, "--json", "--all").output)
            assert [e["name"] for e in listed] == ["tiny2", "tiny"]  # queued, then ended
            cancelled = invoke("cancel", entry2, "--results", root)
            assert cancelled.exit_code == 0, cancelled.output
            assert entry_state(root, entry2)["state"] == "cancelled"
            assert invoke("cancel", entry2, "--results", root).exit_code == 2  # it has ended
        finally:
            other.release()
    finally:
        os.kill(proc.pid, signal.SIGTERM)
        try:
            assert proc.wait(timeout=120) == 0, (tmp_path / "serve.log").read_text()
        finally:
            kill_group(proc)
    wait_group_gone(proc.pid)
    assert ServicePaths(root).running() is None
    assert not ServicePaths(root).info.exists()
    assert invoke("queue", "--results", root).exit_code == 2  # no service


@pytest.mark.slow
def test_kill_9_of_the_service_then_restart_loses_nothing(tmp_path):
    path = campaign(tmp_path, "killed", values="[0.2, 0.3]", seeds=1)
    text = path.read_text().replace("workers: 2", "workers: 1")
    path.write_text(text)
    root = tmp_path / "results"
    store, tasks = tasks_of(path, root)
    checkpoints = store.root / "checkpoints"
    proc = start_service(root, tmp_path / "serve.log")
    try:
        result = invoke("submit", path, "--results", root)
        assert result.exit_code == 0, result.output
        entry_id = int(result.output.split(" as ")[1].split()[0])
        wait_for(
            lambda: (
                (checkpoints.exists() and any(checkpoints.glob("*.nc"))) or proc.poll() is not None
            ),
            300,
            "a checkpoint",
            interval=0.01,
        )
        assert proc.poll() is None, (tmp_path / "serve.log").read_text()
    finally:
        os.kill(proc.pid, signal.SIGKILL)  # the service alone; its workers see it go
        proc.wait(timeout=60)
    try:
        wait_group_gone(proc.pid, timeout=120)
    finally:
        kill_group(proc)
    finished_before = set(records(store.runs_dir))
    assert len(finished_before) < len(tasks)
    in_progress = {p.stem: load(p).t for p in checkpoints.glob("*.nc")}
    assert in_progress
    assert ServicePaths(root).running() is None  # the kernel released its lock
    proc = start_service(root, tmp_path / "serve2.log")
    try:
        done = wait_state(root, entry_id, ("done", "failed"), 600)
        assert done["state"] == "done", (done, (tmp_path / "serve2.log").read_text())
        assert done["starts"] == 2
    finally:
        os.kill(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=120)
        finally:
            kill_group(proc)
    recs = records(store.runs_dir)
    assert len(recs) == len(tasks)
    for run_id, t in in_progress.items():  # continued from the checkpoint the kill left
        assert recs[run_id]["lineage"][-1] == f"checkpoint@{t:.12g}"
    for task in tasks:
        assert_equal_runs(straight(task), store.nc_path(task.run_id))
