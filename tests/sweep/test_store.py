"""The results folder: atomic writes, the lock, the records and their manifest cache."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import xarray as xr

from nematic_solids.sweep.errors import CampaignLocked
from nematic_solids.sweep.files import (
    atomic_to_netcdf,
    atomic_write_text,
    file_stamp,
    netcdf_attr,
    series_time,
)
from nematic_solids.sweep.lock import CampaignLock, read_lock_holder
from nematic_solids.sweep.store import CampaignStore


def test_series_time_reads_both_run_file_schemas():
    """Run files name their time axis t; files of schema 1 called it time."""
    current = xr.Dataset({"sigma2_S": ("t", [0.0, 0.1])}, coords={"t": [0.0, 2.0]})
    schema_1 = xr.Dataset({"sigma2_S": ("time", [0.0, 0.1])}, coords={"time": [0.0, 3.0]})
    assert series_time(current).values.tolist() == [0.0, 2.0]
    assert series_time(schema_1).values.tolist() == [0.0, 3.0]
    with pytest.raises(KeyError):
        series_time(xr.Dataset({"sigma2_S": ("s", [0.0])}))


def dataset() -> xr.Dataset:
    return xr.Dataset(
        {"field": (("x", "y"), np.arange(12.0).reshape(3, 4)), "scalar": ((), 1.5)},
        coords={"x": [0.0, 0.5, 1.0]},
        attrs={
            "flag": True,
            "nothing": None,
            "times": [1.0, 2.0],
            "empty": [],
            "mapping": {"a": 1},
            "text": "x",
        },
    )


def test_atomic_netcdf_round_trip(tmp_path):
    path = tmp_path / "a.nc"
    size = atomic_to_netcdf(dataset(), path, {"field": {"zlib": True}})
    assert size == path.stat().st_size
    assert [p.name for p in tmp_path.iterdir()] == ["a.nc"]  # no temporary left
    with xr.open_dataset(path) as back:
        np.testing.assert_array_equal(back["field"].values, dataset()["field"].values)
        assert back.attrs["flag"] == 1
        assert back.attrs["nothing"] == ""
        np.testing.assert_array_equal(back.attrs["times"], [1.0, 2.0])
        assert json.loads(back.attrs["mapping"]) == {"a": 1}


def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "a.nc"
    atomic_to_netcdf(dataset(), path)
    before = path.read_bytes()
    with pytest.raises(ValueError, match="unexpected encoding"):
        atomic_to_netcdf(dataset(), path, {"field": {"not_an_option": 1}})
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["a.nc"]


def test_netcdf_attr():
    assert netcdf_attr(True) == 1
    assert netcdf_attr(None) == ""
    assert netcdf_attr(()) == ""
    assert netcdf_attr(["a", "b"]) == '["a", "b"]'
    assert netcdf_attr(3.5) == 3.5


def test_lock_excludes_a_second_holder(tmp_path):
    path = tmp_path / "c" / ".lock"
    first = CampaignLock(path)
    first.acquire(command="nematic run c.yaml")
    try:
        holder = read_lock_holder(path)
        assert holder is not None
        assert holder["pid"] == os.getpid()
        assert holder["command"] == "nematic run c.yaml"
        with pytest.raises(CampaignLocked, match=f"pid {os.getpid()}"):
            CampaignLock(path).acquire()
    finally:
        first.release()
    assert read_lock_holder(path) is None
    with CampaignLock(path):
        assert read_lock_holder(path) is not None


def test_a_killed_holder_releases_the_lock(tmp_path):
    path = tmp_path / ".lock"
    code = (
        "import sys, time; from nematic_solids.sweep.lock import CampaignLock; "
        f"CampaignLock(__import__('pathlib').Path({str(path)!r})).acquire(); "
        "print('locked', flush=True); time.sleep(60)"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == b"locked"
        holder = read_lock_holder(path)
        assert holder is not None
        assert holder["pid"] == proc.pid
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        proc.kill()
    assert read_lock_holder(path) is None
    CampaignLock(path).acquire()  # and it can be taken again


def record(rid: str, status: str = "ok", nc_bytes: int | None = 10) -> dict:
    return {
        "run_id": rid,
        "status": status,
        "reason": "" if status == "ok" else "nan",
        "detail": "",
        "t_failed": None,
        "traceback": "",
        "seed": 0,
        "wall_time": 1.0,
        "nc_bytes": nc_bytes,
        "scalars": {"sigma2_S_final": 0.5},
        "code_version": "v",
        "git_commit": "c",
        "finished": "2026-01-01T00:00:00+00:00",
    }


def test_scan_caches_records_and_sees_changes(tmp_path):
    store = CampaignStore(tmp_path, "c")
    store.ensure()
    for rid in ("a", "b"):
        store.write_record(record(rid))
        (store.runs_dir / f"{rid}.nc").write_bytes(b"x" * 10)
    recs = store.scan()
    assert set(recs) == {"a", "b"}
    assert recs["a"]["scalars"] == {"sigma2_S_final": 0.5}
    assert store.manifest_path.exists()
    assert store.load_manifest()["b"]["status"] == "ok"
    # a record rewritten (a retried run) is read again, not taken from the cache
    time.sleep(0.01)
    store.write_record(record("a", status="failed"))
    assert store.scan()["a"]["status"] == "failed"
    # a deleted record disappears
    store.discard("b")
    assert set(store.scan()) == {"a"}
    # a corrupt or foreign manifest is ignored
    atomic_write_text(store.manifest_path, "{not json")
    assert set(store.scan()) == {"a"}


def test_is_complete_checks_the_file(tmp_path):
    store = CampaignStore(tmp_path, "c")
    store.ensure()
    path = store.runs_dir / "a.nc"
    atomic_to_netcdf(dataset().rename(field="sigma2_S").assign_coords(t=[0.0]), path)
    rec = {**record("a"), **file_stamp(path)}
    store.write_record(rec)
    assert store.is_complete("a", store.read_record("a"))
    content = path.read_bytes()
    path.write_bytes(content[:100])
    assert "truncated" in str(store.check_run_file("a", rec))
    path.unlink()
    assert "missing" in str(store.check_run_file("a", rec))
    # same size, other bytes: the mtime changed, so the checksum is compared
    path.write_bytes(b"\0" * 4096 + content[4096:])
    assert "corrupt" in str(store.check_run_file("a", rec))
    # ... even when the mtime is put back, on --check-files
    os.utime(path, ns=(rec["nc_mtime_ns"], rec["nc_mtime_ns"]))
    assert store.check_run_file("a", rec) is None
    assert "corrupt" in str(store.check_run_file("a", rec, check_files=True))
    # intact content with a new mtime (a copy): accepted, and the record refreshed
    path.write_bytes(content)
    assert store.check_run_file("a", rec) is None
    store.refresh_stamp("a")
    assert (store.read_record("a") or {}).get("nc_mtime_ns") == path.stat().st_mtime_ns
    # a record without a checksum (older records): the file must open and hold the run
    legacy = {k: v for k, v in rec.items() if k not in ("nc_sha256", "nc_mtime_ns")}
    assert store.check_run_file("a", legacy) is None
    path.write_bytes(b"\0" * 4096 + content[4096:])
    assert "unreadable" in str(store.check_run_file("a", legacy))
    for bad in ("abc", "10", -1, 1.5, True, [10]):
        assert "malformed" in str(store.check_run_file("a", {**rec, "nc_bytes": bad}))
    crashed = record("b", status="failed", nc_bytes=None)  # raised: the record is all
    assert store.is_complete("b", crashed)
    assert not store.is_complete("c", None)


def test_unreadable_records_are_no_records(tmp_path):
    store = CampaignStore(tmp_path, "c")
    store.ensure()
    for text in ("{not json", "[1, 2]", "3", "null", "\udcff"):
        store.record_path("a").write_text(text, errors="surrogateescape")
        assert store.read_record("a") is None
        assert store.scan() == {}


def test_adopt_rejects_unreadable_files(tmp_path):
    store = CampaignStore(tmp_path, "c")
    store.ensure()
    (store.runs_dir / "a.nc").write_bytes(b"CDF\x01garbage")
    assert store.adopt("a") is None
    assert not (store.runs_dir / "a.nc").exists()
    atomic_to_netcdf(dataset().assign_attrs(run_id="other"), store.runs_dir / "b.nc")
    assert store.adopt("b") is None  # a file that names another run is not this run


def test_clean_temporaries(tmp_path):
    store = CampaignStore(tmp_path, "c")
    store.ensure()
    old = store.runs_dir / ".a.nc.123.tmp"
    old.write_text("")
    os.utime(old, (time.time() - 3600, time.time() - 3600))
    young = store.runs_dir / ".b.nc.456.tmp"
    young.write_text("")
    assert store.clean_temporaries(min_age=600) == 1
    assert young.exists()
    assert not old.exists()
    assert store.clean_temporaries() == 1


def test_storage_cause_names_the_fault(tmp_path):
    import errno
    import resource

    from nematic_solids.sweep.files import storage_cause

    target = tmp_path / "runs" / "a.nc"
    target.parent.mkdir()
    assert storage_cause(target, OSError(errno.ENOSPC, "x")) == "the disk is full"
    assert storage_cause(target, OSError(errno.EROFS, "x")) == "the filesystem is read-only"
    assert storage_cause(target, OSError(errno.EDQUOT, "x")) == "the disk quota is exceeded"
    efbig = storage_cause(target, OSError(errno.EFBIG, "x"))
    assert efbig.startswith("the file size limit was reached")
    if resource.getrlimit(resource.RLIMIT_FSIZE)[0] == resource.RLIM_INFINITY:
        # netCDF's "HDF error" says nothing: the folder is asked (writable here: the error)
        assert (
            storage_cause(target, RuntimeError("NetCDF: HDF error"))
            == "RuntimeError: NetCDF: HDF error"
        )
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert "is a file" in storage_cause(blocker / "x.nc", OSError(errno.EACCES, "x"))
    gone = tmp_path / "deleted" / "runs" / "a.nc"
    assert "does not exist (deleted?)" in storage_cause(gone, OSError(errno.EACCES, "x"))
