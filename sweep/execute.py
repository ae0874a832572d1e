"""Execution: the worker task and the driver that fans runs out over dask.

The worker task (:func:`execute_run`) runs one simulation, writes its netCDF atomically and
then its record, and returns the record; it never raises for a failed or crashing run (the
record says why, with the traceback). The driver (:func:`run_campaign`) plans from what is on
disk (:func:`plan_runs`), submits the remaining runs through a bounded window, reports each
result as it arrives and can be interrupted at any point: everything it needs to resume is on
disk, nothing is kept in dask.

Clusters (:mod:`sweep.workforce`): an embedded ``LocalCluster`` (default), an existing
scheduler (``execution.scheduler`` / ``--scheduler``) or a dask-jobqueue cluster
(``execution.cluster``), watched while the runs go (workers checked as they join, lost batch
jobs replaced, a bounded give-up). The results folder must be visible at the same path from
every worker (a shared filesystem).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import logging
import math
import os
import socket
import time
import traceback
import uuid
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import CancelledError
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from model.parameters import Numerics, Parameters

from .errors import ClusterError, StorageError, StoreError
from .expand import Expansion, RunSpec
from .spec import ExecutionSpec, StoreSpec
from .store import (
    RETRYABLE_REASONS,
    CampaignStore,
    Record,
    atomic_path,
    atomic_to_netcdf,
    file_stamp,
    now_iso,
    record_from_dataset,
)
from .workforce import (
    CHECK_EVERY,
    Supervisor,
    Workforce,
    jobqueue_options,
    make_jobqueue,
    open_cluster,
)

if TYPE_CHECKING:
    import xarray as xr
    from distributed import Client

log = logging.getLogger(__name__)

#: How long the driver sleeps when no result is ready (seconds).
POLL = 0.2
#: How long the driver waits for the result of a finished run to arrive (seconds).
RESULT_WAIT = 10.0
#: How often the driver refreshes the manifest while running (seconds).
MANIFEST_EVERY = 300.0
#: Run-file attributes added by the campaign manager.
IDENTITY_ATTRS = ("run_id", "campaign", "identity_schema")


# --------------------------------------------------------------------------- the worker task
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

    @classmethod
    def from_spec(cls, run: RunSpec, store: CampaignStore, campaign: str,
                  store_spec: StoreSpec) -> RunTask:
        return cls(run_id=run.run_id, seed=run.seed,
                   parameters=run.point.parameters.to_dict(),
                   numerics=run.point.numerics.to_dict(),
                   runs_dir=str(store.runs_dir.resolve()), campaign=campaign,
                   coords=dict(run.point.coords), snapshot_fields=store_spec.snapshot_fields,
                   snapshot_dtype=store_spec.snapshot_dtype)


def prepare_dataset(ds: xr.Dataset, task: RunTask) -> tuple[xr.Dataset, dict[str, Any]]:
    """Add the run's identity attributes, keep the requested snapshot fields in the requested
    precision; return the Dataset and its netCDF encoding (snapshots zlib-compressed)."""
    from .identity import SCHEMA_VERSION

    ds = ds.copy(deep=False)
    if task.snapshot_fields is not None:
        drop = [n for n, v in ds.data_vars.items()
                if "snapshot_time" in v.dims and n not in task.snapshot_fields]
        ds = ds.drop_vars(drop)
    encoding: dict[str, Any] = {}
    for name, var in ds.data_vars.items():
        if var.ndim >= 2:
            encoding[str(name)] = {"zlib": True, "complevel": 4}
            if task.snapshot_dtype == "float32" and var.dtype.kind == "f":
                ds[name] = var.astype("float32")
    ds.attrs.update(run_id=task.run_id, campaign=task.campaign,
                    identity_schema=SCHEMA_VERSION)
    return ds, encoding


def _failure(task: RunTask, reason: str, detail: str, tb: str, wall: float) -> Record:
    return {"run_id": task.run_id, "status": "failed", "reason": reason, "detail": detail,
            "t_failed": None, "traceback": tb, "seed": task.seed, "wall_time": wall,
            "nc_bytes": None, "scalars": {}, "code_version": "", "git_commit": "",
            "finished": now_iso(), "host": socket.gethostname()}


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


def _unsaved(task: RunTask, error: StorageError, ds: xr.Dataset | None,
             encoding: Mapping[str, Any], wall: float) -> Record:
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
            detail += f"; the result is kept in {path} (moved into the results folder by " \
                      "the next run)"
        except (OSError, StoreError) as e:
            detail += f"; it could not be kept elsewhere either ({e})"
            with contextlib.suppress(OSError):
                path.parent.rmdir()
    record = _failure(task, "storage", detail, "", wall)
    record.update(status=UNSAVED, saved_to=saved_to, storage_error=str(error))
    return record


#: glibc's mallopt parameters and the values :func:`restore_heap_reuse` sets
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20  # glibc's largest allowed value on 64-bit systems
_TRIM_THRESHOLD = 64 << 20


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
    name = ctypes.util.find_library("c")
    if not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))


def execute_run(task: RunTask) -> Record:
    """Run one simulation on a worker; write ``<run_id>.nc`` then ``<run_id>.json``
    atomically; return the record. A run the model reports as failed keeps its (partial)
    Dataset; a Python exception becomes a record with reason ``"exception"`` and the
    traceback. A result that cannot be stored (a :class:`StorageError`: disk full,
    read-only, file size limit) is not a failure of the run: no record is written (the run
    stays pending), the Dataset is kept in :func:`spool_dir` if possible, and the returned
    record has status :data:`UNSAVED` with the cause (the driver stops)."""
    from model.simulate import run as simulate

    restore_heap_reuse()
    store = CampaignStore(Path(task.runs_dir).parent.parent, Path(task.runs_dir).parent.name)
    t0 = time.perf_counter()
    try:
        ds = simulate(Parameters.from_dict(task.parameters), Numerics.from_dict(task.numerics),
                      task.seed)
    except Exception as e:  # noqa: BLE001 - any crash is recorded, the campaign goes on
        record = _failure(task, "exception", f"{type(e).__name__}: {e}", traceback.format_exc(),
                          time.perf_counter() - t0)
    else:
        encoding: dict[str, Any] = {}
        try:
            ds, encoding = prepare_dataset(ds, task)
            path = store.nc_path(task.run_id)
            atomic_to_netcdf(ds, path, encoding)
            stamp = file_stamp(path)
            record = record_from_dataset(ds, task.run_id, stamp["nc_bytes"], stamp)
            if record.get("wall_time") is None:
                record["wall_time"] = time.perf_counter() - t0
        except StorageError as e:
            return _unsaved(task, e, ds, encoding, time.perf_counter() - t0)
        except Exception as e:  # noqa: BLE001 - a bug, not the storage: recorded as failed
            record = _failure(task, "write_error", f"{type(e).__name__}: {e}",
                              traceback.format_exc(), time.perf_counter() - t0)
    record.update(parameters=task.parameters, numerics=task.numerics, coords=task.coords,
                  campaign=task.campaign, pid=os.getpid())
    try:
        store.write_record(record)
    except StorageError as e:
        return _unsaved(task, e, None, {}, time.perf_counter() - t0)
    return record


def warm_kinds(expansion: Expansion) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """One ``(parameters, numerics)`` per distinct kind of run in the campaign (mechanics,
    scheme, incompressibility, adaptivity): what :func:`warm_worker` compiles."""
    kinds: dict[tuple[Any, ...], tuple[dict[str, Any], dict[str, Any]]] = {}
    for point in expansion.points:
        n = point.numerics
        key = (n.mechanics, n.scheme, n.incompressible, n.adaptive)
        if key not in kinds:
            kinds[key] = (point.parameters.to_dict(), n.to_dict())
    return list(kinds.values())


def warm_worker(kinds: list[tuple[dict[str, Any], dict[str, Any]]]) -> dict[str, Any]:
    """Run on one worker per host before the campaign: compiles the model's kernels (or
    loads them from the disk cache) with tiny runs, so that the other workers load them
    instead of all compiling at once (:mod:`model.warmup`)."""
    from model.warmup import warm_up

    info = warm_up([(Parameters.from_dict(p), Numerics.from_dict(n)) for p, n in kinds])
    info["host"] = socket.gethostname()
    return info


def warm_workers(client: Client, expansion: Expansion) -> list[dict[str, Any]]:
    """:func:`warm_worker` on one worker of each host (in parallel across hosts); returns
    what each reported. A worker that cannot run it is left to fail in the environment
    check that follows."""
    hosts: dict[str, str] = {}
    for addr, info in client.scheduler_info().get("workers", {}).items():
        hosts.setdefault(str(info.get("host", addr)), addr)
    kinds = warm_kinds(expansion)
    token = uuid.uuid4().hex[:12]  # a shared scheduler may warm several campaigns at once
    futures = [client.submit(warm_worker, kinds, workers=[addr], pure=False,
                             allow_other_workers=False, key=f"nematic-warmup-{token}-{i}")
               for i, addr in enumerate(hosts.values())]
    out = []
    for fut in futures:
        try:
            out.append(fut.result())
        except Exception as e:  # noqa: BLE001 - reported by the environment check
            log.warning("warm-up failed on a worker: %s: %s", type(e).__name__, e)
    return out


# --------------------------------------------------------------------------- planning
@dataclass
class Plan:
    """What is on disk for a campaign's runs, and what remains to do (run positions)."""

    todo: list[int]
    done: list[int]
    failed: list[int]
    records: dict[str, Record]
    adopted: int = 0
    #: results moved in from the spool (written elsewhere when the folder could not be)
    unspooled: int = 0
    #: runs whose record or file was unusable (missing, truncated, corrupt): (run_id, why)
    redone: list[tuple[str, str]] = field(default_factory=list)

    @property
    def discarded(self) -> int:
        return len(self.redone)


