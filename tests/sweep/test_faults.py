"""Faults from outside: corrupt run files, records, phase.nc and fits.nc; storage that cannot
be written; a scheduler without workers. Real files of a real small campaign (conftest.py),
real faults (random bytes, a file-size limit, a full tmpfs, a read-only bind mount), and the
output of the commands checked for tracebacks."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr
from sweep_helpers import records, write_campaign
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.run.detach import child_command
from nematic_solids.sweep.run.todo import plan_runs
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.store import CampaignStore


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def scramble(path: Path, nbytes: int = 4096, offset: int = 0) -> None:
    """Overwrite ``nbytes`` of ``path`` at ``offset`` with random bytes (same size)."""
    fd = os.open(path, os.O_WRONLY)
    try:
        os.pwrite(fd, os.urandom(nbytes), offset)
    finally:
        os.close(fd)


def assert_no_traceback(text: str) -> None:
    assert "Traceback" not in text, text
    assert 'File "' not in text, text


@pytest.fixture
def copy(copy_of_small):
    """A private copy of the small campaign's results (conftest.py: 3 alpha - B values x 2
    seeds, the 2 runs at alpha - B = 20 failed); ``ok``: the runs that succeeded."""
    recs = records(copy_of_small.runs)
    copy_of_small.ok = [r for r in copy_of_small.ids if recs[r]["status"] == "ok"]
    return copy_of_small


def status_counts(copy) -> tuple[int, int, int]:
    res = invoke("status", copy.path, "--results", copy.results, "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    return data["done"], data["failed"], data["pending"]


def test_records_carry_the_checksum_of_their_file(copy):
    import hashlib

    for rid, rec in records(copy.runs).items():
        nc = copy.runs / f"{rid}.nc"
        assert rec["nc_sha256"] == hashlib.sha256(nc.read_bytes()).hexdigest()
        assert rec["nc_mtime_ns"] == nc.stat().st_mtime_ns


def test_a_corrupt_run_file_is_reported_and_redone(copy):
    """Random bytes at the start of a run file (same size) and a record whose nc_bytes is not
    a number: `status` counts both as pending, `run` names them and redoes them; afterwards
    every file opens and phase.nc counts them."""
    first, second = copy.ok[:2]
    scramble(copy.runs / f"{first}.nc")
    rec = json.loads((copy.runs / f"{second}.json").read_text())
    rec["nc_bytes"] = "many"
    (copy.runs / f"{second}.json").write_text(json.dumps(rec))
    assert status_counts(copy) == (2, 2, 2)
    shown = " ".join(invoke("status", copy.path, "--results", copy.results).output.split())
    assert "2 run(s) pending because their file is missing, truncated or corrupt" in shown
    assert f"{first}: its file is corrupt" in shown
    res = invoke("run", copy.path, "--results", copy.results, "--no-figures", "--workers", "1")
    out = " ".join(res.output.split())
    assert res.exit_code == 1, res.output  # the two earlier model failures stay failures
    assert_no_traceback(res.output)
    assert "2 run(s) will be redone" in out
    assert f"{first}: its file is corrupt" in out
    assert f"{second}: its record is malformed (nc_bytes = 'many')" in out
    assert "2 done, 2 failed (skipped; --retry-failed redoes them), 2 to run" in out
    for rid in copy.ok:
        with xr.open_dataset(copy.runs / f"{rid}.nc") as ds:
            assert ds.attrs["run_id"] == rid
            assert float(ds["sigma2_S_final"]) > 0
    with xr.open_dataset(copy.phase) as ds:
        assert (ds.attrs["n_ok"], ds.attrs["n_failed"]) == (4, 2)
    assert status_counts(copy) == (4, 2, 0)


def test_verify_finds_corruption_that_kept_the_mtime(copy):
    """A file changed in place with its mtime put back looks untouched to the cheap check;
    `run --check-files` (checksums every file) finds it. status and plan agree on both."""
    rid = copy.ok[0]
    nc = copy.runs / f"{rid}.nc"
    st = nc.stat()
    scramble(nc, 512, offset=st.st_size // 2)
    os.utime(nc, ns=(st.st_atime_ns, st.st_mtime_ns))
    store = CampaignStore(copy.results, "small")
    expansion = expand(load_campaign(copy.path))
    assert status_counts(copy) == (4, 2, 0)
    plan = plan_runs(expansion, store)
    assert (len(plan.done), len(plan.failed), len(plan.todo)) == (4, 2, 0)
    plan = plan_runs(expansion, store, check_files=True)
    assert (len(plan.done), len(plan.failed), len(plan.todo)) == (3, 2, 1)
    assert plan.redone == [
        (rid, "its file is corrupt (its content is not the one checksummed when it was written)")
    ]
    assert not nc.exists()  # discarded, to be redone
    assert status_counts(copy) == (3, 2, 1)


def test_a_copied_folder_is_still_done_and_its_stamps_refreshed(copy):
    """Copying a results folder without keeping mtimes (cp -r) changes nothing that matters:
    the checksums match, the runs stay done, and the records learn the new mtimes."""
    for nc in copy.runs.glob("*.nc"):
        os.utime(nc, ns=(1, 10**18))
    store = CampaignStore(copy.results, "small")
    plan = plan_runs(expand(load_campaign(copy.path)), store)
    assert (len(plan.done), len(plan.failed), len(plan.todo), plan.redone) == (4, 2, 0, [])
    assert all(rec["nc_mtime_ns"] == 10**18 for rec in records(copy.runs).values())


def test_a_legacy_write_error_record_is_redone_by_default(copy):
    """Records of results that could not be stored (reason write_error, written by older
    versions) are not model failures: pending in status, redone by a plain run."""
    rid = copy.ok[0]
    rec = json.loads((copy.runs / f"{rid}.json").read_text())
    rec.update(
        status="failed",
        reason="write_error",
        nc_bytes=None,
        detail="RuntimeError: NetCDF: HDF error",
    )
    (copy.runs / f"{rid}.json").write_text(json.dumps(rec))
    (copy.runs / f"{rid}.nc").unlink()
    assert status_counts(copy) == (3, 2, 1)
    plan = plan_runs(expand(load_campaign(copy.path)), CampaignStore(copy.results, "small"))
    assert (len(plan.done), len(plan.todo), len(plan.failed)) == (3, 1, 2)


def test_corrupt_phase_and_fits_are_rebuilt_with_a_message(copy):
    fits = copy.phase.parent / "fits.nc"
    scramble(copy.phase, 2048)
    fits.write_bytes(os.urandom(8192))
    res = invoke("figures", copy.path, "--results", copy.results, "--no-fits")
    assert_no_traceback(res.output)
    assert res.exit_code == 0, res.output
    out = " ".join(res.output.split())
    assert "phase.nc: unreadable" in out
    assert "rebuilding it from the run records" in out
    assert "fits.nc: unreadable" in out
    assert "recomputing the fits despite --no-fits" in out
    with xr.open_dataset(copy.phase) as ds:
        assert (ds.attrs["n_ok"], ds.attrs["n_failed"]) == (4, 2)
    with xr.open_dataset(fits) as ds:
        assert ds.attrs
    assert (copy.phase.parent / "figures" / "fig2.png").exists()


# --------------------------------------------------------------------------- storage faults
def nematic(
    args: list[object],
    *,
    fsize: int | None = None,
    env: dict | None = None,
    wrap: list[str] | None = None,
    timeout: float = 300,
) -> subprocess.CompletedProcess:
    """``nematic ARGS`` in a subprocess, optionally under a file-size limit (SIGXFSZ ignored,
    as Python does: writes past the limit fail with EFBIG) or inside ``wrap`` (unshare)."""

    limit = ["signal.signal(signal.SIGXFSZ, signal.SIG_IGN)"]
    if fsize is not None:
        limit.append(f"resource.setrlimit(resource.RLIMIT_FSIZE, ({fsize}, {fsize}))")
    cmd = [*(wrap or []), *child_command(*limit), *map(str, args)]
    return subprocess.run(
        cmd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "COLUMNS": "200", **(env or {})},
    )


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_a_file_size_limit_keeps_runs_pending_and_a_rerun_completes(copy, tmp_path):
    """Results that cannot be written (ulimit -f) are not model failures: the driver stops at
    the first one with one message naming the path and the cause, exit 2, no record; status
    says pending; a plain rerun once the limit is gone completes the campaign."""
    path, results = copy.path, copy.results
    victim = copy.ok[0]
    (copy.runs / f"{victim}.json").unlink()
    (copy.runs / f"{victim}.nc").unlink()
    spool = tmp_path / "spool"
    env = {"NEMATIC_SPOOL": str(spool)}
    proc = nematic(
        ["run", path, "--results", results, "--no-figures", "--workers", "1"],
        fsize=64 * 1024,
        env=env,
    )
    out = " ".join((proc.stdout + proc.stderr).split())
    assert proc.returncode == 2, out
    assert_no_traceback(proc.stdout + proc.stderr)
    assert "error: results cannot be written: cannot write" in out
    assert "the file size limit was reached (ulimit -f: 65536 bytes)" in out
    assert "stay pending (not failed)" in out
    assert out.count("error:") == 1
    assert "it could not be kept elsewhere either" not in out  # the message is short
    runs = copy.runs
    assert victim not in records(runs)  # nothing recorded as failed
    assert not list(spool.glob("*/*.nc"))  # the limit applies there too
    assert status_counts(copy) == (3, 2, 1)
    proc = nematic(["run", path, "--results", results, "--no-figures", "--workers", "1"], env=env)
    assert proc.returncode == 1, proc.stderr  # the earlier model failures only
    assert "3 done, 2 failed (skipped; --retry-failed redoes them), 1 to run" in " ".join(
        proc.stderr.split()
    )
    assert records(runs)[victim]["status"] == "ok"
    assert status_counts(copy) == (4, 2, 0)


def _can_mount() -> bool:
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    probe = subprocess.run(
        ["unshare", "-m", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"], capture_output=True
    )
    return probe.returncode == 0


needs_mount = pytest.mark.skipif(not _can_mount(), reason="needs root and mount (unshare -m)")


@pytest.mark.slow
@needs_mount
def test_a_full_disk_keeps_the_result_elsewhere_and_a_rerun_moves_it_in(small, tmp_path):
    """A real full disk (a 100 kB tmpfs): the computed result goes to the spool and the message
    says where; after the disk is enlarged, a plain rerun moves it in without recomputing."""
    disk = tmp_path / "disk"
    disk.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=100k", "tmpfs", str(disk)], check=True)
    try:
        path = Path(shutil.copy(small.path, tmp_path / "small.yaml"))
        results, spool = disk / "results", tmp_path / "spool"
        env = {"NEMATIC_SPOOL": str(spool)}
        proc = nematic(["run", path, "--results", results, "--no-figures"], env=env)
        out = " ".join((proc.stdout + proc.stderr).split())
        assert proc.returncode == 2, out
        assert_no_traceback(proc.stdout + proc.stderr)
        assert "the disk is full" in out
        assert f"computed result(s) kept in {spool}" in out
        kept = list(spool.glob("*/*.nc"))
        assert kept
        subprocess.run(["mount", "-o", "remount,size=20m", str(disk)], check=True)
        proc = nematic(["run", path, "--results", results, "--no-figures"], env=env)
        out = " ".join((proc.stdout + proc.stderr).split())
        assert proc.returncode == 1, out  # the model failures at alpha - B = 20
        assert f"moved {len(kept)} result(s) that could not be written before" in out
        assert not list(spool.glob("*/*.nc"))
        recs = records(results / "small" / "runs")
        assert len(recs) == 6
        assert sum(r["status"] == "ok" for r in recs.values()) == 4
        for nc in kept:
            with xr.open_dataset(results / "small" / "runs" / nc.name) as ds:
                assert ds.attrs["run_id"] == nc.stem
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)


@needs_mount
def test_a_read_only_results_folder_gives_one_message_per_command(copy):
    """run, aggregate and figures on a read-only bind mount: exit 2, the cause named, no
    traceback."""
    root = copy.results
    wrap = [
        "unshare",
        "-m",
        "sh",
        "-c",
        f'mount --bind {root} {root} && mount -o remount,bind,ro {root} && exec "$@"',
        "sh",
    ]
    for command in ("run", "aggregate", "figures"):
        proc = nematic([command, copy.path, "--results", root], wrap=wrap)
        text = proc.stdout + proc.stderr
        assert_no_traceback(text)
        assert proc.returncode == 2, (command, text)
        assert "the filesystem is read-only" in " ".join(text.split()), (command, text)
        assert text.count("error:") == 1, text


def test_a_result_that_cannot_be_written_is_kept_and_moved_in(tmp_path, monkeypatch):
    """The worker task itself: a results folder that cannot take the file (its runs folder
    is a regular file here) gives a record with status 'unsaved' and no record file; the
    result is in the spool, and the next plan moves it in and adopts it."""
    import nematic_solids.model.simulate
    from nematic_solids.sweep.run.task import RunTask, execute_run, spool_dir
    from nematic_solids.sweep.run.todo import import_spool

    def fake_run(params, numerics, seed, **kw):  # the storage is under test, not the model
        ds = xr.Dataset(
            {"sigma2_S": ("t", [0.0, 0.1]), "sigma2_S_final": ((), 0.1)},
            coords={"t": [0.0, 1.0]},
            attrs={"status": "ok", "seed": seed},
        )
        return (ds, None) if kw.get("keep_state") else ds

    monkeypatch.setattr(nematic_solids.model.simulate, "run", fake_run)
    monkeypatch.setenv("NEMATIC_SPOOL", str(tmp_path / "spool"))
    store = CampaignStore(tmp_path / "results", "c")
    store.root.mkdir(parents=True)
    store.runs_dir.write_text("not a folder")
    task = RunTask(
        run_id="0123456789abcdef",
        seed=0,
        parameters={"noise_modes": 6},
        numerics={"resolution": 32, "t_final": 1.0, "mechanics": "linear"},
        runs_dir=str(store.runs_dir),
        campaign="c",
    )
    rec = execute_run(task)
    assert rec["status"] == "unsaved"
    assert "a part of the path is not a folder" in rec["storage_error"]
    kept = spool_dir(store.runs_dir) / "0123456789abcdef.nc"
    assert rec["saved_to"] == str(kept)
    assert kept.exists()
    store.runs_dir.unlink()
    store.ensure()
    assert import_spool(store) == 1
    assert not kept.exists()
    adopted = store.adopt("0123456789abcdef")
    assert adopted is not None
    assert adopted["status"] == "ok"


# --------------------------------------------------------------------------- no workers
def test_a_scheduler_without_workers_gives_up_with_a_message(tmp_path):
    """An external scheduler that no worker ever joins: after execution.wait_for_workers
    seconds (with a line while waiting), exit 2 saying what to start; nothing recorded."""
    from sweep_helpers import kill_group, wait_for

    sched_file = tmp_path / "scheduler.json"
    with open(tmp_path / "scheduler.log", "wb") as log:
        scheduler = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "dask",
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(sched_file),
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    try:
        wait_for(sched_file.exists, 60, "the dask scheduler")
        address = json.loads(sched_file.read_text())["address"]
        path = write_campaign(tmp_path, name="lonely", values="[0.1]", seeds=1, workers=1)
        path.write_text(
            path.read_text().replace("execution: {workers: 1}", "execution: {wait_for_workers: 3}")
        )
        proc = nematic(
            ["run", path, "--results", tmp_path / "results", "--scheduler", address], timeout=120
        )
    finally:
        kill_group(scheduler)
    text = proc.stdout + proc.stderr
    assert_no_traceback(text)
    assert proc.returncode == 2, text
    out = " ".join(text.split())
    assert "waiting for a dask worker to join the dask scheduler at" in out
    assert f"no dask worker joined the dask scheduler at {address} within 3 s" in out
    assert f"dask worker {address} --nthreads 1" in out
    assert not list((tmp_path / "results" / "lonely" / "runs").glob("*.json"))


def test_no_command_answers_the_fault_matrix_with_a_traceback(copy):
    """Every read-side fault at once (random bytes in phase.nc, fits.nc and a run file; a
    manifest and a record that are not JSON; a record that is a list; a record whose nc_bytes
    is a string): validate, status, aggregate and figures each answer with an exit code and
    messages, and agree on what is done."""
    ok = copy.ok
    scramble(copy.phase, 2048)
    (copy.phase.parent / "fits.nc").write_bytes(os.urandom(4096))
    scramble(copy.runs / f"{ok[0]}.nc")
    (copy.phase.parent / "manifest.json").write_text("{garbage")
    (copy.runs / f"{ok[1]}.json").write_text("[1, 2, 3]")
    (copy.runs / f"{ok[2]}.json").write_text("{not json")
    rec = json.loads((copy.runs / f"{ok[3]}.json").read_text())
    (copy.runs / f"{ok[3]}.json").write_text(json.dumps({**rec, "nc_bytes": "12"}))
    for args in (["validate"], ["status"], ["status", "--json"], ["aggregate"], ["figures"]):
        res = invoke(*args[:1], copy.path, *args[1:], "--results", copy.results)
        assert res.exit_code in (0, 1, 2), (args, res.output)
        assert isinstance(res.exception, SystemExit | type(None)), (args, repr(res.exception))
        assert_no_traceback(res.output)
    # the records that cannot be read leave their (intact) files to be adopted by the driver;
    # the corrupt file and the malformed record are pending for status and aggregate alike
    done, failed, pending = status_counts(copy)
    assert (done, failed, pending) == (0, 2, 4)
    with xr.open_dataset(copy.phase) as ds:
        assert (ds.attrs["n_ok"], ds.attrs["n_failed"], ds.attrs["n_missing"]) == (0, 2, 4)
