"""How long a batch job's dask worker lives, derived from the job's walltime, so that it
retires cleanly before the batch system kills it.

The rule (:func:`worker_lifetime`), for a walltime ``W``:

- stagger ``S = min(W / 20, 5 min)``: each worker's lifetime is drawn uniformly from
  ``[L - S, L + S]`` (dask's ``--lifetime-stagger``), so the jobs of a campaign do not all
  retire at once;
- grace ``G = min(60 s, W / 4)``: what the retirement needs (the worker hands its runs back
  to the scheduler and exits, the job ends) plus the job's start before the worker's clock;
- lifetime ``L = W - S - G`` (dask's ``--lifetime``): the latest retirement is at
  ``W - G``, the earliest at ``W - 2 S - G``.

A worker that retires hands the runs it has in flight back to the scheduler, which runs
them again on another worker (not a failure, not counted against
:data:`nematic_solids.sweep.run.clusters.WORKER_LOSSES`): a job loses at most one run per worker
thread, and a run longer than the earliest retirement (``W - 2 S - G``) can never finish in a job.

The driver adds ``--lifetime`` and ``--lifetime-stagger`` to the job's
``worker_extra_args``, unless they already name ``--lifetime`` (``[--lifetime, "0"]``
turns retirement off). The batch jobs that end are replaced by
:class:`nematic_solids.sweep.run.workers.JobWatch`, so the cluster keeps its jobs.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

#: Caps of the rule above (seconds).
MAX_STAGGER = 300.0
MAX_GRACE = 60.0

_CLOCK = re.compile(r"^(?:(\d+)-)?(\d+)(?::(\d+))?(?::(\d+))?$")


def walltime_seconds(text: Any) -> float | None:
    """A batch walltime in seconds: ``"HH:MM:SS"``, ``"MM:SS"``, ``"D-HH[:MM[:SS]]"``,
    ``"MM"`` (SLURM's minutes), or a number of seconds; ``None`` if it is none of these."""
    if isinstance(text, bool):
        return None
    if isinstance(text, (int, float)):
        return float(text) if text > 0 else None
    m = _CLOCK.match(str(text).strip())
    if not m:
        return None
    days, *parts = m.groups()
    fields = [int(p) for p in parts if p is not None]
    if days is not None:  # D-HH, D-HH:MM, D-HH:MM:SS
        h, mi, s = (fields + [0, 0])[:3]
    elif len(fields) == 1:  # minutes
        h, mi, s = 0, fields[0], 0
    elif len(fields) == 2:  # MM:SS
        h, mi, s = 0, *fields
    else:
        h, mi, s = fields
    seconds = 86400.0 * int(days or 0) + 3600.0 * h + 60.0 * mi + s
    return seconds if seconds > 0 else None


def lifetime_rule(walltime: float) -> tuple[float, float]:
    """``(lifetime, stagger)`` in seconds for a walltime of ``walltime`` seconds."""
    stagger = min(walltime / 20.0, MAX_STAGGER)
    grace = min(MAX_GRACE, walltime / 4.0)
    return walltime - stagger - grace, stagger


def worker_lifetime(kind: str, options: Mapping[str, Any]) -> tuple[list[str], str | None]:
    """The job's ``worker_extra_args`` with ``--lifetime`` and ``--lifetime-stagger`` from its
    walltime (``options["walltime"]``, else dask-jobqueue's configured default for
    ``kind``), and a line for the log (``None`` when nothing was added: no walltime, or the
    arguments already name ``--lifetime``)."""
    import dask
    import dask_jobqueue  # noqa: F401 - loads its configuration (the default walltimes)

    extra = options.get("worker_extra_args")
    if extra is None:
        extra = dask.config.get(f"jobqueue.{kind}.worker-extra-args", None) or []
    extra = [str(a) for a in extra]
    if any(a == "--lifetime" or a.startswith("--lifetime=") for a in extra):
        return extra, None
    given = options.get("walltime")
    if given is None:
        given = dask.config.get(f"jobqueue.{kind}.walltime", None)
    walltime = walltime_seconds(given)
    if walltime is None:
        return extra, None
    lifetime, stagger = lifetime_rule(walltime)
    args = [*extra, "--lifetime", f"{lifetime:.0f}s", "--lifetime-stagger", f"{stagger:.0f}s"]
    return args, (
        f"batch workers retire after {lifetime:.0f} s +- {stagger:.0f} s of their "
        f"walltime {given} ({walltime:.0f} s); their jobs are then replaced"
    )