def plan_runs(expansion: Expansion, store: CampaignStore, *, retry_failed: bool = False,
              verify: bool = False) -> Plan:
    """Classify every run: done (skipped), failed (skipped unless ``retry_failed``), to do.

    A record whose file is missing, truncated or corrupt (:meth:`CampaignStore.check_run_file`;
    ``verify`` checksums every file) is discarded and its run redone; a ``.nc`` without a
    record is adopted if it opens, else deleted; a record of a result that could not be
    written (reason ``write_error``) is redone.
    """
    unspooled = import_spool(store)
    records = store.scan()
    plan = Plan(todo=[], done=[], failed=[], records=records, unspooled=unspooled)
    for i, rid in enumerate(expansion.run_ids):
        rec = records.get(rid)
        if rec is None and rid in store.nc_present:
            rec = store.adopt(rid)
            if rec is not None:
                plan.adopted += 1
        problem = None if rec is None else store.check_run_file(rid, rec, verify=verify)
        if rec is not None and problem is not None:
            log.warning("run %s: %s; it will be redone", rid, problem)
            store.discard(rid)
            records.pop(rid, None)
            plan.redone.append((rid, problem))
            rec = None
        elif rec is not None and rec.get("nc_bytes") is not None and (
                not rec.get("nc_sha256") or rec.get("nc_mtime_ns") != _mtime(store, rid)):
            store.refresh_stamp(rid)  # intact, but copied or checksum-less: stat next time
        if rec is None:
            plan.todo.append(i)
        elif rec.get("status") == "ok":
            plan.done.append(i)
        elif retry_failed or rec.get("reason") in RETRYABLE_REASONS:
            plan.todo.append(i)
        else:
            plan.failed.append(i)
    return plan


