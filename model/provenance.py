"""Where a result came from: the git commit of the source tree (light: no heavy imports)."""

from __future__ import annotations

import ctypes
import functools
import subprocess
from collections.abc import Iterator
from pathlib import Path


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """``HEAD`` of the repository holding the code (``+dirty`` if tracked files have
    uncommitted changes), or ``"unknown"`` outside a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(
            ["git", "-C", str(here), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def library_versions() -> dict[str, str]:
    """Versions of the libraries a run's numbers depend on (numpy, scipy, py-pde, numba,
    FFTW, pyfftw, xarray, netCDF4, dask), for the files' provenance attributes; a library
    that is not installed is left out. Read once per process (:func:`_library_versions`:
    parsing the packages' metadata took 18 ms a run, measured at 16^2 on the 2-core VM,
    where the run's own steps took 30 ms)."""
    return dict(_library_versions())


@functools.lru_cache(maxsize=1)
def _library_versions() -> tuple[tuple[str, str], ...]:
    """:func:`library_versions`, read once: the versions of the libraries this process loaded
    do not change while it runs."""
    import importlib.metadata as md

    out: dict[str, str] = {}
    for label, dist in (
        ("numpy", "numpy"),
        ("scipy", "scipy"),
        ("py-pde", "py-pde"),
        ("numba", "numba"),
        ("pyfftw", "pyFFTW"),
        ("xarray", "xarray"),
        ("netCDF4", "netCDF4"),
        ("dask", "dask"),
    ):
        try:
            out[label] = md.version(dist)
        except md.PackageNotFoundError:
            continue
    fftw = _fftw_version()
    if fftw:
        out["fftw"] = fftw
    return tuple(out.items())


@functools.lru_cache(maxsize=1)
def _fftw_version() -> str:
    """The native FFTW library's own version string (``fftw-3.3.5-sse2-avx``): of the library
    :mod:`nematic_solids.model.compiled.fftw` loaded, or, where that module is not imported, of the
    one it would load, read with ctypes alone (importing the compiled package imports numba, a
    quarter of a second that the report and aggregation do not need)."""
    import sys

    compiled = sys.modules.get("nematic_solids.model.compiled.fftw")
    lib = getattr(compiled, "_LIB", None) if compiled is not None else _fftw_library()
    if lib is None:
        return ""
    try:
        return ctypes.string_at(ctypes.addressof(ctypes.c_char.in_dll(lib, "fftw_version"))).decode(
            errors="replace"
        )
    except (ValueError, OSError):
        return ""


def fftw_candidates() -> Iterator[str]:
    """Where FFTW's double-precision library may be, in :mod:`nematic_solids.model.compiled.fftw`'s
    order (its ``_candidates``, repeated here without importing pyfftw; a test holds the two equal):
    inside the pyFFTW wheel first, then the system (looked up only when asked for)."""
    import ctypes.util
    import glob
    import importlib.util
    import os

    spec = importlib.util.find_spec("pyfftw")
    if spec is not None and spec.origin:
        here = os.path.dirname(spec.origin)
        for pattern in (
            "../pyfftw.libs/libfftw3-*.so*",
            ".dylibs/libfftw3.*dylib",
            "libfftw3-3.dll",
            "../pyFFTW.libs/libfftw3-*.so*",
        ):
            yield from sorted(glob.glob(os.path.join(here, pattern)))
    system = ctypes.util.find_library("fftw3")
    if system:
        yield system


def _fftw_library() -> ctypes.CDLL | None:
    """The first FFTW library of :func:`fftw_candidates` that loads with the transforms the
    model calls (as :mod:`nematic_solids.model.compiled.fftw` chooses it), or None."""
    for path in fftw_candidates():
        try:
            lib = ctypes.CDLL(path)
            lib.fftw_execute_dft_r2c  # noqa: B018 - the symbols the model needs must exist
            lib.fftw_execute_dft_c2r  # noqa: B018
        except (OSError, AttributeError):
            continue
        return lib
    return None


def library_versions_text() -> str:
    """:func:`library_versions` as one attribute value: ``numpy 2.1.3, py-pde 0.45, ...``."""
    return ", ".join(f"{k} {v}" for k, v in library_versions().items())
