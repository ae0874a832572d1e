"""The ``execution:`` section: a local dask cluster (workers, threads, memory), an existing
scheduler, or a dask-jobqueue cluster (kind, jobs or adapt bounds, the class's own options),
the waits, TLS (on unless turned off with a stated reason), and the backend that computes the
runs (compiled, or accelerated with seeds in batches on a device)."""

from __future__ import annotations

import inspect
import math
import os
import re
from collections.abc import Mapping
from typing import Any

from nematic_solids.model.accelerated_support import DEVICES, INSTALL, jax_installed

from ..campaign import (
    CLUSTER_KINDS,
    DEFAULT_GIVE_UP,
    DEFAULT_WORKER_WAIT,
    EXECUTION_BACKENDS,
    MAX_BATCH,
    MAX_RUNS_PER_TASK,
    ClusterSpec,
    ExecutionSpec,
)
from ..limits import max_local_workers
from .checker import Checker, KeyPath, is_int, is_number, suggest

EXECUTION_KEYS = (
    "workers",
    "threads_per_worker",
    "memory_limit",
    "scheduler",
    "cluster",
    "wait_for_workers",
    "give_up_after",
    "security",
    "backend",
    "batch",
    "device",
    "runs_per_task",
)
SECURITY_KEYS = ("tls", "reason")
#: Most batch jobs of a dask-jobqueue cluster.
MAX_JOBS = 100_000
SCHEDULER_RE = re.compile(r"^(tcp|tls|inproc|ucx|ws|wss)://\S+$")
#: Arguments of the dask-jobqueue classes that the campaign manager sets itself.
_CLUSTER_RESERVED = {
    "self",
    "scheduler",
    "name",
    "config_name",
    "job_cls",
    "loop",
    "asynchronous",
    "n_workers",
    "base_class_kwargs",
    "job_kwargs",
    "kwargs",
    "security",
}


def cluster_option_names(kind: str) -> list[str]:
    """Keyword arguments the dask-jobqueue cluster class of ``kind`` accepts."""
    import dask_jobqueue
    import dask_jobqueue.core as core

    cls = getattr(dask_jobqueue, CLUSTER_KINDS[kind])
    names: set[str] = set()
    for fn in (cls.job_cls.__init__, core.Job.__init__, core.JobQueueCluster.__init__):
        names.update(inspect.signature(fn).parameters)
    return sorted(names - _CLUSTER_RESERVED)


def read_execution(c: Checker, raw: Any, read: Mapping[str, Any]) -> ExecutionSpec:
    """``execution:`` -> where and how the runs are done."""
    ex = c.mapping(("execution",), raw, EXECUTION_KEYS)
    workers = ex.get("workers")
    most = max_local_workers()
    if workers is not None and (not is_int(workers) or not 1 <= workers <= most):
        c.bad(
            ("execution", "workers"),
            workers,
            f"an integer from 1 to {most} (local worker "
            f"processes; this machine has {os.cpu_count() or 1} core(s))",
        )
        workers = None
    tpw = ex.get("threads_per_worker", 1)
    if not is_int(tpw) or not 1 <= tpw <= most:
        c.bad(("execution", "threads_per_worker"), tpw, f"an integer from 1 to {most}")
        tpw = 1
    memory = ex.get("memory_limit")
    if memory is not None and not isinstance(memory, (str, int)):
        c.bad(("execution", "memory_limit"), memory, "a size such as '4GB', or 'auto'")
        memory = None
    scheduler = ex.get("scheduler")
    if scheduler is not None and (
        not isinstance(scheduler, str) or not SCHEDULER_RE.match(scheduler)
    ):
        c.bad(
            ("execution", "scheduler"),
            scheduler,
            "a dask scheduler address such as 'tcp://10.0.0.1:8786'",
        )
        scheduler = None
    cluster = None
    if ex.get("cluster") is not None:
        cluster = _check_cluster(c, ex["cluster"])
    if scheduler and ex.get("cluster") is not None:
        c.add(("execution", "cluster"), "give either 'scheduler' or 'cluster', not both")
    if (scheduler or ex.get("cluster") is not None) and "workers" in ex:
        c.add(
            ("execution", "workers"),
            "'workers' sizes the local cluster only; with "
            "'scheduler' the cluster is sized elsewhere, with 'cluster' use cluster.jobs",
        )
    wait = ex.get("wait_for_workers", DEFAULT_WORKER_WAIT)
    if not is_number(wait) or not 0 <= wait < math.inf:
        c.bad(
            ("execution", "wait_for_workers"),
            wait,
            "a number of seconds >= 0 (0: wait for ever, with a line every minute)",
        )
        wait = DEFAULT_WORKER_WAIT
    give_up = ex.get("give_up_after", DEFAULT_GIVE_UP)
    if not is_number(give_up) or not 0 < give_up < math.inf:
        c.bad(
            ("execution", "give_up_after"),
            give_up,
            "a number of seconds > 0 (how long a "
            "running campaign goes on without any usable worker)",
        )
        give_up = DEFAULT_GIVE_UP
    tls, reason = _check_security(c, ex.get("security"))
    if tls and cluster is not None and cluster.options.get("protocol") not in (None, "tls://"):
        c.add(
            ("execution", "cluster", "protocol"),
            f"{cluster.options['protocol']!r} is not "
            "encrypted: the scheduler uses TLS ('tls://') unless execution.security says "
            "{tls: false, reason: ...}",
        )
    backend, batch, device = _check_backend(c, ex, local=not scheduler and cluster is None)
    return ExecutionSpec(
        backend=backend,
        batch=batch,
        device=device,
        runs_per_task=_check_runs_per_task(c, ex, backend),
        workers=workers,
        threads_per_worker=int(tpw),
        memory_limit=None if memory is None else str(memory),
        scheduler=scheduler,
        cluster=cluster,
        wait_for_workers=float(wait),
        give_up_after=float(give_up),
        tls=tls,
        insecure_reason=reason,
    )