def import_spool(store: CampaignStore) -> int:
    """Move the results the workers kept in :func:`spool_dir` (the folder could not be
    written) into the results folder, where the plan adopts them; return how many. Raises
    :class:`StorageError` if the folder still cannot be written."""
    import shutil

    spool = spool_dir(store.runs_dir)
    try:
        files = sorted(spool.glob("*.nc"))
    except OSError:
        return 0
    n = 0
    for src in files:
        target = store.nc_path(src.stem)
        if not target.exists() and store.read_record(src.stem) is None:
            with atomic_path(target) as tmp:
                shutil.copyfile(src, tmp)
            n += 1
        with contextlib.suppress(OSError):
            src.unlink()
    with contextlib.suppress(OSError):
        spool.rmdir()
    if n:
        log.info("moved %d result(s) kept in %s into %s", n, spool, store.runs_dir)
    return n


def _mtime(store: CampaignStore, run_id: str) -> int | None:
    try:
        return store.nc_path(run_id).stat().st_mtime_ns
    except OSError:
        return None


# --------------------------------------------------------------------------- clusters
@contextlib.contextmanager
def dask_client(execution: ExecutionSpec, *, timeout: float = 30.0,
                dashboard: bool = False, campaign_dir: Path | None = None) -> Iterator[Client]:
    """A dask ``Client`` for the campaign's execution section (closed on exit); see
    :func:`sweep.workforce.open_cluster`."""
    with open_cluster(execution, timeout=timeout, dashboard=dashboard,
                      campaign_dir=campaign_dir) as force:
        yield force.client


