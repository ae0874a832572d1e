"""A driver in the background (`nematic run --detach`), seen by `nematic status` and ended
by `nematic stop` (real runs at 32^2 on a local cluster)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from sweep_helpers import group_alive, records, run_ids, wait_for, wait_group_gone, write_campaign
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.lock import read_lock_holder
from nematic_solids.sweep.run.detach import detached_args


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def detach_from_a_shell(path: Path, results: Path, tmp_path: Path) -> tuple[str, int]:
    """`nematic run --detach` from a shell in a session of its own, which then exits; the
    shell's process group is sent SIGHUP, as a terminal that closes does. Returns the
    shell's output and the detached driver's pid."""
    cmd = (
        f"{sys.executable} -m nematic_solids.sweep run {path} --results {results} --no-figures "
        "--detach; echo exit=$?"
    )
    shell = subprocess.Popen(
        ["bash", "-c", cmd],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
        env=dict(os.environ, COLUMNS="300"),
    )
    out, _ = shell.communicate(timeout=240)
    assert "exit=0" in out, out
    with_hup = group_alive(shell.pid)
    if with_hup:  # whatever is left of the shell's session gets the terminal's hangup
        os.killpg(shell.pid, signal.SIGHUP)
    holder = read_lock_holder(results / path.stem / ".lock")
    assert holder is not None, out
    pid = int(holder["pid"])
    assert os.getsid(pid) == pid != shell.pid  # a session of its own
    return out, pid


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_the_command_line_of_the_background_driver():
    assert detached_args(["--debug", "run", "c.yaml", "--detach", "--seeds", "2"]) == [
        "--debug",
        "run",
        "c.yaml",
        "--seeds",
        "2",
    ]


def test_a_detached_driver_outlives_its_shell_and_completes(tmp_path):
    path = write_campaign(
        tmp_path, name="detached", values="[0.1, 0.2]", seeds=2, t_final=2.0, workers=1
    )
    results = tmp_path / "results"
    folder = results / "detached"
    out, pid = detach_from_a_shell(path, results, tmp_path)
    text = " ".join(out.split())
    log = folder / "driver.log"
    assert f"pid {pid}" in text, text
    assert f"tail -f {log}" in text, text
    assert f"nematic status {path}" in text, text
    assert "nematic stop detached" in text, text
    # the shell is gone; the driver goes on
    assert alive(pid)
    status = invoke("status", path, "--results", results)
    assert f"driver running: pid {pid}" in status.output, status.output
    assert f"log: {log}" in " ".join(status.output.split())
    wait_for(lambda: read_lock_holder(folder / ".lock") is None, 300, "the campaign to end")
    recs = records(folder / "runs")
    assert sorted(recs) == sorted(run_ids(path))
    assert all(r["status"] == "ok" for r in recs.values())
    assert (folder / "phase.nc").is_file()
    assert "phase diagram:" in log.read_text()
    status = invoke("status", path, "--results", results)
    assert "driver: none running" in status.output, status.output


def test_stop_ends_the_driver_and_leaves_no_run_half_written(tmp_path):
    path = write_campaign(
        tmp_path,
        name="stopped",
        values="[0.1, 0.12, 0.14, 0.16, 0.18]",
        seeds=2,
        t_final=4.0,
        workers=2,
    )
    results = tmp_path / "results"
    folder = results / "stopped"
    runs = folder / "runs"
    _, pid = detach_from_a_shell(path, results, tmp_path)
    try:
        wait_for(
            lambda: len(list(runs.glob("*.json"))) >= 1 or not alive(pid), 240, "a finished run"
        )
        result = invoke("stop", "stopped", "--results", results)
    finally:
        if read_lock_holder(folder / ".lock") is not None:
            os.killpg(pid, signal.SIGKILL)
    # the driver closed its workers as it stopped; the folder is read once they are gone
    wait_group_gone(pid)
    text = " ".join(result.output.split())
    assert result.exit_code == 0, text
    assert f"stopped the driver of stopped (pid {pid}" in text, text
    assert "the runs not finished stay pending" in text, text
    assert "interrupted after" in text, text  # the driver's last line, from its log
    assert read_lock_holder(folder / ".lock") is None
    # every record whole, every run file named by its record, no temporary file left
    recs = {p.stem: json.loads(p.read_text()) for p in runs.glob("*.json")}
    assert all(r["status"] == "ok" for r in recs.values())
    assert set(recs) <= {p.stem for p in runs.glob("*.nc")}  # (a file without its record
    # is whole too: the next run adopts it)
    assert not list(runs.glob(".*"))
    n = len(run_ids(path))
    status = json.loads(invoke("status", path, "--results", results, "--json").output)
    assert (status["done"], status["failed"], status["pending"]) == (len(recs), 0, n - len(recs))
    assert status["unreadable"] == 0
    assert 1 <= len(recs) < n
    # nothing left to stop: says so, exit 1; by the campaign file too
    again = invoke("stop", path, "--results", results)
    assert again.exit_code == 1, again.output
    assert "no driver is running campaign stopped" in " ".join(again.output.split())


def test_stop_of_an_unknown_campaign_is_one_error_line(tmp_path):
    result = invoke("stop", "nothing-here", "--results", tmp_path)
    assert result.exit_code == 2
    out = " ".join(result.output.split())
    assert out.startswith("error: no results of a campaign named 'nothing-here'"), out
    result = invoke("stop", tmp_path / "missing.yaml", "--results", tmp_path)
    assert result.exit_code == 2
    assert "error: no campaign file" in result.output


def test_detach_on_a_campaign_in_use_is_refused(copy_of_small):
    from nematic_solids.sweep.lock import CampaignLock

    lock = CampaignLock(copy_of_small.results / "small" / ".lock")
    lock.acquire(command="nematic run small.yaml")
    try:
        result = invoke("run", copy_of_small.path, "--results", copy_of_small.results, "--detach")
    finally:
        lock.release()
    assert result.exit_code == 2
    out = " ".join(result.output.split())
    assert f"in use by another driver (pid {os.getpid()}" in out, out
    assert not (copy_of_small.results / "small" / "driver.log").exists()
