"""The files of a service under its results root (``<root>/.service/``): the lock that makes it
the only service of the root (:data:`LOCK`), where it listens (:data:`INFO`, ``service.json``: its
URL, pid, host, start) and its token (:data:`TOKEN`, readable by its owner only)."""

from __future__ import annotations

import contextlib
import json
import os
import secrets
from pathlib import Path
from typing import Any

from ..errors import StorageError
from ..files import atomic_write_text, storage_cause
from ..lock import read_lock_holder

FOLDER = ".service"
LOCK = "service.lock"
INFO = "service.json"
TOKEN = "token"
#: The log of a service started in the background (``nematic serve --detach``).
LOG = "service.log"


class ServicePaths:
    """The service files of one results root."""

    def __init__(self, root: str | Path):
        self.root = Path(root).resolve()
        self.folder = self.root / FOLDER
        self.lock = self.folder / LOCK
        self.info = self.folder / INFO
        self.token = self.folder / TOKEN
        self.log = self.folder / LOG

    def ensure(self) -> None:
        """The folder, readable by its owner only (0700: the token lives in it)."""
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            os.chmod(self.folder, 0o700)
        except OSError as e:
            raise StorageError(
                f"cannot create {self.folder}: {storage_cause(self.folder, e)}"
            ) from None

    def write_token(self, token: str) -> None:
        """The token in a file only its owner can read (created 0600, then renamed over)."""
        tmp = self.token.with_name(f".{TOKEN}.{os.getpid()}")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(token + "\n")
        os.replace(tmp, self.token)

    def read_token(self) -> str | None:
        """The running service's token, or ``None`` (no file, or one this user cannot read)."""
        try:
            return self.token.read_text(encoding="utf-8").strip() or None
        except OSError:
            return None

    def write_info(self, info: dict[str, Any]) -> None:
        atomic_write_text(self.info, json.dumps(info, indent=1) + "\n")

    def running(self) -> dict[str, Any] | None:
        """Where the service of this root listens (``service.json``), if one runs: its lock is
        held (a service killed with ``kill -9`` holds none, whatever its file says)."""
        if not self.folder.is_dir():  # never started here (or the root is not a folder)
            return None
        if read_lock_holder(self.lock) is None:
            return None
        try:
            info = json.loads(self.info.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return dict(info) if isinstance(info, dict) else None

    def clear_info(self) -> None:
        """The service has stopped: where it listened and its token go."""
        for path in (self.info, self.token):
            with contextlib.suppress(OSError):
                path.unlink()


def new_token() -> str:
    """A fresh token: 48 hexadecimal digits (192 bits), as Jupyter's server makes them."""
    return secrets.token_hex(24)