def make_cluster(execution: ExecutionSpec, campaign_dir: Path | None = None) -> Any:
    """The dask-jobqueue cluster of ``execution.cluster`` as ``nematic run`` makes it (TLS,
    dashboard, job logs; not scaled: no job is submitted), e.g. to inspect ``job_script()``.
    Without ``campaign_dir`` the TLS credential files go to a private folder of the
    temporary directory."""
    import tempfile

    assert execution.cluster is not None
    if campaign_dir is None:
        campaign_dir = Path(tempfile.gettempdir()) / f"nematic-jobscript-{os.getuid()}"
    options, _ = jobqueue_options(execution.cluster, execution, campaign_dir)
    return make_jobqueue(execution.cluster, options)


# --------------------------------------------------------------------------- the driver
def dashboard_link(client: Client, timeout: float = 5.0) -> str | None:
    """The link of the dask dashboard if it answers from here, else ``None`` (started
    without it, bokeh not installed where the scheduler runs, or not reachable: the
    scheduler's HTTP server then answers 404 for the page, or not at all)."""
    import urllib.error
    import urllib.request

    try:
        link = str(client.dashboard_link)
        with urllib.request.urlopen(link, timeout=timeout) as response:  # noqa: S310 - http
            return link if response.status == 200 else None
    except (OSError, ValueError, urllib.error.URLError):
        return None


class RunEvents(Protocol):
    """What the driver reports (the CLI draws the progress bar from these)."""

    def started(self, plan: Plan, total: int, workers: int) -> None: ...

    def finished_run(self, run: RunSpec, record: Record) -> None: ...


@dataclass
class RunSummary:
    total: int
    skipped: int
    submitted: int = 0
    ok: int = 0
    failed: list[tuple[RunSpec, Record]] = field(default_factory=list)
    failed_before: int = 0
    #: runs whose dask task was cancelled under them (scheduler or cluster gone): no record
    lost: list[RunSpec] = field(default_factory=list)
    #: why results cannot be stored (the driver stopped: the runs left stay pending)
    storage_error: str | None = None
    #: results that could not be written where they belong (kept elsewhere if possible)
    unsaved: list[tuple[RunSpec, Record]] = field(default_factory=list)
    interrupted: bool = False
    wall_time: float = 0.0
    run_time: float = 0.0

    @property
    def completed(self) -> int:
        return self.ok + len(self.failed)


def _lost_task_record(task: RunTask, exc: BaseException) -> Record:
    from distributed import KilledWorker

    if isinstance(exc, KilledWorker):
        reason = "killed_worker"
        detail = (f"the run's worker died repeatedly ({exc}); it may exhaust memory or "
                  "crash the interpreter")
    else:
        reason = "exception"
        detail = f"{type(exc).__name__}: {exc}"
    tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    return _failure(task, reason, detail, tb, math.nan)


