"""Where results came from: the code version and git commit of this checkout."""

from __future__ import annotations

import logging
import platform
from typing import Any

from nematic_solids import model
from nematic_solids.model.provenance import git_commit, library_versions, library_versions_text

log = logging.getLogger(__name__)

__all__ = ["code_version", "environment", "git_commit", "library_versions", "library_versions_text"]


def code_version() -> str:
    return str(getattr(model, "__version__", "unknown"))


def environment() -> dict[str, Any]:
    """Versions that matter for reproducing a run (reported by every worker at start)."""
    import dask
    import numpy
    import xarray

    return {
        "code_version": code_version(),
        "git_commit": git_commit(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "xarray": xarray.__version__,
        "dask": dask.__version__,
        **library_versions(),
        "host": platform.node(),
    }
