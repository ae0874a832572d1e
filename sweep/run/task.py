"""The worker task: one run -> its netCDF (written atomically) and its record.

:func:`execute_run` runs one simulation, writes the file and then the record, and returns
the record; it never raises for a failed or crashing run (the record says why, with the
traceback). A result the results folder cannot take is kept in the spool
(:func:`spool_dir`) and the run stays pending. :func:`warm_workers` compiles (or loads) the
model's kernels on every worker before the runs start.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import logging
import math
import os
import socket
import time
import uuid
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from ..campaign import DEFAULT_MODEL, StoreSpec
from ..errors import DeviceUnavailable, StorageError, StoreError
from ..expand import Expansion, RunSpec
from ..files import atomic_to_netcdf, file_stamp
from ..identity import SCHEMA_VERSION, identity_start, trajectory_id
from ..models.interface import Compiled, RunRequest, State, batched
from ..models.registry import get_model
from ..provenance import code_version, git_commit
from ..store import CampaignStore, Record, record_from_dataset
from . import continuation
from .failures import crash_record, failure_record

if TYPE_CHECKING:
    import xarray as xr
    from distributed import Client

log = logging.getLogger(__name__)

#: Run-file attributes added by the campaign manager.
IDENTITY_ATTRS = ("run_id", "campaign", "identity_schema")


@dataclass(frozen=True)
class RunTask:
    """Everything a worker needs for one run (plain data: cheap to pickle)."""

    run_id: str
    seed: int
    parameters: dict[str, Any]
    numerics: dict[str, Any]
    runs_dir: str
    campaign: str
    coords: dict[str, Any] = field(default_factory=dict)
    snapshot_fields: tuple[str, ...] | None = None
    snapshot_dtype: str = "float64"
    #: the earlier failures of a run that is redone (``--retry-failed``), oldest first: its
    #: new record keeps them as ``previous_failures``
    previous_failures: tuple[dict[str, Any], ...] = ()
    #: the run's trajectory id (:func:`nematic_solids.sweep.identity.trajectory_id`)
    trajectory: str = ""
    #: the finished shorter run of its trajectory whose end state it continues (or None),
    #: and its file when another campaign made it (None: this campaign's runs folder)
    parent: str | None = None
    parent_path: str | None = None
    #: the rolling checkpoint's interval: simulated time, wall seconds (store.checkpoint_every)
    checkpoint_tau: float = math.inf
    checkpoint_wall: float = math.inf
    #: whether the run file keeps the end state (store.end_state)
    end_state: bool = True
    #: the run of another campaign it begins from (``initial.from``): its ``run`` id, the
    #: ``time`` ("end" or the time), its ``campaign`` and ``runs_dir``; None: the texture
    initial_from: dict[str, str] | None = None
    #: the model that computes it, by its registered name (the campaign's ``model:``)
    model: str = DEFAULT_MODEL

    @classmethod
    def from_spec(
        cls,
        run: RunSpec,
        store: CampaignStore,
        campaign: str,
        store_spec: StoreSpec,
        previous_failures: list[dict[str, Any]] | None = None,
        parent: str | None = None,
        parent_path: str | None = None,
        *,
        model: str = DEFAULT_MODEL,
    ) -> RunTask:
        parameters, numerics = run.point.parameters.to_dict(), run.point.numerics.to_dict()
        initial_from, start = None, None
        if run.start is not None:
            start = identity_start(run.start)
            runs = CampaignStore(store.results_root, run.start["campaign"]).runs_dir
            initial_from = {**run.start, "runs_dir": str(runs.resolve())}
        return cls(
            run_id=run.run_id,
            seed=run.seed,
            parameters=parameters,
            numerics=numerics,
            runs_dir=str(store.runs_dir.resolve()),
            campaign=campaign,
            coords=dict(run.point.coords),
            snapshot_fields=store_spec.snapshot_fields,
            snapshot_dtype=store_spec.snapshot_dtype,
            previous_failures=tuple(previous_failures or ()),
            trajectory=trajectory_id(parameters, numerics, run.seed, start, model),
            parent=parent,
            parent_path=parent_path,
            checkpoint_tau=store_spec.checkpoint_tau,
            checkpoint_wall=store_spec.checkpoint_wall,
            end_state=store_spec.end_state,
            initial_from=initial_from,
            model=model,
        )

    def identity(self) -> dict[str, Any]:
        """What every record of this run carries besides the result: its settings, swept
        values, campaign and earlier failures."""
        out: dict[str, Any] = {
            "parameters": self.parameters,
            "numerics": self.numerics,
            "coords": self.coords,
            "campaign": self.campaign,
        }
        if self.previous_failures:
            out["previous_failures"] = list(self.previous_failures)
        return out


def prepare_dataset(ds: xr.Dataset, task: RunTask) -> tuple[xr.Dataset, dict[str, Any]]:
    """Add the run's identity attributes, keep the requested snapshot fields in the requested
    precision; return the Dataset and its netCDF encoding (snapshots zlib-compressed)."""
    ds = ds.copy(deep=False)
    if task.snapshot_fields is not None:
        drop = [
            n
            for n, v in ds.data_vars.items()
            if "snapshot_time" in v.dims and n not in task.snapshot_fields
        ]
        ds = ds.drop_vars(drop)
    encoding: dict[str, Any] = {}
    for name, var in ds.data_vars.items():
        if var.ndim >= 2:
            encoding[str(name)] = {"zlib": True, "complevel": 4}
            if task.snapshot_dtype == "float32" and var.dtype.kind == "f":
                ds[name] = var.astype("float32")
    ds.attrs.update(run_id=task.run_id, campaign=task.campaign, identity_schema=SCHEMA_VERSION)
    ds.attrs.setdefault("status", "ok")  # a model's run that returns says how it ended, or ok
    ds.attrs.setdefault("code_version", code_version())  # where a model's file does not say
    ds.attrs.setdefault("git_commit", git_commit())
    return ds, encoding


def task_store(task: RunTask) -> CampaignStore:
    """The results folder a task writes into (its ``runs_dir`` is ``<results>/<name>/runs``)."""
    runs = Path(task.runs_dir)
    return CampaignStore(runs.parent.parent, runs.parent.name)


#: ``status`` of the record :func:`execute_run` returns (and does not write) when the
#: result could not be stored: the run is not a failure, it stays pending.
UNSAVED = "unsaved"


def spool_dir(runs_dir: str | Path) -> Path:
    """Where a worker keeps a result it could not write into ``runs_dir`` (a full or
    read-only results disk): ``$NEMATIC_SPOOL`` or the temporary folder, one subfolder per
    results folder. The driver moves what it finds there into the folder on the next run."""
    import hashlib
    import tempfile

    runs = Path(runs_dir).resolve()
    base = Path(os.environ.get("NEMATIC_SPOOL") or Path(tempfile.gettempdir()) / "nematic-unsaved")
    tag = hashlib.sha256(str(runs).encode()).hexdigest()[:12]
    return base / f"{runs.parent.name}-{tag}"


def unsaved(
    task: RunTask,
    error: StorageError,
    ds: xr.Dataset | None,
    encoding: Mapping[str, Any],
    wall: float,
) -> Record:
    """The record of a run whose result could not be written: kept in the spool if possible
    (and the message says where), no record written (the run stays pending)."""
    detail = str(error)
    saved_to = None
    if ds is not None:
        path = spool_dir(task.runs_dir) / f"{task.run_id}.nc"
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_to_netcdf(ds, path, encoding)
            saved_to = str(path)
            detail += (
                f"; the result is kept in {path} (moved into the results folder by the next run)"
            )
        except (OSError, StoreError) as e:
            detail += f"; it could not be kept elsewhere either ({e})"
            with contextlib.suppress(OSError):
                path.parent.rmdir()
    record = failure_record(task, "storage", detail, "", wall)
    record["status"] = UNSAVED
    record["saved_to"] = saved_to
    record["storage_error"] = str(error)
    return record


#: glibc's mallopt parameters and the values :func:`restore_heap_reuse` sets
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20  # glibc's largest allowed value on 64-bit systems
_TRIM_THRESHOLD = 64 << 20


@functools.lru_cache(maxsize=1)
def _mallopt() -> Any:
    """glibc's ``mallopt`` (None elsewhere), looked up once per process (``find_library``
    runs ``ldconfig``: 2 to 5 ms a call, measured, against 13 ms of steps in a 16^2 run)."""
    name = ctypes.util.find_library("c")
    if not name:
        return None
    try:
        return ctypes.CDLL(name).mallopt
    except (OSError, AttributeError):
        return None


def restore_heap_reuse() -> bool:
    """Let this process reuse freed heap memory for a run's temporary arrays (glibc only;
    returns whether it could).

    dask's nanny starts every worker with ``MALLOC_TRIM_THRESHOLD_=65536`` (so that freed
    memory goes back to the system). Setting it also fixes glibc's mmap threshold at 128 KiB
    instead of letting it grow, so every temporary array of a run (a 128^2 tangent is 2 MB) is
    mapped and unmapped anew and its pages faulted in again: a finite-strain run took 2.1-2.5x
    the CPU time in a worker (measured: 128^2, t = 60, 9.4 s against 3.9 s; 1.9 million page
    faults against 63 thousand). Fixed thresholds of 32 MiB (mmap) and 64 MiB (trim) keep the
    run's arrays on the heap and still return large free blocks."""
    mallopt = _mallopt()
    if mallopt is None:
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD)
    )