def run_campaign(expansion: Expansion, store: CampaignStore, client: Client | Workforce,
                 plan: Plan, events: RunEvents | None = None, *,
                 clock: Callable[[], float] = time.monotonic) -> RunSummary:
    """Run ``plan.todo`` on the cluster; return when all are done or on Ctrl-C
    (``KeyboardInterrupt`` is caught: pending runs are cancelled and ``interrupted`` set).

    Waits (bounded) for the first worker, checks every worker that joins and sizes the
    submission window from the accepted workers (:class:`~sweep.workforce.Supervisor`).
    Raises :class:`ClusterError` when the workers cannot run the model or none is left for
    ``execution.give_up_after`` seconds (the runs in flight stay pending)."""
    from distributed import as_completed

    campaign = expansion.campaign
    force = client if isinstance(client, Workforce) else Workforce(client, "the dask cluster")
    client = force.client
    t0 = clock()
    summary = RunSummary(total=len(expansion), skipped=len(plan.done) + len(plan.failed),
                         failed_before=len(plan.failed))
    watch = Supervisor(force, campaign.execution, clock=clock)
    watch.wait_for_first()
    if events and hasattr(events, "warming"):
        events.warming()
    warm0 = clock()
    warmed = warm_workers(client, expansion)
    log.info("warm-up on %d host(s) in %.1f s: %s", len(warmed), clock() - warm0, warmed)
    if events and hasattr(events, "warmed"):
        events.warmed(warmed, clock() - warm0)
    watch.check()
    if events:
        events.started(plan, len(expansion), max(1, watch.threads))
    queue = list(reversed(plan.todo))
    tasks: dict[Any, tuple[RunSpec, RunTask, int]] = {}
    attempts: dict[int, int] = {}
    ac = as_completed()
    last_manifest = clock()

    def submit_more() -> None:
        while queue and ac.count() < watch.window:
            i = queue.pop()
            run = expansion.run(i)
            task = RunTask.from_spec(run, store, campaign.name, campaign.store)
            # a run that goes again (its result was lost) gets a new key: the old one may
            # still be being released
            again = attempts[i] = attempts.get(i, -1) + 1
            key = f"nematic-run-{run.run_id}" + (f"-{again}" if again else "")
            fut = client.submit(execute_run, task, key=key, pure=False)
            tasks[fut.key] = (run, task, i)
            ac.add(fut)
            summary.submitted += 1

    def handle(fut: Any) -> bool:
        """Take one finished future; ``False`` to stop the campaign."""
        run, task, i = tasks.pop(fut.key)
        try:
            record = fut.result(timeout=RESULT_WAIT)
        except OSError as e:
            # Finished, but its result did not arrive: it went with its worker (a batch job
            # ended; dask would recompute it), or the connection to the scheduler broke
            # (TimeoutError, CommClosedError). Not the run's fault: the record on disk says
            # what happened, else the run goes again (or stays pending).
            with contextlib.suppress(Exception):
                fut.cancel()
            record = store.read_record(run.run_id)
            if record is None:
                if client.status == "running":
                    log.warning("the result of run %s was lost with its worker (%s); it "
                                "runs again", run.run_id, type(e).__name__)
                    queue.append(i)
                else:
                    summary.lost.append(run)
                return True
        except CancelledError as e:  # the cluster went away under the run: not its fault
            (log.debug if summary.lost else log.warning)(
                "run %s was cancelled by dask (%s); rerun to redo it", run.run_id,
                " ".join(str(e).split()))
            summary.lost.append(run)
            if client.status != "running":  # the futures are gone with the connection
                if queue or tasks:
                    log.warning("the connection to %s is lost (client %s): the %d run(s) "
                                "left stay pending", force.where, client.status,
                                len(queue) + len(tasks) + 1)
                queue.clear()  # nothing more can be submitted
            return True
        except Exception as e:  # noqa: BLE001 - killed workers, errors outside the run
            record = _lost_task_record(task, e)
            record.update(parameters=task.parameters, numerics=task.numerics,
                          coords=task.coords, campaign=task.campaign)
            store.write_record(record)
        fut.release()
        if record.get("status") == UNSAVED:
            # The results folder cannot take results: stop instead of burning every run.
            # The runs in flight are cancelled: they stay pending, as this one does.
            summary.unsaved.append((run, record))
            summary.storage_error = str(record.get("storage_error") or "")
            queue.clear()
            with contextlib.suppress(Exception):
                client.cancel(list(ac.futures))
            return False
        if record.get("status") == "ok":
            summary.ok += 1
        else:
            summary.failed.append((run, record))
        wall = record.get("wall_time")
        if isinstance(wall, (int, float)) and math.isfinite(wall):
            summary.run_time += float(wall)
        if events:
            events.finished_run(run, record)
        return True

    try:
        submit_more()
        going = True
        while going and (tasks or queue):
            if ac.has_ready():
                for fut in ac.next_batch(block=False):
                    if not handle(fut):
                        going = False
                        break
            else:
                time.sleep(POLL)
            if going and clock() - watch.last_check >= CHECK_EVERY:
                try:
                    watch.check()
                except ClusterError:
                    with contextlib.suppress(Exception):
                        client.cancel(list(ac.futures))
                    raise
            if going:
                submit_more()
            if clock() - last_manifest > MANIFEST_EVERY:
                store.scan()
                last_manifest = clock()
    except KeyboardInterrupt:
        summary.interrupted = True
        log.info("interrupted: cancelling %d pending run(s)", ac.count())
        with contextlib.suppress(Exception):
            client.cancel(list(ac.futures))
    summary.wall_time = clock() - t0
    return summary


