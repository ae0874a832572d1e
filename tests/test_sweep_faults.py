"""Faults from outside: corrupt run files, records, phase.nc and fits.nc; storage that cannot
be written. Real files of a real (tiny) campaign, real faults (random bytes, a file-size
limit), and every command's output checked for tracebacks."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest
import xarray as xr
from sweep_helpers import records, run_ids, write_campaign
from typer.testing import CliRunner

from sweep.cli import app
from sweep.execute import plan_runs
from sweep.expand import expand
from sweep.spec import load_campaign
from sweep.store import CampaignStore


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


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Two grid points x one seed, run once (every run succeeds)."""
    folder = tmp_path_factory.mktemp("tiny")
    path = write_campaign(folder, name="tiny", values="[0.1, 0.2]", seeds=1, workers=1)
    result = invoke("run", path, "--results", folder / "results", "--no-figures")
    assert result.exit_code == 0, result.output
    return SimpleNamespace(path=path, results=folder / "results", ids=run_ids(path))


@pytest.fixture
def copy(tiny, tmp_path):
    shutil.copytree(tiny.results, tmp_path / "results")
    path = Path(shutil.copy(tiny.path, tmp_path / "tiny.yaml"))
    return SimpleNamespace(path=path, results=tmp_path / "results",
                           runs=tmp_path / "results" / "tiny" / "runs", ids=tiny.ids,
                           phase=tmp_path / "results" / "tiny" / "phase.nc")


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
    a number: `status` counts both as pending, `run` names them, redoes them and exits 0;
    afterwards every file opens."""
    first, second = copy.ids
    scramble(copy.runs / f"{first}.nc")
    rec = json.loads((copy.runs / f"{second}.json").read_text())
    rec["nc_bytes"] = "many"
    (copy.runs / f"{second}.json").write_text(json.dumps(rec))
    assert status_counts(copy) == (0, 0, 2)
    res = invoke("run", copy.path, "--results", copy.results, "--no-figures")
    out = " ".join(res.output.split())
    assert res.exit_code == 0, res.output
    assert_no_traceback(res.output)
    assert "2 run(s) will be redone" in out
    assert f"{first}: its file is corrupt" in out
    assert f"{second}: its record is malformed (nc_bytes = 'many')" in out
    assert "0 done, 0 failed, 2 to run" in out
    for rid in copy.ids:
        with xr.open_dataset(copy.runs / f"{rid}.nc") as ds:
            assert ds.attrs["run_id"] == rid
            assert float(ds["sigma2_S_final"]) > 0
    with xr.open_dataset(copy.phase) as ds:
        assert ds.attrs["n_ok"] == 2
    assert status_counts(copy) == (2, 0, 0)


def test_verify_finds_corruption_that_kept_the_mtime(copy):
    """A file changed in place with its mtime put back looks untouched to the cheap check;
    `run --verify` (checksums every file) finds it. status and plan agree on both."""
    rid = copy.ids[0]
    nc = copy.runs / f"{rid}.nc"
    st = nc.stat()
    scramble(nc, 512, offset=st.st_size // 2)
    os.utime(nc, ns=(st.st_atime_ns, st.st_mtime_ns))
    store = CampaignStore(copy.results, "tiny")
    expansion = expand(load_campaign(copy.path))
    assert status_counts(copy) == (2, 0, 0)
    plan = plan_runs(expansion, store)
    assert (len(plan.done), len(plan.todo)) == (2, 0)
    plan = plan_runs(expansion, store, verify=True)
    assert (len(plan.done), len(plan.todo)) == (1, 1)
    assert plan.redone == [(rid, "its file is corrupt (its content is not the one checksummed "
                                 "when it was written)")]
    assert not nc.exists()  # discarded, to be redone
    assert status_counts(copy) == (1, 0, 1)


def test_a_copied_folder_is_still_done_and_its_stamps_refreshed(copy):
    """Copying a results folder without keeping mtimes (cp -r) changes nothing that matters:
    the checksums match, the runs stay done, and the records learn the new mtimes."""
    for nc in copy.runs.glob("*.nc"):
        os.utime(nc, ns=(1, 10**18))
    store = CampaignStore(copy.results, "tiny")
    plan = plan_runs(expand(load_campaign(copy.path)), store)
    assert (len(plan.done), len(plan.todo), plan.redone) == (2, 0, [])
    assert all(rec["nc_mtime_ns"] == 10**18 for rec in records(copy.runs).values())


def test_a_legacy_write_error_record_is_redone_by_default(copy):
    """Records of results that could not be stored (reason write_error, written by older
    versions) are not model failures: pending in status, redone by a plain run."""
    rid = copy.ids[0]
    rec = json.loads((copy.runs / f"{rid}.json").read_text())
    rec.update(status="failed", reason="write_error", nc_bytes=None,
               detail="RuntimeError: NetCDF: HDF error")
    (copy.runs / f"{rid}.json").write_text(json.dumps(rec))
    (copy.runs / f"{rid}.nc").unlink()
    assert status_counts(copy) == (1, 0, 1)
    plan = plan_runs(expand(load_campaign(copy.path)), CampaignStore(copy.results, "tiny"))
    assert (len(plan.done), len(plan.todo), len(plan.failed)) == (1, 1, 0)


def test_corrupt_phase_and_fits_are_rebuilt_with_a_message(copy):
    assert invoke("figures", copy.path, "--results", copy.results).exit_code == 0
    fits = copy.phase.parent / "fits.nc"
    assert fits.exists()
    scramble(copy.phase, 2048)
    scramble(fits, 2048)
    res = invoke("figures", copy.path, "--results", copy.results, "--no-fits")
    assert_no_traceback(res.output)
    assert res.exit_code == 0, res.output
    out = " ".join(res.output.split())
    assert "phase.nc: unreadable" in out
    assert "rebuilding it from the run records" in out
    assert "fits.nc: unreadable" in out
    assert "recomputing the fits despite --no-fits" in out
    with xr.open_dataset(copy.phase) as ds:
        assert ds.attrs["n_ok"] == 2
    with xr.open_dataset(fits) as ds:
        assert ds.attrs
    assert (copy.phase.parent / "figures" / "fig2.png").exists()
