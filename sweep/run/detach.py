"""A campaign's driver in the background, and stopping a running driver.

:func:`start_detached` starts ``nematic run`` (without ``--detach``) in a session of its own
(``setsid``: closing the terminal or logging out does not end it, SIGHUP is ignored) with
its output appended to ``results/<name>/driver.log``, and waits until it holds the
campaign's lock (or has already ended). :func:`stop_driver` ends the driver that holds a
campaign's lock as a batch system does, with SIGTERM, which the driver takes as Ctrl-C: it
cancels the runs in flight (they stay pending: a run file and its record are written whole
or not at all), closes the cluster and releases the lock; a driver running in a SLURM job
on another host is sent the same signal through ``scancel --batch --signal=TERM``.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ClusterError
from ..lock import DRIVER_LOG_ENV, read_lock_holder
from ..store import now_iso

#: The detached driver's output, in the campaign's results folder.
DRIVER_LOG = "driver.log"
#: How long ``run --detach`` waits for the background driver to take the lock (seconds).
START_WAIT = 120.0
#: How long ``nematic stop`` waits for the driver to exit, by default (seconds).
STOP_WAIT = 300.0
POLL = 0.25


@dataclass
class Started:
    """A driver started in the background: its pid, and its exit code if it has already
    ended (``None`` while it runs; ``holds_lock`` says whether it took the lock in time)."""

    pid: int
    log: Path
    returncode: int | None = None
    holds_lock: bool = False


def child_command(*dispositions: str) -> list[str]:
    """``python -m nematic_solids.sweep`` (the arguments to follow) that first runs the
    statements ``dispositions`` (e.g. ``signal.signal(...)``, ``resource.setrlimit(...)``;
    ``signal`` and ``resource`` are imported) in the child itself: a ``preexec_fn`` would do
    it between fork and exec, which the subprocess documentation calls unsafe in a process
    with threads (dask's, JAX's: a lock held at the fork deadlocks the child)."""
    start = "; ".join(
        [
            "import resource, runpy, signal",
            *dispositions,
            "runpy.run_module('nematic_solids.sweep', run_name='__main__', alter_sys=True)",
        ]
    )
    return [sys.executable, "-c", start]


#: the detached driver: SIGHUP ignored (closing the terminal or logging out does not end it),
#: Ctrl-C's signal raising KeyboardInterrupt as in any Python program (a shell's background job
#: inherits it ignored, and Python then leaves it so), so that ``kill -INT`` stops the driver
#: as Ctrl-C does
DETACHED = (
    "signal.signal(signal.SIGHUP, signal.SIG_IGN)",
    "signal.signal(signal.SIGINT, signal.default_int_handler)",
)


def detached_args(argv: list[str]) -> list[str]:
    """The command line of the background driver: this one without ``--detach``."""
    return [a for a in argv if a != "--detach"]


def start_detached(
    args: list[str],
    log: Path,
    lock_path: Path,
    *,
    wait: float = START_WAIT,
    clock: Callable[[], float] = time.monotonic,
) -> Started:
    """``python -m nematic_solids.sweep ARGS`` (:func:`child_command` with :data:`DETACHED`)
    in a new session, its output appended to ``log``;
    returns once it holds the lock at ``lock_path``, has ended, or after ``wait`` seconds."""
    log.parent.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONUNBUFFERED="1", **{DRIVER_LOG_ENV: str(log)})
    env.setdefault("COLUMNS", "120")
    with open(log, "ab") as out:
        out.write(f"# {now_iso()} on {socket.gethostname()}: nematic {' '.join(args)}\n".encode())
        out.flush()
        proc = subprocess.Popen(
            [*child_command(*DETACHED), *args],
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )
    started = Started(pid=proc.pid, log=log)
    deadline = clock() + wait
    while clock() < deadline:
        holder = read_lock_holder(lock_path) or {}
        if holder.get("pid") == proc.pid:
            started.holds_lock = True
            return started
        if proc.poll() is not None:
            started.returncode = proc.returncode
            return started
        time.sleep(POLL)
    return started


def log_tail(log: Path, lines: int = 5) -> list[str]:
    """The last non-empty lines of ``log`` (none if it cannot be read)."""
    try:
        with open(log, "rb") as f:
            f.seek(max(0, f.seek(0, os.SEEK_END) - 16384))
            text = f.read().decode("utf-8", "replace")
    except OSError:
        return []
    return [line.rstrip() for line in text.splitlines() if line.strip()][-lines:]


@dataclass
class Stopped:
    """What :func:`stop_driver` did: the lock holder it signalled (``None``: no driver was
    running), how (``"SIGTERM"`` or ``"scancel JOB"``) and how long it took to exit
    (``None``: it had not exited within the wait)."""

    holder: dict[str, Any] | None
    how: str = ""
    took: float | None = None


def _signal(holder: dict[str, Any]) -> str:
    pid, host, job = holder.get("pid"), holder.get("host"), holder.get("slurm_job")
    if not isinstance(pid, int):
        raise ClusterError(
            f"the campaign's lock is held, but its holder is not recorded "
            f"({holder!r}); stop the driver where it runs (Ctrl-C)"
        )
    if host == socket.gethostname():
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            raise ClusterError(
                f"the driver's process {pid} is not on this host although "
                "the host name is this one (another container?); stop it "
                "where it runs (Ctrl-C)"
            ) from None
        except PermissionError:
            raise ClusterError(
                f"not allowed to signal the driver (pid {pid}, another user's)"
            ) from None
        return "SIGTERM"
    if job and shutil.which("scancel"):
        done = subprocess.run(
            ["scancel", "--batch", "--signal=TERM", str(job)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        if done.returncode != 0:
            raise ClusterError(
                f"scancel --batch --signal=TERM {job} failed: "
                f"{' '.join((done.stderr or done.stdout).split())}"
            )
        return f"scancel --batch --signal=TERM {job}"
    raise ClusterError(
        f"the driver runs on {host} (pid {pid}), not on this host "
        f"({socket.gethostname()}): run 'nematic stop' there, or "
        f"'kill -TERM {pid}' on {host}"
    )


def stop_driver(
    lock_path: Path, *, wait: float = STOP_WAIT, clock: Callable[[], float] = time.monotonic
) -> Stopped:
    """Signal the driver holding ``lock_path`` and wait (at most ``wait`` seconds) until it
    has released the lock. Raises :class:`~nematic_solids.sweep.errors.ClusterError` when it cannot
    be signalled from here."""
    holder = read_lock_holder(lock_path)
    if holder is None:
        return Stopped(holder=None)
    t0 = clock()
    how = _signal(holder)
    while clock() - t0 < wait:
        now = read_lock_holder(lock_path)
        if (
            now is None
            or now.get("pid") != holder.get("pid")
            or now.get("host") != holder.get("host")
        ):
            return Stopped(holder=holder, how=how, took=clock() - t0)
        time.sleep(POLL)
    return Stopped(holder=holder, how=how, took=None)
