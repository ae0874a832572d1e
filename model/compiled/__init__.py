"""The compiled layer (numba, cached on disk: ``cache=True``), one module per concept, each
naming its numpy twin (a module of :mod:`nematic_solids.model`):

=====================  ===================================================================
module                 numpy twin
=====================  ===================================================================
``arith``              the plain products ``c * z``, ``1j * c * z``
``constitutive``       ``constitutive`` (through ``reference_kernels``)
``spectral``           ``reference_kernels`` (``fourier.SpectralGrid``)
``etd``                ``reference_kernels`` (``phi_functions``)
``rates``              ``reference_kernels`` (the expressions of ``pde``)
``wellposedness``      ``wellposedness.finite_margin_samples``
``krylov``             ``krylov``
``linear_rhs``         ``split.SpectralSplit.reference``
``linear_step``        ``solver.ETDRK4Solver.step`` (its stages in Python, the same kernels)
``finite_krylov``      ``krylov.pcg``, ``krylov.gmres`` on the operators of
                       ``mechanics.FiniteMechanics``
``fftw``               ``fourier.FFT`` with scipy.fft
``kernels``            the kernel set of ``Numerics.backend = "compiled"``
=====================  ===================================================================

Nothing here imports the classes that call it.

**The disk cache.** numba invalidates a cached function only when its own source file changes,
not when a function it calls from another file does (``linear_rhs`` calls ``krylov``, ``etd``
calls ``arith``, and the one GMRES reaches its operators through overloads defined elsewhere),
so a change in one module could leave stale machine code in another's cache. Importing this
package therefore points numba's cache (``numba.config.CACHE_DIR``) at a folder named by a
hash of every source file here, ``model/compiled/__pycache__/numba-<hash>`` (or
``~/.cache/nematic/numba-<hash>`` where the package folder is not writable): any change to
the compiled code starts a fresh cache. A ``NUMBA_CACHE_DIR`` set in the environment is used
as given. :func:`prune_stale_caches` (run by ``python -m nematic_solids.model.warmup``, so by
``scripts/bootstrap.sh``) removes the folders of earlier versions.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import numba


def source_digest(folder: Path | None = None) -> str:
    """A hash of every module of this package (names and contents), or of ``folder``'s."""
    h = hashlib.sha256()
    for path in sorted((folder or Path(__file__).parent).glob("*.py")):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    """The numba cache folder of this version of the compiled code."""
    here = Path(__file__).parent
    name = f"numba-{source_digest()}"
    if os.access(here, os.W_OK):
        return here / "__pycache__" / name
    return Path.home() / ".cache" / "nematic" / name


def prune_stale_caches(current: Path | None = None) -> list[Path]:
    """Remove the ``numba-<hash>`` folders beside ``current`` (default :func:`cache_dir`)
    that belong to other versions of the compiled code; returns what was removed."""
    current = current or cache_dir()
    if not current.parent.is_dir():
        return []
    stale = [p for p in current.parent.glob("numba-*") if p.is_dir() and p != current]
    for p in stale:
        shutil.rmtree(p, ignore_errors=True)
    return stale


if not os.environ.get("NUMBA_CACHE_DIR"):
    numba.config.CACHE_DIR = str(cache_dir())  # type: ignore[attr-defined]
