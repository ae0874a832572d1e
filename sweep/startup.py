"""What makes the short commands (``nematic report``, ``status``) start fast: the cyclic
garbage collector paused while they import their libraries and build their output
(:func:`paused_gc`), and xarray without ``dask.array`` until a dask array exists
(:func:`defer_dask_array`).

Importing xarray, pandas, bokeh and matplotlib makes about a million long-lived objects, and
the collector walks them again and again while they are made: 0.9 s of the report's 3.3 s of
CPU (measured with ``gc.callbacks``), 0.2 s of status's 1.2 s. These commands make little
cyclic garbage. Turned back on, the collector would walk every object made meanwhile once
more (0.3 s); in the command line's own process, which ends with the command
(:data:`FRESH_PROCESS`), those objects are frozen instead (``gc.freeze``: kept, never walked
again); elsewhere (tests, a command called in a longer process) they are collected as usual.

xarray asks, for every array it wraps, whether it is a dask array, and the first time it
asks it imports ``dask.array`` to get the class (where dask is installed): about 0.4 s
(dask.array imports scipy.fftpack, among others), the largest single import of ``nematic
report``, which holds no dask array. :func:`defer_dask_array` gives xarray's cache of that
class (``xarray.namedarray.pycompat``) a stand-in whose ``isinstance`` check is dask's own
once ``dask.array`` is imported, and False before: no object can be an instance of a class
whose module was never imported, so every answer is the one xarray would give. A process
that goes on to make dask arrays gets them recognised as usual.

It changes nothing where ``dask.array`` is already imported, where xarray has already asked,
or where xarray's internals are not the ones this was written for (then xarray imports
``dask.array`` as before: slower, never wrong). ``tests/sweep/test_startup.py`` checks that a dask
array made after it is still recognised.
"""

from __future__ import annotations

import contextlib
import gc
import sys
from collections.abc import Iterator
from typing import Any

#: True in the command line's own process (set by ``nematic_solids.sweep.cli.app``), which ends with
#: its command.
FRESH_PROCESS = {"on": False}


@contextlib.contextmanager
def paused_gc() -> Iterator[None]:
    """The cyclic garbage collector off inside, as it was after (nested uses are fine); in
    the command line's own process, the objects made inside frozen (module doc)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if FRESH_PROCESS["on"]:
            gc.freeze()
        if enabled:
            gc.enable()


class _DaskArrayCheck(type):
    """``isinstance(x, DaskArray)`` is ``isinstance(x, dask.array.Array)`` once dask.array is
    imported, else False (without importing it)."""

    def __instancecheck__(cls, obj: Any) -> bool:
        module = sys.modules.get("dask.array")
        array = getattr(module, "Array", None)
        return array is not None and isinstance(obj, array)

    def __subclasscheck__(cls, sub: Any) -> bool:
        module = sys.modules.get("dask.array")
        array = getattr(module, "Array", None)
        return array is not None and isinstance(sub, type) and issubclass(sub, array)


class DaskArray(metaclass=_DaskArrayCheck):
    """Stands for ``dask.array.Array`` in xarray's type checks (never instantiated)."""


def defer_dask_array() -> bool:
    """Let xarray check for dask arrays without importing ``dask.array`` (module doc); True
    if the stand-in was installed."""
    if "dask.array" in sys.modules:
        return False
    try:
        import dask
        from packaging.version import Version
        from xarray.namedarray import pycompat

        cache = pycompat._cached_duck_array_modules
        if "dask" in cache or not isinstance(cache, dict):
            return False
        entry = object.__new__(pycompat.DuckArrayModule)
        # the attributes DuckArrayModule.__init__ sets (xarray 2024.x to 2026.x)
        entry.module = dask
        entry.version = Version(dask.__version__)
        entry.type = (DaskArray,)
        entry.available = True
    except (ImportError, AttributeError, TypeError):
        return False
    cache["dask"] = entry
    return True