def _check_backend(c: Checker, ex: Mapping[str, Any], *, local: bool) -> tuple[str, int, str]:
    """``execution.backend``, ``batch`` and ``device``: batches and devices are the accelerated
    backend's; on a local cluster JAX must be importable here (elsewhere the workers' warm-up
    checks it, with the device)."""
    backend = ex.get("backend", "compiled")
    if backend not in EXECUTION_BACKENDS:
        c.bad(("execution", "backend"), backend, " or ".join(EXECUTION_BACKENDS))
        backend = "compiled"
    batch, device = ex.get("batch", 1), ex.get("device", "auto")
    if not is_int(batch) or not 1 <= batch <= MAX_BATCH:
        c.bad(("execution", "batch"), batch, f"an integer from 1 to {MAX_BATCH} (seeds per task)")
        batch = 1
    if device not in DEVICES:
        c.bad(("execution", "device"), device, ", ".join(DEVICES))
        device = "auto"
    if backend != "accelerated":
        for key in ("batch", "device"):
            if key in ex:
                c.add(
                    ("execution", key),
                    f"'{key}' is the accelerated backend's; give backend: accelerated with it",
                )
    elif local and not jax_installed():
        c.add(
            ("execution", "backend"),
            f"the accelerated backend needs JAX, which is not installed here: {INSTALL}",
        )
    return str(backend), int(batch), str(device)


def _check_runs_per_task(c: Checker, ex: Mapping[str, Any], backend: str) -> int | None:
    """``execution.runs_per_task``: ``auto`` (None, the default: from the cost model) or a
    number of runs of the compiled backend per task (the accelerated one groups by ``batch``)."""
    value = ex.get("runs_per_task", "auto")
    if value == "auto":
        return None
    if not is_int(value) or not 1 <= value <= MAX_RUNS_PER_TASK:
        c.bad(
            ("execution", "runs_per_task"),
            value,
            f"'auto' or an integer from 1 to {MAX_RUNS_PER_TASK} (runs per dask task)",
        )
        return None
    if backend == "accelerated":
        c.add(
            ("execution", "runs_per_task"),
            "the accelerated backend groups the seeds of a point by 'batch', not 'runs_per_task'",
        )
    return int(value)


def _check_security(c: Checker, raw: Any) -> tuple[bool, str | None]:
    """``execution.security``: TLS on (default), or ``{tls: false, reason: ...}``."""
    if raw is None:
        return True, None
    path: KeyPath = ("execution", "security")
    sec = c.mapping(path, raw, SECURITY_KEYS)
    tls = sec.get("tls", True)
    if not isinstance(tls, bool):
        c.bad((*path, "tls"), tls, "true or false")
        return True, None
    reason = sec.get("reason")
    if reason is not None and (not isinstance(reason, str) or not reason.strip()):
        c.bad((*path, "reason"), reason, "a sentence saying why the scheduler may run without TLS")
        return tls, None
    if not tls and reason is None:
        c.add(
            (*path, "tls"),
            "turning TLS off needs a stated reason: add "
            "'reason: <why plain tcp is acceptable here>' (without TLS anyone who can "
            "reach the scheduler can run code as you)",
        )
    return tls, None if reason is None else reason.strip()


def _check_cluster(c: Checker, raw: Any) -> ClusterSpec | None:
    path: KeyPath = ("execution", "cluster")
    if not isinstance(raw, Mapping):
        c.bad(path, raw, "a mapping with 'kind' (" + ", ".join(CLUSTER_KINDS) + ") and options")
        return None
    kind = raw.get("kind")
    if kind not in CLUSTER_KINDS:
        c.bad(
            (*path, "kind"),
            kind,
            "one of "
            + ", ".join(CLUSTER_KINDS)
            + (suggest(kind, list(CLUSTER_KINDS)) if isinstance(kind, str) else ""),
        )
        return None
    valid = cluster_option_names(kind)
    jobs = raw.get("jobs", 1)
    if not is_int(jobs) or not 0 <= jobs <= MAX_JOBS:
        c.bad((*path, "jobs"), jobs, f"an integer from 0 to {MAX_JOBS} (batch jobs to submit)")
        jobs = 1
    adapt = None
    if raw.get("adapt") is not None:
        a = c.mapping((*path, "adapt"), raw["adapt"], ("minimum_jobs", "maximum_jobs"))
        lo, hi = a.get("minimum_jobs", 0), a.get("maximum_jobs")
        if not is_int(lo) or lo < 0:
            c.bad((*path, "adapt", "minimum_jobs"), lo, "an integer >= 0")
        elif hi is None or not is_int(hi) or not max(lo, 1) <= hi <= MAX_JOBS:
            c.bad(
                (*path, "adapt", "maximum_jobs"), hi, f"an integer from max(1, {lo}) to {MAX_JOBS}"
            )
        else:
            adapt = (int(lo), int(hi))  # type: ignore[arg-type]  # checked by _is_int
    options = {}
    for key, value in raw.items():
        if key in ("kind", "jobs", "adapt"):
            continue
        if key not in valid:
            c.unknown(
                (*path, str(key)),
                key,
                ["kind", "jobs", "adapt", *valid],
                f" (options of dask_jobqueue.{CLUSTER_KINDS[kind]})",
            )
        else:
            options[key] = value
    return ClusterSpec(kind=kind, jobs=int(jobs), adapt=adapt, options=options)
