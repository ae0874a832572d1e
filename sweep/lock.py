"""The lock that lets one driver at a time run a campaign: ``results/<name>/.lock``, held with
``flock`` by the driver (:class:`CampaignLock`), with who holds it written inside (pid, host,
command, start, its SLURM job and log) for ``nematic status`` and ``nematic stop``
(:func:`read_lock_holder`)."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
from pathlib import Path
from typing import Any

from .errors import CampaignLocked, StorageError
from .files import now_iso, storage_cause

#: Set by ``nematic run --detach`` for its background driver: where its output goes (kept
#: in the lock's holder information, shown by ``nematic status``).
DRIVER_LOG_ENV = "NEMATIC_DRIVER_LOG"


class CampaignLock:
    """An exclusive ``flock`` on ``results/<name>/.lock``, released by the kernel when the
    process ends however it ends (SIGKILL included), so a dead driver never blocks a resume.
    The file holds the holder's pid, host and start time for the message."""

    def __init__(self, path: Path):
        self.path = path
        self._fd: int | None = None

    def acquire(self, command: str = "") -> None:

        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise StorageError(
                f"cannot create the lock file {self.path}: {storage_cause(self.path, e)}"
            ) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            os.close(fd)
            if e.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            holder = read_lock_holder(self.path) or {}
            raise CampaignLocked(
                f"campaign folder {self.path.parent} is in use by another driver "
                f"(pid {holder.get('pid', '?')} on {holder.get('host', '?')}, since "
                f"{holder.get('started', '?')}: {holder.get('command', '')}). Wait for it to "
                "finish or stop it (Ctrl-C); 'nematic status' shows its progress."
            ) from None
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": now_iso(),
            "command": command,
        }
        for key, var in (("slurm_job", "SLURM_JOB_ID"), ("log", DRIVER_LOG_ENV)):
            if os.environ.get(var):  # a driver in a batch job; a detached driver's log
                info[key] = os.environ[var]
        with contextlib.suppress(OSError):  # who holds it is a courtesy (a full disk...)
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            import fcntl

            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, 0)
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> CampaignLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def read_lock_holder(path: Path) -> dict[str, Any] | None:
    """Who holds the lock (pid, host, started, command; ``slurm_job`` for a driver in a SLURM
    job, ``log`` for a detached one), or ``None`` if nobody does."""

    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            try:
                return dict(json.loads(os.pread(fd, 4096, 0).decode() or "{}"))
            except ValueError:
                return {}
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


# --------------------------------------------------------------------------- the folder