class DriveEvents(RunEvents, Protocol):
    def planned(self, plan: Plan, expansion: Expansion) -> None: ...


#: Temporary files younger than this may belong to a cancelled run still finishing on a
#: remote worker: a driver on a remote cluster leaves them (seconds).
REMOTE_TMP_AGE = 600.0


def drive(expansion: Expansion, store: CampaignStore, *, retry_failed: bool = False,
          verify: bool = False,
          events: DriveEvents | None = None,
          dashboard: bool = False) -> tuple[Plan, RunSummary | None]:
    """What ``nematic run`` does while holding the campaign's lock: clean up, record the
    campaign text, plan from disk, run what remains on the campaign's dask cluster and
    refresh the manifest. Returns the plan and the summary (``None`` if nothing was to do;
    ``interrupted`` set on Ctrl-C). Raises :class:`~sweep.errors.ClusterError` if the
    cluster cannot be used."""
    campaign = expansion.campaign
    local = campaign.execution.mode == "local"
    store.clean_temporaries(min_age=0.0 if local else REMOTE_TMP_AGE)
    store.save_campaign_text(campaign.text, campaign.overrides)
    plan = plan_runs(expansion, store, retry_failed=retry_failed, verify=verify)
    if events:
        events.planned(plan, expansion)
    summary = None
    if plan.todo:
        try:
            with open_cluster(campaign.execution, dashboard=dashboard,
                              campaign_dir=store.root) as force:
                if dashboard and events and hasattr(events, "dashboard"):
                    events.dashboard(dashboard_link(force.client))
                summary = run_campaign(expansion, store, force, plan, events)
        except KeyboardInterrupt:  # while the cluster was starting or closing
            summary = RunSummary(total=len(expansion), skipped=len(plan.done) + len(plan.failed),
                                 failed_before=len(plan.failed), interrupted=True)
        finally:
            if local:  # the local workers are gone: whatever they left half-written goes
                store.clean_temporaries()
    store.scan()
    return plan, summary


def describe_failure(run: RunSpec, record: Mapping[str, Any]) -> str:
    """One line: the run, its swept values and seed, why and when it failed."""
    coords = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in run.coords.items())
    when = record.get("t_failed")
    at = f" at t = {when:.4g}" if isinstance(when, (int, float)) and math.isfinite(when) else ""
    detail = str(record.get("detail") or "").strip().splitlines()
    return (f"run {run.run_id} ({coords}) failed: {record.get('reason') or 'unknown'}{at}"
            + (f": {detail[-1]}" if detail else ""))
