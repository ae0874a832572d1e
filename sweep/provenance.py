"""Where results came from: the code version and git commit of this checkout."""

from __future__ import annotations

import functools
import logging
import platform
import subprocess
from pathlib import Path
from typing import Any

import model

log = logging.getLogger(__name__)


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """``HEAD`` of the repository holding the code (``+dirty`` if it has uncommitted changes to
    tracked files), or ``"unknown"`` outside a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain",
                                "--untracked-files=no"], capture_output=True, text=True,
                               timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def code_version() -> str:
    return str(getattr(model, "__version__", "unknown"))


def environment() -> dict[str, Any]:
    """Versions that matter for reproducing a run (reported by every worker at start)."""
    import dask
    import numpy
    import xarray

    return {"code_version": code_version(), "git_commit": git_commit(),
            "python": platform.python_version(), "numpy": numpy.__version__,
            "xarray": xarray.__version__, "dask": dask.__version__,
            "host": platform.node()}
