"""numba's disk cache of the model's kernels, as one process sees and writes it: what the
process has compiled and loaded (:func:`compile_counts`), and a file lock around the cache's
reads and writes (:func:`lock_cache_files`).

numba's cache index (one file per function) is read, changed and rewritten without a lock, so
two processes that save two signatures of one function at once could lose one or give both
the same data file: the processes that ``python -m nematic_solids.model.warmup`` starts to compile
in parallel (:func:`nematic_solids.model.warmup.compile_in_parallel`) hold the lock.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import Any

#: Modules holding the compiled kernels.
KERNEL_MODULES = (
    "nematic_solids.model.compiled.arith",
    "nematic_solids.model.compiled.constitutive",
    "nematic_solids.model.compiled.spectral",
    "nematic_solids.model.compiled.etd",
    "nematic_solids.model.compiled.rates",
    "nematic_solids.model.compiled.wellposedness",
    "nematic_solids.model.compiled.krylov",
    "nematic_solids.model.compiled.linear_rhs",
    "nematic_solids.model.compiled.finite_krylov",
    "nematic_solids.model.compiled.fftw",
)


def kernel_dispatchers() -> list[Any]:
    """Every numba dispatcher of :data:`KERNEL_MODULES` (imported here if needed)."""
    import importlib

    from numba.core.dispatcher import Dispatcher

    out: list[Any] = []
    for name in KERNEL_MODULES:
        module = importlib.import_module(name)
        out.extend(v for v in vars(module).values() if isinstance(v, Dispatcher))
    return out


def compile_counts() -> dict[str, int]:
    """Kernel signatures this process has compiled (cache misses) and loaded from the disk
    cache (cache hits) so far."""
    misses = hits = 0
    for d in kernel_dispatchers():
        misses += sum(d.stats.cache_misses.values())
        hits += sum(d.stats.cache_hits.values())
    return {"compiled": misses, "loaded": hits}


@contextlib.contextmanager
def _locked(folder: str, exclusive: bool) -> Iterator[None]:
    """An advisory lock on ``folder/.nematic-cache.lock`` (nothing if the folder is absent)."""
    import fcntl

    if not os.path.isdir(folder):
        yield
        return
    fd = os.open(os.path.join(folder, ".nematic-cache.lock"), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        yield
    finally:
        os.close(fd)  # releases the lock


def lock_cache_files() -> None:
    """Make numba's cache reads and writes in this process take a file lock in the cache
    folder: a write (read the index, choose a data file, write both) excludes every other
    read and write, so processes that compile at once never give one data file to two
    signatures, nor lose an index entry. Patches ``numba.core.caching.IndexDataCacheFile``'s
    ``save`` and ``load`` (numba has no public hook); idempotent."""
    from numba.core import caching

    cls = caching.IndexDataCacheFile
    if getattr(cls, "_nematic_locked", False):
        return
    save, load = cls.save, cls.load

    def locked_save(self: Any, key: Any, data: Any) -> None:
        with _locked(self._cache_path, exclusive=True):
            save(self, key, data)

    def locked_load(self: Any, key: Any) -> Any:
        with _locked(self._cache_path, exclusive=False):
            return load(self, key)

    cls.save, cls.load = locked_save, locked_load  # type: ignore[method-assign]
    cls._nematic_locked = True  # type: ignore[attr-defined]
