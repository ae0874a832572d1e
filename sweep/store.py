"""The results folder of one campaign, ``results/<name>/``::

    campaign.yaml           the campaign text of the last run (provenance)
    runs/<run_id>.nc        one self-describing netCDF per run (time series, snapshots, attrs)
    runs/<run_id>.json      the run's record: status, reason, traceback, scalars, nc size
    manifest.json           cache of all records (so ``status`` reads one file, not 10^5)
    phase.nc                the aggregate (written by the driver alone)
    .lock                   held (flock) by the one driver running the campaign

Every file is written to a temporary name in the same folder and renamed into place
(:mod:`nematic_solids.sweep.files`), so a file that exists is complete. A run counts as
*done* when its record exists and, for a run that produced a Dataset, its ``.nc`` is the file
the worker wrote: the size the record states and, when the file's mtime is not the recorded
one (or on ``--check-files``), the recorded SHA-256 of its content
(:meth:`CampaignStore.check_run_file`); a ``.nc`` without a record (the worker died between
the two renames) is adopted if it opens and names the same run, deleted otherwise. The
manifest is only a cache: a record whose file changed since (other mtime or size) or is
missing from it is read again.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import logging
import math
import os
import socket
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict, cast

import numpy as np

from .errors import StorageError, StoreError
from .files import (
    TMP_SUFFIX,
    atomic_write_text,
    dumps,
    file_sha256,
    file_stamp,
    netcdf_lock,
    netcdf_problem,
    now_iso,
    probe_write,
    storage_cause,
)
from .lock import CampaignLock

if TYPE_CHECKING:
    import xarray as xr

log = logging.getLogger(__name__)

RUNS = "runs"
#: the rolling checkpoints of the runs in progress (nematic_solids.sweep.run.continuation)
CHECKPOINTS = "checkpoints"
MANIFEST = "manifest.json"
PHASE = "phase.nc"
LOCK = ".lock"
CAMPAIGN_COPY = "campaign.yaml"
MANIFEST_VERSION = 6
#: Record keys kept in the manifest (the sidecar also has traceback, parameters, numerics).
MANIFEST_KEYS = (
    "status",
    "reason",
    "detail",
    "t_failed",
    "seed",
    "wall_time",
    "nc_bytes",
    "nc_sha256",
    "nc_mtime_ns",
    "scalars",
    "code_version",
    "git_commit",
    "finished",
    "trajectory",
    "end_state",
    "reused_from",
)
#: Variables every run file holds (checked when a file without a checksum is verified; the
#: time axis is ``t``, or ``time`` in files of schema 1: see :func:`series_time`).
RUN_FILE_VARIABLES = ("sigma2_S",)
MAX_DETAIL = 500
#: Reasons of records that say the result could not be stored or the run's worker was lost
#: (no longer written; old folders may hold some), or that the run it begins from did not
#: end (its parent, its predecessor in a chain) or its state could not be used (corrupt: the
#: parent is redone when its file no longer matches its record): not that it failed. Redone by
#: default.
RETRYABLE_REASONS = ("write_error", "killed_worker", "parent_failed", "parent_state")


class Record(TypedDict, total=False):
    """A run's record (``runs/<run_id>.json``; the manifest keeps :data:`MANIFEST_KEYS`):
    written by the worker task (:mod:`nematic_solids.sweep.run.task`) or on adopting a run file
    (:func:`record_from_dataset`), read back by every reader of the results folder."""

    run_id: str
    #: "ok" or "failed"
    status: str
    #: why a run failed (a short word: nan, ill_posed, exception, ...) and the detail
    reason: str
    detail: str
    t_failed: float | None
    traceback: str
    seed: int | None
    #: the run's seconds, and the run scalars (sigma2_S_final, lambda_peak, ...)
    wall_time: float | None
    scalars: dict[str, float]
    #: the run file as the worker wrote it: size, checksum, modification time
    nc_bytes: int | None
    nc_sha256: str | None
    nc_mtime_ns: int | None
    code_version: str
    git_commit: str
    finished: str
    host: str
    parameters: dict[str, Any]
    numerics: dict[str, Any]
    #: the run's file when the results folder could not take it (the spool)
    saved_to: str | None
    storage_error: str
    #: the earlier failures of a run redone with --retry-failed
    previous_failures: list[dict[str, Any]]
    #: what the run is: its campaign, settings and swept values (:meth:`RunTask.identity`)
    campaign: str
    coords: dict[str, Any]
    #: the worker process that wrote it
    pid: int
    #: the manifest's copy of the run file's stamp (size, mtime), beside the record's own
    stamp: list[int]
    #: the run's trajectory (its id without t_final: :func:`.identity.trajectory_id`)
    trajectory: str
    #: the time of the end state its file keeps (a longer run continues it), or None
    end_state: float | None
    #: where this execution of the run started (0, or the time of the state it continued),
    #: the run whose end state it continued (or ""), and every state it went through
    #: ("checkpoint@t", "<run_id>@t"; :mod:`nematic_solids.sweep.run.continuation`)
    started_at: float
    continued_from: str
    lineage: list[str]
    #: why a checkpoint or end state it found was not used (corrupt, another run's, ...)
    start_warning: str
    #: the campaign whose finished run this one is, taken in place (its file a link to that
    #: campaign's; :mod:`nematic_solids.sweep.catalogue.reuse`)
    reused_from: str


# --------------------------------------------------------------------------- run records
def _float(value: Any) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return math.nan
    return x


def scalars_of(ds: xr.Dataset) -> dict[str, float]:
    """Every 0-d numeric data variable of a run Dataset (sigma2_S_final, t_peak, ...)."""
    out = {}
    for name, var in ds.data_vars.items():
        if var.ndim == 0 and np.issubdtype(var.dtype, np.number):
            out[str(name)] = _float(var.values)
    return out


def record_from_dataset(
    ds: xr.Dataset, run_id: str, nc_bytes: int | None, stamp: Mapping[str, Any] | None = None
) -> Record:
    """The record of a run from its Dataset (the worker, or adoption of an unindexed file);
    ``stamp`` (:func:`file_stamp`) identifies the file written."""
    a = ds.attrs
    status = str(a.get("status", "ok")) or "ok"
    t_failed = _float(a.get("t_failed", math.nan))
    scalars = scalars_of(ds)
    return {
        "run_id": run_id,
        "status": "ok" if status == "ok" else "failed",
        "reason": str(a.get("reason", "")),
        "detail": str(a.get("detail", "")),
        "t_failed": None if math.isnan(t_failed) else t_failed,
        "traceback": "",
        "seed": int(a["seed"]) if "seed" in a else None,
        "wall_time": scalars.get("wall_time"),
        "nc_bytes": nc_bytes,
        "nc_sha256": (stamp or {}).get("nc_sha256"),
        "nc_mtime_ns": (stamp or {}).get("nc_mtime_ns"),
        "scalars": scalars,
        "code_version": str(a.get("code_version", "")),
        "git_commit": str(a.get("git_commit", "")),
        "finished": now_iso(),
        "host": socket.gethostname(),
    }


def _is_count(value: Any) -> bool:
    """A byte count: a non-negative whole number (not a bool, not a string)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return math.isfinite(value) and value >= 0 and float(value).is_integer()


