"""Starting a campaign's dask cluster: :func:`open_cluster` starts (or connects to) the
cluster of its ``execution`` section: an embedded ``LocalCluster``, an external scheduler or
a dask-jobqueue cluster. A scheduler the driver starts itself uses TLS with temporary
credentials made for this campaign (``distributed.Security.temporary()``; a batch job reads
the worker's copy from files that only the campaign's owner can read, in ``<campaign>/tls``),
unless ``execution.security`` opts out with a stated reason, and serves its dashboard on
127.0.0.1 only. The cluster is then watched by
:class:`~nematic_solids.sweep.run.workers.Supervisor`. As a local cluster closes, its workers drop
one known message of distributed's, a heartbeat that met the closing scheduler
(:func:`quiet_heartbeats`), so that a campaign that succeeded prints no traceback.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..campaign import CLUSTER_KINDS, ClusterSpec, ExecutionSpec, local_worker_count
from ..errors import ClusterError
from .lifetime import worker_lifetime
from .workers import JOB_LOGS, TLS_DIR, ClusterLink, JobWatch

log = logging.getLogger(__name__)

#: A run whose worker is lost under it (the process dies: a batch job cancelled, preempted
#: or past its walltime, a crash) is run again by the scheduler the driver starts, at most
#: this many times (dask's ``allowed-failures``); then it stays pending (no record: not a
#: failure of the run) and the driver says so. A worker that retires (its lifetime,
#: :mod:`nematic_solids.sweep.run.lifetime`) hands its runs back without counting.
WORKER_LOSSES = 3


def worker_lost(exc: BaseException) -> bool:
    """Whether ``exc`` (what a run's task ended with) says its worker was lost under it more
    often than the scheduler retries it (:data:`WORKER_LOSSES`): not a failure of the run."""
    from distributed import KilledWorker

    return isinstance(exc, KilledWorker)


def _security(execution: ExecutionSpec) -> Any:
    if not execution.tls:
        log.warning(
            "the campaign's dask scheduler runs without TLS (execution.security: %s)",
            execution.insecure_reason,
        )
        return None
    from distributed import Security

    try:
        return Security.temporary()
    except ImportError as e:
        raise ClusterError(
            f"TLS for the dask scheduler needs the 'cryptography' package "
            f"({e}); install it, or set execution.security: {{tls: false, "
            "reason: ...}"
        ) from None


def private_dir(path: Path) -> Path:
    """``path`` created if needed, readable by its owner only (0700)."""
    path.mkdir(parents=True, exist_ok=True)
    os.chmod(path, 0o700)
    return path


def jobqueue_options(
    spec: ClusterSpec, execution: ExecutionSpec, campaign_dir: Path | None
) -> tuple[dict[str, Any], Path | None]:
    """The keyword arguments of the dask-jobqueue class (security, the dashboard on
    127.0.0.1, the job logs in the campaign's folder unless the YAML says otherwise) and the
    job log folder."""
    options = dict(spec.options)
    if options.get("log_directory") is None and campaign_dir is not None:
        options["log_directory"] = str(campaign_dir / JOB_LOGS)
    logs = (
        Path(os.path.expandvars(str(options["log_directory"]))).expanduser()
        if options.get("log_directory")
        else None
    )
    if logs is not None:
        with contextlib.suppress(OSError):
            logs.mkdir(parents=True, exist_ok=True)
    scheduler_options = dict(options.get("scheduler_options") or {})
    scheduler_options.setdefault("dashboard_address", "127.0.0.1:0")
    scheduler_options.setdefault("allowed_failures", WORKER_LOSSES)
    extra, retiring = worker_lifetime(spec.kind, options)
    if retiring is not None:
        options["worker_extra_args"] = extra
        log.info("%s", retiring)
    options["scheduler_options"] = scheduler_options
    security = _security(execution)
    if security is not None:
        options["security"] = security
        if options.get("shared_temp_directory") is None:
            if campaign_dir is None:
                raise ClusterError(
                    "TLS credentials for the batch jobs need the campaign's "
                    "folder (or execution.cluster.shared_temp_directory)"
                )
            options["shared_temp_directory"] = str(private_dir(campaign_dir / TLS_DIR))
    return options, logs


def make_jobqueue(spec: ClusterSpec, options: dict[str, Any]) -> Any:
    import dask_jobqueue

    cls = getattr(dask_jobqueue, CLUSTER_KINDS[spec.kind])
    try:
        return cls(**options)
    except (ValueError, TypeError, OSError, RuntimeError) as e:
        raise ClusterError(f"cannot set up the {cls.__name__} of execution.cluster: {e}") from None


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


@contextlib.contextmanager
def open_cluster(
    execution: ExecutionSpec,
    *,
    timeout: float = 30.0,
    dashboard: bool = False,
    campaign_dir: Path | None = None,
) -> Iterator[ClusterLink]:
    """The campaign's cluster (closed on exit): an external scheduler, a dask-jobqueue
    cluster (jobs submitted here; logs and TLS credentials in ``campaign_dir``) or a local
    cluster (its dashboard on 127.0.0.1, a free port, if ``dashboard``)."""
    from distributed import Client, LocalCluster

    if execution.scheduler:
        log.info("connecting to the dask scheduler at %s", execution.scheduler)
        try:
            client = Client(execution.scheduler, timeout=timeout)
        except (OSError, ValueError, TypeError) as e:
            raise ClusterError(
                f"cannot reach the dask scheduler at {execution.scheduler}: {e}"
            ) from None
        try:
            yield ClusterLink(client, f"the dask scheduler at {execution.scheduler}")
        finally:
            if client.status != "running":  # the scheduler is gone: its reconnection
                # attempts, cancelled by close(), are no news (nor are their tracebacks)
                logging.getLogger("distributed.client").setLevel(logging.CRITICAL)
            with contextlib.suppress(Exception):
                client.close(timeout=10)
        return
    if execution.cluster is not None:
        spec = execution.cluster
        options, logs = jobqueue_options(spec, execution, campaign_dir)
        cls_name = CLUSTER_KINDS[spec.kind]
        log.info("starting a dask-jobqueue %s (job logs in %s)", cls_name, logs)
        with make_jobqueue(spec, options) as cluster:
            if spec.adapt:
                # at least one job: the driver submits runs once a worker has passed the
                # check, and dask's adaptive scaling starts jobs only for submitted runs
                cluster.adapt(minimum_jobs=max(1, spec.adapt[0]), maximum_jobs=spec.adapt[1])
            else:
                cluster.scale(jobs=spec.jobs)
            with Client(cluster) as client:
                yield ClusterLink(
                    client, f"the dask-jobqueue {cls_name}", JobWatch(cluster, spec, logs)
                )
        return
    n = local_worker_count(execution)
    log.info("starting a local dask cluster: %d worker process(es)", n)
    kwargs: dict[str, Any] = {}
    if execution.memory_limit:
        kwargs["memory_limit"] = execution.memory_limit
    security = _security(execution)
    if security is not None:
        kwargs.update(security=security, protocol="tls://")
    with _workers_ignore_sigint():
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=execution.threads_per_worker,
            processes=True,
            host="127.0.0.1",
            # the scheduler's HTTP server (health, metrics; the dashboard
            # if asked for) on the loopback interface, a free port
            dashboard_address="127.0.0.1:0",
            scheduler_kwargs={"dashboard": dashboard, "allowed_failures": WORKER_LOSSES},
            silence_logs=logging.ERROR,
            **kwargs,
        )
    with cluster, Client(cluster) as client:
        try:
            yield ClusterLink(client, "the local dask cluster")
        finally:
            quiet_heartbeats(client)


#: What a worker's heartbeat logs, with a traceback, when it cannot reach the scheduler
#: (``distributed.worker``, level ERROR): at the local cluster's shutdown, under load, a
#: worker's last heartbeat can meet the scheduler closing; the campaign is over by then.
HEARTBEAT_FAILURE = "Failed to communicate with scheduler during heartbeat"


class _HeartbeatAtShutdown(logging.Filter):
    """Drops :data:`HEARTBEAT_FAILURE` (that message only) in a worker process whose cluster
    is closing."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(HEARTBEAT_FAILURE)


def _drop_heartbeat_failures() -> None:
    """Run in each local worker process as its cluster closes (:func:`quiet_heartbeats`)."""
    worker_log = logging.getLogger("distributed.worker")
    if not any(isinstance(f, _HeartbeatAtShutdown) for f in worker_log.filters):
        worker_log.addFilter(_HeartbeatAtShutdown())


def quiet_heartbeats(client: Any) -> None:
    """Before the local cluster closes: its workers stop reporting a heartbeat that fails
    because the scheduler is closing (:data:`HEARTBEAT_FAILURE`, a traceback on the
    campaign's stderr otherwise); every other message of theirs stays. Best effort: a worker
    that does not answer is closed anyway."""
    with contextlib.suppress(Exception):
        client.run(_drop_heartbeat_failures, on_error="return")


@contextlib.contextmanager
def _workers_ignore_sigint() -> Iterator[None]:
    """Start local worker processes with SIGINT ignored (the disposition is inherited across
    exec, and Python then installs no KeyboardInterrupt handler): a terminal's Ctrl-C reaches
    the whole process group, but only the driver should react, by cancelling the runs and
    closing the cluster cleanly."""
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