#: records completed but not yet written (:func:`finish_record` with ``held``): the run, its
#: folder, its record and its start (``time.perf_counter``), written together by
#: :func:`nematic_solids.sweep.run.group.write_held`
Held = list[tuple[RunTask, CampaignStore, Record, float]]


def request(task: RunTask, start: continuation.Start, store: CampaignStore) -> RunRequest:
    """What the task's model is asked to run: its point and seed, from ``start`` (a state
    to continue, or fields to begin from at t = 0), its rolling checkpoints written into
    ``store``."""
    return RunRequest(
        parameters=task.parameters,
        numerics=task.numerics,
        seed=task.seed,
        start=start.state,
        initial=start.initial,
        checkpoint=continuation.Checkpointer(store, task.run_id),
        checkpoint_every=task.checkpoint_tau,
        checkpoint_wall=task.checkpoint_wall,
    )


def execute_run(task: RunTask, held: Held | None = None) -> Record:
    """Run one simulation on a worker; write ``<run_id>.nc`` then ``<run_id>.json``
    atomically; return the record. A run the model reports as failed keeps its (partial)
    Dataset; a Python exception becomes a record with reason ``"exception"`` and the
    traceback. A result that cannot be stored (a :class:`StorageError`: disk full,
    read-only, file size limit) is not a failure of the run: no record is written (the run
    stays pending), the Dataset is kept in :func:`spool_dir` if possible, and the returned
    record has status :data:`UNSAVED` with the cause (the driver stops). With ``held``
    (several runs in one task: :mod:`nematic_solids.sweep.run.group`) the file's folder is not
    synced and the record is completed into ``held`` instead of written: the caller syncs the
    folder once, then writes the records."""
    from .workers import import_model

    import_model(task.model)
    restore_heap_reuse()
    store = task_store(task)
    t0 = time.perf_counter()
    start = continuation.Start()
    end_state: State | None = None
    try:
        start = continuation.starting_state(task, store)
        outcome = get_model(task.model).run(request(task, start, store))
        ds, end_state = outcome.dataset, outcome.end_state
        if outcome.warnings:  # the model's word on its start (a continuation not exact)
            start.warning = "; ".join(w for w in (start.warning, *outcome.warnings) if w)
    except continuation.ParentFailed as e:  # redone with its parent (RETRYABLE_REASONS)
        record = failure_record(task, "parent_failed", str(e), "", time.perf_counter() - t0)
    except continuation.ParentUnusable as e:  # its state is corrupt or not the one named
        record = failure_record(task, "parent_state", str(e), "", time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - any crash is recorded, the campaign goes on
        record = crash_record(task, "exception", e, t0)
    else:
        return save_result(task, store, ds, end_state, start, t0, held)
    return finish_record(task, store, record, start, t0, held)


def save_result(
    task: RunTask,
    store: CampaignStore,
    ds: xr.Dataset,
    end_state: State | None,
    start: continuation.Start,
    t0: float,
    held: Held | None = None,
) -> Record:
    """Write the run's Dataset (with its end state ``end_state`` when the task keeps it) as
    ``<run_id>.nc``, then its record (:func:`finish_record`); the result of one run, whatever
    computed it (:func:`execute_run`, :func:`nematic_solids.sweep.run.batch.execute_batch`).
    ``t0``: the run's start (``time.perf_counter``); ``held``: as :func:`execute_run`."""
    encoding: dict[str, Any] = {}
    try:
        ds, encoding = prepare_dataset(ds, task)
        ds.attrs.update(continuation.run_attrs(start))
        path = store.nc_path(task.run_id)
        groups = (
            {continuation.STATE_GROUP: end_state.to_dataset(snapshots=False)}
            if task.end_state and end_state is not None
            else {}
        )
        atomic_to_netcdf(ds, path, encoding, groups, sync_dir=held is None)
        stamp = file_stamp(path)
        record = record_from_dataset(ds, task.run_id, stamp["nc_bytes"], stamp)
        if record.get("wall_time") is None:
            record["wall_time"] = time.perf_counter() - t0
        record["end_state"] = end_state.t if groups and end_state is not None else None
    except StorageError as e:
        return unsaved(task, e, ds, encoding, time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - a bug, not the storage: recorded as failed
        record = crash_record(task, "write_error", e, t0)
    return finish_record(task, store, record, start, t0, held)


def finish_record(
    task: RunTask,
    store: CampaignStore,
    record: Record,
    start: continuation.Start,
    t0: float,
    held: Held | None = None,
) -> Record:
    """Complete the run's record (its identity, process, trajectory, start) and write it, the
    run's last act: then its rolling checkpoint goes. A record that cannot be written leaves
    the run pending (:data:`UNSAVED`). With ``held`` the completed record goes there, to be
    written with others (:func:`nematic_solids.sweep.run.group.write_held`)."""
    record.update(cast(Record, task.identity()))
    record["pid"] = os.getpid()
    record["trajectory"] = task.trajectory
    record.update(cast(Record, continuation.run_attrs(start)))
    if start.warning:
        record["start_warning"] = start.warning
    if held is not None:
        held.append((task, store, record, t0))
        return record
    try:
        store.write_record(record)
    except StorageError as e:
        return unsaved(task, e, None, {}, time.perf_counter() - t0)
    continuation.remove_checkpoint(store, task.run_id)
    return record


def warm_kinds(expansion: Expansion) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """One ``(parameters, numerics)`` per distinct kind of run in the campaign (the model's
    :meth:`~nematic_solids.sweep.models.interface.Compiled.warm_kind`): what
    :func:`warm_worker` compiles; none for a model without compiled kernels."""
    model = get_model(expansion.campaign.model)
    if not isinstance(model, Compiled):
        return []
    kinds: dict[Any, tuple[dict[str, Any], dict[str, Any]]] = {}
    for point in expansion.points:
        n = point.numerics
        key = model.warm_kind(point.parameters, n)
        if key not in kinds:
            kinds[key] = (point.parameters.to_dict(), n.to_dict())
    return list(kinds.values())


def check_device(device: str, model: str = DEFAULT_MODEL) -> str:
    """The device ``device`` names here, described (``platform:kind``); raises
    :class:`~nematic_solids.sweep.errors.DeviceUnavailable` (one message: JAX missing, or no
    GPU where one is asked for) before any run is given to it."""
    return batched(get_model(model)).check_device(device)


def warm_worker(
    kinds: list[tuple[dict[str, Any], dict[str, Any]]],
    device: str | None = None,
    model: str = DEFAULT_MODEL,
) -> dict[str, Any]:
    """Run on one worker per host before the campaign: compiles the model's kernels (or
    loads them from the disk cache) with tiny runs, so that the other workers load them
    instead of all compiling at once (the model's ``warm_up``); with ``device`` (the
    accelerated backend's), also finds that device there (``device``, or why not:
    ``device_error``)."""
    from .workers import import_model

    import_model(model)
    found = get_model(model)
    info = found.warm_up(kinds) if isinstance(found, Compiled) else {}
    info["host"] = socket.gethostname()
    if device is not None:
        try:
            info["device"] = check_device(device, model)
        except DeviceUnavailable as e:
            info["device_error"] = str(e)
    return info


def warm_workers(client: Client, expansion: Expansion) -> list[dict[str, Any]]:
    """:func:`warm_worker` on one worker of each host (in parallel across hosts); returns
    what each reported, or raises :class:`~nematic_solids.sweep.errors.DeviceUnavailable` where
    a host lacks the accelerated backend's device. A worker that cannot run it is left to
    fail in the environment check that follows."""
    hosts: dict[str, str] = {}
    from .workers import scheduler_workers

    for addr, info in scheduler_workers(client).items():
        hosts.setdefault(str(info.get("host", addr)), addr)
    kinds = warm_kinds(expansion)
    execution = expansion.campaign.execution
    device = execution.device if execution.backend == "accelerated" else None
    token = uuid.uuid4().hex[:12]  # a shared scheduler may warm several campaigns at once
    futures = [
        client.submit(
            warm_worker,
            kinds,
            device,
            expansion.campaign.model,
            workers=[addr],
            pure=False,
            allow_other_workers=False,
            key=f"nematic-warmup-{token}-{i}",
        )
        for i, addr in enumerate(hosts.values())
    ]
    out = []
    for fut in futures:
        try:
            out.append(fut.result())
        except Exception as e:  # noqa: BLE001 - reported by the environment check
            log.warning("warm-up failed on a worker: %s: %s", type(e).__name__, e)
    for info in out:  # a host without the device asked for: one message, nothing run
        if "device_error" in info:
            raise DeviceUnavailable(f"on the worker host {info['host']}: {info['device_error']}")
    return out