def slim(record: Mapping[str, Any], stamp: list[int]) -> Record:
    """The manifest's copy of a record; ``stamp`` is its file's [mtime_ns, size]."""
    out = {k: record.get(k) for k in MANIFEST_KEYS}
    if isinstance(out["detail"], str) and len(out["detail"]) > MAX_DETAIL:
        out["detail"] = out["detail"][:MAX_DETAIL] + "..."
    out["stamp"] = stamp
    return cast(Record, out)


# --------------------------------------------------------------------------- the lock
class CampaignStore:
    """``results/<name>/`` and everything in it."""

    def __init__(self, results_root: str | Path, name: str):
        self.results_root = Path(results_root)
        self.root = self.results_root / name
        self.runs_dir = self.root / RUNS
        self.checkpoints_dir = self.root / CHECKPOINTS
        self.manifest_path = self.root / MANIFEST
        self.phase_path = self.root / PHASE
        self.lock_path = self.root / LOCK
        self.campaign_copy = self.root / CAMPAIGN_COPY
        #: names of the .nc files seen by the last :meth:`scan` (run_ids)
        self.nc_present: set[str] = set()

    # paths
    def nc_path(self, run_id: str) -> Path:
        return self.runs_dir / f"{run_id}.nc"

    def record_path(self, run_id: str) -> Path:
        return self.runs_dir / f"{run_id}.json"

    def checkpoint_path(self, run_id: str) -> Path:
        """The rolling checkpoint of a run in progress (sweep/run/continuation.py)."""
        return self.checkpoints_dir / f"{run_id}.nc"

    def in_progress(self) -> dict[str, dict[str, Any]]:
        """The runs with a rolling checkpoint: run_id -> ``t`` (the time it holds, NaN if
        unreadable), ``checkpoint`` (its path) and ``written`` (its mtime): headers only."""
        import netCDF4

        out: dict[str, dict[str, Any]] = {}
        try:
            entries = sorted(self.checkpoints_dir.glob("*.nc"))
        except OSError:
            return out
        for path in entries:
            try:
                written = _dt.datetime.fromtimestamp(path.stat().st_mtime, _dt.UTC)
                with netcdf_lock(), netCDF4.Dataset(path, "r") as nc:
                    t = float(nc.getncattr("t"))
            except FileNotFoundError:  # the run ended meanwhile
                continue
            except Exception:  # noqa: BLE001 - unreadable: the run will ignore it too
                t = math.nan
            out[path.stem] = {
                "t": t,
                "checkpoint": str(path),
                "written": written.isoformat(timespec="seconds"),
            }
        return out

    def lock(self) -> CampaignLock:
        return CampaignLock(self.lock_path)

    def ensure(self) -> None:
        """Create the folder and check that a file can be written in it (a test write: the
        permission bits do not stop root, a read-only or full filesystem does)."""
        try:
            self.runs_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise StorageError(
                f"cannot create {self.runs_dir}: {storage_cause(self.runs_dir, e)}"
            ) from None
        problem = probe_write(self.runs_dir)
        if problem is not None:
            raise StorageError(
                f"cannot write in {self.runs_dir}: {storage_cause(self.runs_dir / 'x', problem)}"
            )

    # records
    def write_record(self, record: Mapping[str, Any], *, sync_dir: bool = True) -> None:
        path = self.record_path(str(record["run_id"]))  # sync_dir: as files.atomic_path's
        atomic_write_text(path, dumps(dict(record)), sync_dir=sync_dir)

    def read_record(self, run_id: str) -> Record | None:
        try:
            data = json.loads(self.record_path(run_id).read_text(encoding="utf-8"))
        except (OSError, ValueError):  # missing, unreadable, not JSON: no record
            return None
        return cast(Record, dict(data)) if isinstance(data, dict) else None

    def load_manifest(self) -> dict[str, Record]:
        """The cached records (columnar JSON: one list per key, one entry per run)."""
        try:
            data = json.loads(self.manifest_path.read_text(encoding="utf-8"))
        except (FileNotFoundError, ValueError):
            return {}
        if not isinstance(data, dict) or data.get("version") != MANIFEST_VERSION:
            return {}
        try:
            keys = [k for k in (*MANIFEST_KEYS, "stamp") if k != "scalars"]
            names = list(data["scalars"])
            rows = zip(*(data[k] for k in keys), strict=True)
            values = zip(*(data["scalars"][k] for k in names), strict=True) if names else None
            records = {}
            for rid, row in zip(data["run_id"], rows, strict=True):
                rec = cast(Record, dict(zip(keys, row, strict=True)))
                scalar_row = next(values) if values is not None else ()
                rec["scalars"] = {
                    k: v for k, v in zip(names, scalar_row, strict=True) if v is not None
                }
                records[rid] = rec
        except (KeyError, TypeError, ValueError, StopIteration):
            return {}
        return records

    def save_manifest(self, records: Mapping[str, Record]) -> None:
        """Write the manifest atomically (best effort: a read-only folder is left alone)."""
        ids = list(records)
        data: dict[str, Any] = {"version": MANIFEST_VERSION, "run_id": ids}
        for key in (*MANIFEST_KEYS, "stamp"):
            if key != "scalars":
                data[key] = [records[r].get(key) for r in ids]
        names = sorted({k for r in ids for k in (records[r].get("scalars") or {})})
        data["scalars"] = {
            k: [(records[r].get("scalars") or {}).get(k) for r in ids] for k in names
        }
        try:
            atomic_write_text(self.manifest_path, dumps(data))
        except (OSError, StoreError) as e:
            log.debug("manifest not written: %s", e)

    def scan(self, *, save: bool = True) -> dict[str, Record]:
        """All run records (slim) keyed by run_id, from the manifest where it is current and
        from the per-run files elsewhere; also sets :attr:`nc_present`. Opens no netCDF."""
        manifest = self.load_manifest()
        records: dict[str, Record] = {}
        nc: set[str] = set()
        changed = False
        try:
            entries = os.scandir(self.runs_dir)
        except FileNotFoundError:
            self.nc_present = set()
            return {}
        with entries:
            for entry in entries:
                name = entry.name
                if name.startswith("."):
                    continue
                if name.endswith(".nc"):
                    nc.add(name[:-3])
                elif name.endswith(".json"):
                    rid = name[:-5]
                    try:
                        st = entry.stat()
                    except FileNotFoundError:
                        continue
                    stamp = [st.st_mtime_ns, st.st_size]
                    cached = manifest.get(rid)
                    if cached is not None and cached.get("stamp") == stamp:
                        records[rid] = cached
                        continue
                    full = self.read_record(rid)
                    if full is None:
                        continue
                    records[rid] = slim(full, stamp)
                    changed = True
        if len(records) != len(manifest):
            changed = True
        self.nc_present = nc
        if save and changed:
            self.save_manifest(records)
        return records

    def check_run_file(
        self, run_id: str, record: Mapping[str, Any], *, check_files: bool = False
    ) -> str | None:
        """Why the run of ``record`` does not count as done (``None`` if it does).

        A run that raised has no file: its record is all there is. Otherwise its ``.nc`` must
        have the recorded size; if its mtime is not the recorded one (or ``check_files``), its
        content must have the recorded SHA-256 (records written before checksums existed:
        the file must open and hold the run's variables). One ``stat`` per run when nothing
        changed, so ``status`` and the driver's plan stay cheap for 10^5 runs."""
        nc_bytes = record.get("nc_bytes")
        if nc_bytes is None:
            if record.get("status") == "failed":
                return None
            return "its record names no run file"
        if not _is_count(nc_bytes):
            return f"its record is malformed (nc_bytes = {nc_bytes!r})"
        path = self.nc_path(run_id)
        try:
            st = path.stat()
        except OSError:
            return "its file is missing"
        if st.st_size != int(nc_bytes):
            return (
                f"its file has {st.st_size} bytes, not the {int(nc_bytes)} recorded "
                "(truncated or overwritten)"
            )
        if not check_files and record.get("nc_mtime_ns") == st.st_mtime_ns:
            return None
        sha = record.get("nc_sha256")
        if isinstance(sha, str) and sha:
            try:
                if file_sha256(path) != sha:
                    return (
                        "its file is corrupt (its content is not the one checksummed "
                        "when it was written)"
                    )
            except OSError as e:
                return f"its file cannot be read ({e.strerror or e})"
            return None
        problem = netcdf_problem(path, RUN_FILE_VARIABLES)
        return None if problem is None else f"its file: {problem}"

    def is_complete(
        self, run_id: str, record: Mapping[str, Any] | None, *, check_files: bool = False
    ) -> bool:
        """Whether ``record`` stands for a finished run whose file (if any) is intact
        (:meth:`check_run_file`)."""
        return (
            record is not None
            and self.check_run_file(run_id, record, check_files=check_files) is None
        )

    def refresh_stamp(self, run_id: str) -> None:
        """After :meth:`check_run_file` accepted a file whose mtime changed (a copy, a
        restore) or that has no checksum yet (an older record): record its current mtime
        and checksum, so the next check is a ``stat`` again. Best effort."""
        full = self.read_record(run_id)
        if full is None:
            return
        path = self.nc_path(run_id)
        try:
            full.update(cast(Record, file_stamp(path)))
            self.write_record(full)
        except (OSError, StoreError) as e:
            log.debug("record of %s not refreshed: %s", run_id, e)

    def adopt(self, run_id: str) -> Record | None:
        """Index a ``.nc`` that has no record (its worker died before writing it): keep it if
        it opens and names this run, else delete it. Returns the new record or ``None``."""
        path = self.nc_path(run_id)
        import dask
        import xarray as xr

        try:
            with (
                dask.config.set(scheduler="synchronous"),
                xr.open_dataset(path, engine="netcdf4") as ds,
            ):
                ds.load()
                if str(ds.attrs.get("run_id", "")) != run_id:
                    raise ValueError(f"it names run {ds.attrs.get('run_id')!r}")
                stamp = file_stamp(path)
                record = record_from_dataset(ds, run_id, stamp["nc_bytes"], stamp)
        except Exception as e:  # noqa: BLE001 - any unreadable file is simply redone
            log.warning("removing unreadable run file %s (%s)", path, e)
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
            return None
        self.write_record(record)
        return record

    def discard(self, run_id: str) -> None:
        """Remove a run's record and file (before redoing it)."""
        for p in (self.record_path(run_id), self.nc_path(run_id)):
            with contextlib.suppress(FileNotFoundError):
                p.unlink()

    def clean_temporaries(self, min_age: float = 0.0) -> int:
        """Delete leftover temporary files older than ``min_age`` seconds (only call while
        holding the lock; a worker of a remote cluster may still be finishing a cancelled
        run, so the driver passes a safety age there)."""
        n = 0
        now = time.time()
        for directory in (self.root, self.runs_dir, self.checkpoints_dir):
            with contextlib.suppress(FileNotFoundError), os.scandir(directory) as it:
                for entry in it:
                    if entry.name.startswith(".") and entry.name.endswith(TMP_SUFFIX):
                        with contextlib.suppress(FileNotFoundError):
                            if now - entry.stat().st_mtime >= min_age:
                                os.unlink(entry.path)
                                n += 1
        if n:
            log.info("removed %d temporary file(s) left by an interrupted run", n)
        return n

    def save_campaign_text(self, text: str) -> None:
        """Write the campaign copy (its content:
        :func:`nematic_solids.sweep.campaign_copy.campaign_copy_text`)."""
        atomic_write_text(self.campaign_copy, text)
