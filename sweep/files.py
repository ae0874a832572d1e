"""Files written so that a file that exists is complete: written to a temporary name in the
same folder and renamed into place (``os.replace`` is atomic on POSIX). Also why a file or
folder cannot be written (disk full, read-only, quota, ...), said in words, and the checks
of a file that was written (size, checksum, a netCDF that opens)."""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import hashlib
import json
import os
import uuid
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import StorageError

if TYPE_CHECKING:
    import xarray as xr

TMP_SUFFIX = ".tmp"


# --------------------------------------------------------------------------- atomic writes
def temporary_path(path: Path) -> Path:
    """A unique hidden name next to ``path`` (same filesystem, so the rename is atomic)."""
    return path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}{TMP_SUFFIX}")


def fsync_dir(directory: Path) -> None:
    """Make the renames into ``directory`` durable (an error is ignored: not every filesystem
    syncs a folder)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


#: errno -> what it means for a results folder.
_CAUSES = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.EROFS: "the filesystem is read-only",
    errno.EFBIG: "the file size limit was reached",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.ENOENT: "the folder does not exist",
    errno.ENOTDIR: "a part of the path is not a folder",
    errno.EIO: "an input/output error of the storage",
}
#: Free space below which a failed write is put down to a full disk (bytes).
NEARLY_FULL = 1 << 20


def probe_write(folder: Path) -> OSError | None:
    """Write (and remove) a small file in ``folder``; the error, or ``None`` if it works."""
    probe = folder / f".probe.{uuid.uuid4().hex[:12]}{TMP_SUFFIX}"
    try:
        with open(probe, "wb") as f:
            f.write(b"\0" * 65536)
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        return e
    finally:
        with contextlib.suppress(OSError):
            os.unlink(probe)
    return None


def _existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _read_only(path: Path) -> bool:
    try:
        return bool(os.statvfs(_existing(path.parent)).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _no_space(folder: Path, probe: bool = True) -> str | None:
    """ "the disk is full" (or its quota exceeded) when ``folder``'s filesystem has less than
    :data:`NEARLY_FULL` bytes free or, with ``probe``, a test write there says so; else None."""
    try:
        vfs = os.statvfs(folder)
    except OSError:
        vfs = None
    if vfs is not None and vfs.f_bavail * vfs.f_frsize < NEARLY_FULL:
        return f"{_CAUSES[errno.ENOSPC]} ({vfs.f_bavail * vfs.f_frsize} bytes free)"
    failed = probe_write(folder) if probe and folder.is_dir() else None
    if failed is not None and failed.errno in (errno.ENOSPC, errno.EDQUOT):
        return _CAUSES[failed.errno]
    return None


def storage_cause(path: Path, exc: BaseException | None = None) -> str:
    """Why ``path`` could not be written, in words, from the error (an ``OSError``'s errno)
    or, when the error does not say (netCDF reports "HDF error"), from the folder itself:
    read-only, nearly no free space, a file size limit (``ulimit -f``), a test write."""
    import resource

    if isinstance(exc, OSError) and exc.errno in (errno.EACCES, errno.EPERM, errno.ENOENT):
        # some libraries report a read-only filesystem, a file in the way or a full disk so
        # (netCDF's nc_create on a disk with no free block: "Permission denied")
        if _read_only(path):
            return _CAUSES[errno.EROFS]
        if not _existing(path.parent).is_dir():
            return f"{_CAUSES[errno.ENOTDIR]} ({_existing(path.parent)} is a file)"
        if not path.parent.exists():
            return f"the folder {path.parent} does not exist (deleted?)"
        full = _no_space(_existing(path.parent))
        if full is not None:
            return full
    if isinstance(exc, OSError) and exc.errno in _CAUSES:
        cause = _CAUSES[exc.errno]
        if exc.errno == errno.EFBIG:
            soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
            if soft != resource.RLIM_INFINITY:
                cause += f" (ulimit -f: {soft} bytes)"
        return cause
    folder = _existing(path.parent)
    try:
        vfs = os.statvfs(folder)
    except OSError:
        vfs = None
    if vfs is not None and vfs.f_flag & os.ST_RDONLY:
        return _CAUSES[errno.EROFS]
    full = _no_space(folder, probe=False)
    if full is not None:
        return full
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if soft != resource.RLIM_INFINITY:
        return f"the file size limit was reached (ulimit -f: {soft} bytes)"
    probe = probe_write(folder) if folder.is_dir() else None
    if probe is not None and probe.errno in _CAUSES:
        return _CAUSES[probe.errno]
    if exc is not None:
        return f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    return "unknown cause"


def storage_error(path: Path, exc: BaseException) -> StorageError:
    """The :class:`StorageError` for a failed write of ``path``."""
    return StorageError(f"cannot write {path}: {storage_cause(path, exc)}")


@contextlib.contextmanager
def atomic_path(path: Path, *, sync_dir: bool = True) -> Iterator[Path]:
    """Yield a temporary path; on success fsync it and rename it to ``path``, then fsync the
    folder (``sync_dir=False``: the caller does, once for several files, with
    :func:`fsync_dir`). A failure to write (an ``OSError``; netCDF's ``RuntimeError``)
    raises :class:`StorageError` naming the path and the cause."""
    tmp = temporary_path(path)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except (OSError, RuntimeError) as e:
        raise storage_error(path, e) from e
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
    if sync_dir:
        fsync_dir(path.parent)


def atomic_write_text(path: Path, text: str, *, sync_dir: bool = True) -> None:
    with atomic_path(path, sync_dir=sync_dir) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _json_default(value: Any) -> Any:
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (tuple, set)):
        return list(value)
    return str(value)


def dumps(obj: Any) -> str:
    """JSON with NaN allowed (Python's json reads it back)."""
    return json.dumps(obj, default=_json_default, allow_nan=True, sort_keys=True)


def netcdf_attr(value: Any) -> Any:
    """A value netCDF can store as an attribute (bools as 0/1, None as "", dicts as JSON)."""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if value is None:
        return ""
    if isinstance(value, Mapping):
        return dumps(dict(value))
    if isinstance(value, (list, tuple)):
        if not value:
            return ""
        if all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool) for v in value):
            return np.asarray(value)
        return dumps(list(value))
    return value


def atomic_to_netcdf(
    ds: xr.Dataset,
    path: Path,
    encoding: Mapping[str, Mapping[str, Any]] | None = None,
    groups: Mapping[str, xr.Dataset] | None = None,
    *,
    sync_dir: bool = True,
) -> int:
    """Write ``ds`` to ``path`` atomically, with ``groups`` (name -> Dataset) as netCDF groups
    of the same file; return the file's size in bytes. ``sync_dir``: as :func:`atomic_path`."""
    ds = ds.copy(deep=False)
    ds.attrs = {k: netcdf_attr(v) for k, v in ds.attrs.items()}
    for var in ds.variables.values():
        var.attrs = {k: netcdf_attr(v) for k, v in var.attrs.items()}
    import dask

    # Inside a dask worker xarray would guard the write with a distributed lock (a round trip
    # to the scheduler, and a failure while it shuts down): the file is private, so no lock.
    enc = {str(k): dict(v) for k, v in (encoding or {}).items()}
    for name in ds.coords:  # CF: a coordinate variable has no _FillValue (xarray's default)
        enc.setdefault(str(name), {}).setdefault("_FillValue", None)
    with atomic_path(path, sync_dir=sync_dir) as tmp, dask.config.set(scheduler="synchronous"):
        _write_netcdf(tmp, ds, enc, groups or {})
        size = tmp.stat().st_size
    return size


def netcdf_lock() -> Any:
    """The process's lock around netCDF-C / HDF5 calls: xarray's own
    (``NETCDF4_PYTHON_LOCK``), which its netCDF4 backend takes for every read and write.
    HDF5 is built without thread safety, so a file opened with ``netCDF4.Dataset`` directly
    is opened, used and closed under it: a run file written by a worker thread of an
    in-process cluster while the driver's catalogue thread reads a phase.nc crashed the
    process (a segmentation fault) without it. Not re-entrant: no xarray call inside."""
    from xarray.backends.netCDF4_ import NETCDF4_PYTHON_LOCK

    return NETCDF4_PYTHON_LOCK


class _DeferredWrites:
    """xarray's array writer, holding every data write until all variables are defined.

    netCDF-C leaves define mode for a data write and syncs the file's metadata each time
    (``nc_enddef``); xarray writes each variable as soon as it defines it, so a run file of
    39 small variables took 75-120 ms to write, against 25-50 ms with the writes held to the
    end (measured at 16^2 on the 2-core VM: ``benchmarks/bench_overhead.py``)."""

    def __init__(self) -> None:
        self.writes: list[tuple[Any, Any, Any]] = []

    def add(self, source: Any, target: Any, region: Any = None) -> None:
        self.writes.append((source, target, region))

    def flush(self) -> None:
        for source, target, region in self.writes:
            target[region if region else ...] = source
        self.writes.clear()


def _write_netcdf(
    path: Path,
    ds: xr.Dataset,
    encoding: Mapping[str, Mapping[str, Any]],
    groups: Mapping[str, xr.Dataset],
) -> None:
    """``ds`` (with ``encoding``) and ``groups`` into one new netCDF-4 file, in one opening:
    what ``ds.to_netcdf`` then ``group.to_netcdf(mode="a", group=...)`` write, with the data
    written after every variable of every group is defined (:class:`_DeferredWrites`)."""
    import netCDF4
    from xarray.backends import NetCDF4DataStore

    # the file opened here, not by xarray's file manager (whose cache costs a fifth of the
    # write): the store only writes into it, the whole write under the process's netCDF lock
    # once (the stores take none: lock=False)
    with netcdf_lock():
        nc = netCDF4.Dataset(path, mode="w", format="NETCDF4")
        try:
            writer = _DeferredWrites()
            ds.dump_to_store(NetCDF4DataStore(nc, lock=False), writer=writer, encoding=encoding)
            for name, group in groups.items():
                store = NetCDF4DataStore(nc.createGroup(name), lock=False)
                group.dump_to_store(store, writer=writer)
            writer.flush()
        finally:
            nc.close()


# --------------------------------------------------------------------------- file checks
def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's content (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(1 << 20):
            h.update(block)
    return h.hexdigest()


def file_stamp(path: Path) -> dict[str, Any]:
    """What a run's record says about its file, to recognise it later: size, mtime and
    SHA-256 (``nc_bytes``, ``nc_mtime_ns``, ``nc_sha256``)."""
    st = path.stat()
    return {"nc_bytes": st.st_size, "nc_mtime_ns": st.st_mtime_ns, "nc_sha256": file_sha256(path)}


def netcdf_problem(path: Path, variables: Iterable[str] = ()) -> str | None:
    """Why ``path`` is not a readable netCDF holding ``variables`` (``None`` if it is one):
    a header read, no data is loaded."""
    import netCDF4

    try:
        with netcdf_lock(), netCDF4.Dataset(path, "r") as nc:
            missing = [v for v in variables if v not in nc.variables]
    except FileNotFoundError:
        return "the file is missing"
    except Exception as e:  # noqa: BLE001 - any failure to open means unreadable
        return f"unreadable ({type(e).__name__}: {' '.join(str(e).split())})"
    if missing:
        return f"it lacks the variable(s) {', '.join(missing)}"
    return None


def series_time(run: xr.Dataset) -> xr.DataArray:
    """The time coordinate of a run's series: ``t`` (``time`` in run files of schema 1)."""
    return run["t"] if "t" in run.variables else run["time"]


def now_iso() -> str:
    """The UTC time now as ISO 8601 text (to the second): the stamp of records, locks and
    files."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
