"""The driver's workers: watching the campaign's dask cluster while it runs (the cluster is
started by :mod:`nematic_solids.sweep.run.clusters`).

:class:`Supervisor` is what the driver asks, every couple of seconds, while runs are in
flight: it checks each worker that joins (it imports the model, its code version is the
driver's) and refuses the others, sizes the submission window from the accepted workers'
threads, replaces batch jobs that ended (walltime, ``scancel``, preemption, a crash) and
gives up with a :class:`~nematic_solids.sweep.errors.ClusterError` when no usable worker is left for
``execution.give_up_after`` seconds, or at once when every batch job dies before its worker
joins (a broken worker environment), quoting the last error found in the job logs.
"""

from __future__ import annotations

import contextlib
import getpass
import logging
import math
import os
import re
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..campaign import DEFAULT_MODEL, ClusterSpec, ExecutionSpec
from ..errors import ClusterError
from ..models.interface import Compiled
from ..models.registry import get_model

if TYPE_CHECKING:
    from distributed import Client

log = logging.getLogger(__name__)


class _GatherEndedByClose(logging.Filter):
    """Drop asyncio's "Task exception was never retrieved" report of a result fetch that a
    closing client ended (distributed's ``AllExit``): a fetch given up after its timeout leaves
    such a task behind, and its end at shutdown is expected, not an error (the run's record
    on disk holds the result)."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return not (exc is not None and type(exc).__name__ == "AllExit")


logging.getLogger("asyncio").addFilter(_GatherEndedByClose())

#: Runs in flight per worker thread (keeps the scheduler's queue short for 10^5 runs).
INFLIGHT_PER_THREAD = 4
MIN_INFLIGHT = 8
#: How often the supervisor looks at the workers and the batch jobs (seconds).
CHECK_EVERY = 2.0
#: While waiting for workers: a line this often (seconds).
WAIT_REPORT_EVERY = 60.0
#: Folder of the campaign (under its results folder) for the batch jobs' logs, unless
#: ``execution.cluster.log_directory`` says otherwise; and for the TLS credential files.
JOB_LOGS = "jobs"
TLS_DIR = "tls"
#: Lines of a job log that report an error (the last one is quoted when giving up).
ERROR_LINE = re.compile(
    r"\w*(Error|Exception)\b|\b(error|ERROR|FATAL|Killed)\b|CANCELLED|"
    r"No such file|command not found|[Pp]ermission denied"
)


def scheduler_workers(client: Client) -> dict[str, dict[str, Any]]:
    """The workers the scheduler knows now (address -> its information), asked of the
    scheduler itself. Not ``client.scheduler_info()``: the client's periodic refresh of the
    cache that call returns asks for no workers, and can overwrite the answer before it is
    returned, so that every worker seems to have left (22 of 3,000 calls with the refresh at
    5 ms, distributed 2026.8; at the default 2 s, the "worker left" warnings of a busy
    machine, tests/sweep/test_workers.py)."""
    scheduler = client.scheduler
    if scheduler is None:  # a closed client: no worker it can reach
        return {}
    identity = client.sync(scheduler.identity, n_workers=-1)
    return dict(identity.get("workers", {}))


def window_size(threads: int) -> int:
    """Runs kept in flight for ``threads`` worker threads."""
    return max(MIN_INFLIGHT, INFLIGHT_PER_THREAD * threads)


# --------------------------------------------------------------------------- worker check
#: One import of the model at a time in a worker process. The environment check and a run
#: that arrives with it (a run handed back by a retired worker goes to the next worker at
#: once) would import it from two threads, and Python's module locks can break that with a
#: ``_DeadlockError`` in one of them (seen: a worker refused, "deadlock detected by
#: _ModuleLock('pde.solvers.base')").
_MODEL_IMPORT = threading.Lock()


def import_model(name: str = DEFAULT_MODEL) -> None:
    """Import the model ``name`` (the nematic model: py-pde, numba, the kernels' modules) in
    this process, once."""
    with _MODEL_IMPORT:
        model = get_model(name)
        if isinstance(model, Compiled):
            model.import_kernels()


def worker_environment() -> dict[str, Any]:
    """Run on every worker that joins: proves the model imports there; returns its versions."""
    from ..provenance import environment

    import_model()  # the import is the check

    return environment()


def refusal(env: Any, mine: dict[str, Any]) -> str | None:
    """Why a worker that reported ``env`` (or raised it) cannot run this campaign, or ``None``."""
    if isinstance(env, BaseException):
        return (
            f"it cannot run the model ({type(env).__name__}: {env}); install this "
            "package in the workers' environment"
        )
    if not isinstance(env, dict):
        return f"it answered the environment check with {env!r}"
    if env.get("code_version") != mine.get("code_version"):
        return (
            f"its code version is {env.get('code_version')!r}, the driver's is "
            f"{mine.get('code_version')!r}: install the same version of this package "
            "on both sides"
        )
    theirs, ours = str(env.get("git_commit") or ""), str(mine.get("git_commit") or "")
    if theirs and ours and "unknown" not in (theirs, ours) and theirs != ours:
        return (
            f"its code is at commit {theirs}, the driver's at {ours}: the workers must run "
            "the driver's checkout (a shared filesystem) or the same commit"
        )
    return None


# --------------------------------------------------------------------------- job logs
def last_worker_error(log_directory: Path | None, newest: int = 20) -> tuple[str, Path] | None:
    """The last error line of the newest job logs in ``log_directory`` (and its file), or
    ``None`` when no log there reports one."""
    if log_directory is None:
        return None
    try:
        files = sorted(
            (p for p in log_directory.iterdir() if p.is_file()),
            key=lambda p: p.stat().st_mtime,
            reverse=True,
        )[:newest]
    except OSError:
        return None
    for path in files:
        try:
            with open(path, "rb") as f:
                f.seek(max(0, f.seek(0, os.SEEK_END) - 65536))
                lines = f.read().decode("utf-8", "replace").splitlines()
        except OSError:
            continue
        for line in reversed(lines):
            if ERROR_LINE.search(line.strip()):
                return line.strip()[:300], path
    return None


# --------------------------------------------------------------------------- batch jobs
class JobWatch:
    """The batch jobs of a dask-jobqueue cluster: notices the jobs that ended, and submits
    replacements, so that the cluster keeps ``jobs`` (or what ``adapt`` asked for).

    SLURM: a job has ended once ``squeue`` no longer lists it. Other batch systems: once its
    worker has left the scheduler for ``distributed.deploy.lost-worker-timeout`` (dask drops
    it then); a job that ends before its worker ever joins is noticed on SLURM only (elsewhere
    the driver gives up after ``execution.give_up_after``).
    """

    def __init__(self, cluster: Any, spec: ClusterSpec, log_directory: Path | None):
        self.cluster = cluster
        self.kind = spec.kind
        self.log_directory = log_directory
        #: ids of the jobs whose worker joined
        self.joined: set[str] = set()
        #: jobs that ended before their worker joined, since a worker last joined
        self.failed_starts = 0
        self.ended = 0
        self.replaced = 0
        self.last_ended: str | None = None
        self._reported_queue_error = False

    @property
    def target(self) -> int:
        """Batch jobs the cluster is asked to keep."""
        return len(getattr(self.cluster, "worker_spec", {}) or {})

    def _queued(self) -> set[str] | None:
        if self.kind != "slurm":
            return None
        try:
            out = subprocess.run(
                ["squeue", "-h", "-o", "%i", "-u", getpass.getuser()],
                capture_output=True,
                text=True,
                timeout=30,
                check=True,
            ).stdout
        except (OSError, subprocess.SubprocessError) as e:
            if not self._reported_queue_error:
                log.warning(
                    "cannot list the batch queue (%s); lost jobs are noticed only "
                    "after their workers leave",
                    e,
                )
                self._reported_queue_error = True
            return None
        return {line.strip() for line in out.splitlines() if line.strip()}

    def check(self, worker_names: set[str]) -> None:
        """Note which jobs' workers joined, find the jobs that ended and replace them."""
        jobs = {
            name: str(getattr(job, "job_id", None) or "")
            for name, job in list(self.cluster.workers.items())
        }
        for wname in worker_names:  # a replacement job has its predecessor's name
            job = wname if wname in jobs else wname.rsplit("-", 1)[0]
            if jobs.get(job) and jobs[job] not in self.joined:
                self.joined.add(jobs[job])
                self.failed_starts = 0
        queued = self._queued() if jobs else None
        ended = (
            []
            if queued is None
            else [
                name
                for name, jid in jobs.items()
                if jid
                and jid not in queued
                and not any(w == name or w.startswith(name + "-") for w in worker_names)
            ]
        )
        for name in ended:
            jid = jobs[name]
            self.ended += 1
            self.last_ended = jid
            if jid in self.joined:
                log.warning("batch job %s (%s) ended; submitting a replacement", jid, name)
            else:
                self.failed_starts += 1
                log.warning(
                    "batch job %s (%s) ended before its worker joined%s",
                    jid,
                    name,
                    f" (logs in {self.log_directory})" if self.log_directory else "",
                )
        if ended:

            def drop() -> None:
                for name in ended:
                    self.cluster.workers.pop(name, None)

            self.cluster.loop.add_callback(drop)
        missing = set(self.cluster.worker_spec) - set(jobs) | set(ended)
        if missing and self.cluster.status.name == "running":
            self.replaced += len(ended)
            self.cluster.scale(jobs=len(self.cluster.worker_spec))

    def describe_logs(self) -> str:
        where = (
            f"job logs: {self.log_directory}"
            if self.log_directory
            else "job logs: where the batch system writes them (no log_directory)"
        )
        found = last_worker_error(self.log_directory)
        if found:
            line, path = found
            return f"{where}; last worker error: {line!r} (in {path.name})"
        return f"{where}; no error found in them"


# --------------------------------------------------------------------------- supervisor
@dataclass
class ClusterLink:
    """The driver's link to a running cluster: its client, where it is (for messages) and,
    for a dask-jobqueue cluster, its batch jobs."""

    client: Client
    #: "the dask scheduler at tcp://..." / "the dask-jobqueue SLURMCluster" / ...
    where: str
    jobs: JobWatch | None = None


@dataclass
class Supervisor:
    """Watches the workers while a campaign runs (see the module's docstring)."""

    link: ClusterLink
    execution: ExecutionSpec
    clock: Callable[[], float] = time.monotonic
    mine: dict[str, Any] = field(default_factory=dict)
    accepted: dict[str, int] = field(default_factory=dict)
    refused: dict[str, str] = field(default_factory=dict)
    window: int = MIN_INFLIGHT
    no_worker_since: float | None = None
    last_check: float = -math.inf

    def __post_init__(self) -> None:
        if not self.mine:
            from ..provenance import code_version, git_commit

            self.mine = {"code_version": code_version(), "git_commit": git_commit()}

    @property
    def client(self) -> Client:
        return self.link.client

    @property
    def threads(self) -> int:
        return sum(self.accepted.values())

    def _logs(self) -> str:
        return f"; {self.link.jobs.describe_logs()}" if self.link.jobs else ""

    def check(self, *, running: bool = True) -> None:
        """Look at the workers and jobs now; raise :class:`ClusterError` to give up."""
        now = self.clock()
        self.last_check = now
        status = getattr(self.client, "status", "running")
        if status not in ("running", "newly-created"):
            self._no_workers(now, f"the connection to {self.link.where} is lost (client {status})")
            return
        try:
            info = scheduler_workers(self.client)
        except Exception as e:  # noqa: BLE001 - the scheduler went away: judged by time
            self._no_workers(now, f"{self.link.where} does not answer ({type(e).__name__}: {e})")
            return
        for addr in list(self.accepted):
            if addr not in info:
                del self.accepted[addr]
                log.warning("worker %s left (%d worker(s) remain)", addr, len(self.accepted))
        new = [a for a in info if a not in self.accepted and a not in self.refused]
        if new:
            self._check_workers(new, info)
        if self.link.jobs is not None:
            self.link.jobs.check({str(w.get("name", "")) for w in info.values()})
        self.window = window_size(self.threads)
        if self.accepted:
            self.no_worker_since = None
            return
        if self.refused and not self.accepted:
            reasons = sorted(set(self.refused.values()))
            raise ClusterError(
                f"refusing the workers of {self.link.where}: "
                f"{len(self.refused)} worker(s) joined and none can run this "
                f"campaign: {reasons[0]}" + self._logs()
            )
        jobs = self.link.jobs
        if jobs is not None and jobs.failed_starts >= 2 * max(1, jobs.target):
            raise ClusterError(
                f"every batch job of {self.link.where} ends before its dask "
                f"worker joins ({jobs.failed_starts} in a row, the last job "
                f"{jobs.last_ended}){self._logs()}. Fix the workers' "
                "environment (execution.cluster: python or "
                "job_script_prologue) and rerun the same command: finished "
                "runs are kept"
            )
        if running:
            self._no_workers(now, f"no worker is left in {self.link.where}")

    def _no_workers(self, now: float, why: str) -> None:
        if self.no_worker_since is None:
            self.no_worker_since = now
            log.warning(
                "%s; giving up after %g s without a worker (execution.give_up_after)",
                why,
                self.execution.give_up_after,
            )
        elif now - self.no_worker_since >= self.execution.give_up_after:
            raise ClusterError(
                f"{why} and none came back within "
                f"{self.execution.give_up_after:g} s "
                f"(execution.give_up_after){self._logs()}. The finished runs "
                "are kept: rerun the same command to resume"
            )

    def _check_workers(self, addrs: list[str], info: dict[str, Any]) -> None:
        try:
            envs = self.client.run(worker_environment, workers=addrs, on_error="return")
        except Exception as e:  # noqa: BLE001 - e.g. a worker that left meanwhile: next time
            log.debug("worker check postponed: %s", e)
            return
        for addr in addrs:
            if addr not in envs:
                continue
            why = refusal(envs[addr], self.mine)
            if why is None:
                self.accepted[addr] = int(info.get(addr, {}).get("nthreads", 1) or 1)
                log.info(
                    "worker %s joined (%d thread(s)); %d worker(s), window %d",
                    addr,
                    self.accepted[addr],
                    len(self.accepted),
                    window_size(self.threads),
                )
            else:
                self.refused[addr] = why
                log.warning("refusing worker %s: %s", addr, why)
                with contextlib.suppress(Exception):
                    self.client.retire_workers([addr], close_workers=True)

    def wait_for_first(self) -> None:
        """Return once an accepted worker is there. Without one after
        ``execution.wait_for_workers`` seconds raise :class:`ClusterError` (0: wait for
        ever, with a line every :data:`WAIT_REPORT_EVERY` seconds); refuse at once when the
        workers that join cannot run the model or every batch job dies on start."""
        limit = self.execution.wait_for_workers
        t0 = self.clock()
        last: float | None = None
        while True:
            self.check(running=False)
            if self.accepted:
                return
            now = self.clock()
            if (
                last is None
                and now - t0 >= 1.0
                or last is not None
                and now - last >= WAIT_REPORT_EVERY
            ):
                log.warning(
                    "waiting for a dask worker to join %s (%.0f s so far%s)",
                    self.link.where,
                    now - t0,
                    f", giving up after {limit:g} s" if limit else "",
                )
                last = now
            if limit and now - t0 >= limit:
                if self.execution.scheduler:
                    hint = (
                        f"start workers with `dask worker {self.execution.scheduler} "
                        "--nthreads 1` from this package's environment"
                    )
                else:
                    hint = "check the batch system's queue"
                raise ClusterError(
                    f"no dask worker joined {self.link.where} within "
                    f"{limit:g} s (execution.wait_for_workers){self._logs()}; "
                    f"{hint}, or raise the wait (0 waits for ever)"
                )
            time.sleep(0.5 if now - t0 < 5 else 1.0)
