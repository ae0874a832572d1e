"""Where a result came from: the git commit of the source tree (light: no heavy imports)."""

from __future__ import annotations

import functools
import subprocess
from pathlib import Path


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """``HEAD`` of the repository holding the code (``+dirty`` if tracked files have
    uncommitted changes), or ``"unknown"`` outside a git checkout."""
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


def library_versions() -> dict[str, str]:
    """Versions of the libraries a run's numbers depend on (numpy, scipy, py-pde, numba,
    FFTW, pyfftw, xarray, netCDF4, dask), for the files' provenance attributes; a library
    that is not installed is left out."""
    import importlib.metadata as md

    out: dict[str, str] = {}
    for label, dist in (("numpy", "numpy"), ("scipy", "scipy"), ("py-pde", "py-pde"),
                        ("numba", "numba"), ("pyfftw", "pyFFTW"), ("xarray", "xarray"),
                        ("netCDF4", "netCDF4"), ("dask", "dask")):
        try:
            out[label] = md.version(dist)
        except md.PackageNotFoundError:
            continue
    fftw = _fftw_version()
    if fftw:
        out["fftw"] = fftw
    return out


@functools.lru_cache(maxsize=1)
def _fftw_version() -> str:
    """The native FFTW library's own version string (``fftw-3.3.5-sse2-avx``), if loaded."""
    import ctypes

    try:
        from .compiled import fftw
    except ImportError:
        return ""
    lib = getattr(fftw, "_LIB", None)
    if lib is None:
        return ""
    try:
        return ctypes.string_at(ctypes.addressof(ctypes.c_char.in_dll(lib, "fftw_version"))
                                ).decode(errors="replace")
    except (ValueError, OSError):
        return ""


def library_versions_text() -> str:
    """:func:`library_versions` as one attribute value: ``numpy 2.1.3, py-pde 0.45, ...``."""
    return ", ".join(f"{k} {v}" for k, v in library_versions().items())
