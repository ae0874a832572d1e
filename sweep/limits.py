"""Bounds checked before anything is expanded, allocated or run: how many runs a campaign may
have, how much memory one run needs, how many workers a machine can take.

A run's memory is estimated from its resolution N: the interpreter with the model imported
(:data:`BASE_BYTES`) plus a number of N x N float64 arrays that depends on the mechanics
(:data:`ARRAYS_PER_POINT`). Measured peak RSS of ``nematic_solids.model.simulate.run`` (t_final =
0.2): the bare interpreter with the model imported 230 MB; linear mechanics 281 / 293 / 341 MB and
finite 286 / 306 / 372 MB at N = 64 / 128 / 256, i.e. about 124 (linear) and 172 (finite) float64
arrays of N x N above 280 MB; the constants add a margin. The estimate only has to be right within a
factor of about two: it exists to refuse N = 100000 (75 GiB per array) in a second instead of
letting the allocation fail after minutes, or the machine swap.
"""

from __future__ import annotations

import math
import os
import resource
from collections.abc import Mapping
from typing import Any

from .errors import ParameterError

#: Default ceiling on the runs of one campaign (``limits.max_runs`` changes it).
DEFAULT_MAX_RUNS = 1_000_000
#: Most grid points of a campaign, its parents' (``initial.from``) included. Validation builds the
#: model's objects at every grid point and compares their identities (about 0.06 ms a point on
#: the reference machine, a point with time protocols 0.13 ms), so the largest accepted
#: campaign is answered in about a second (``benchmarks/validate_bounds.py``). Not a setting: a
#: file could raise it itself; a larger study is several campaigns, or an adaptive one.
MAX_GRID_POINTS = 10_000
#: Most campaign files one collection lists (``campaigns:``). Each member is read and checked
#: as a campaign file is (up to about a second each, :data:`MAX_GRID_POINTS`), after its
#: count is: a list of 90000 members took 19 s to check member by member before it was
#: refused. A paper is a few campaigns; more are several collections. Not a setting.
MAX_COLLECTION_MEMBERS = 100
#: Most grid points of a collection's campaigns together: its members are checked one after
#: the other and the collection is refused once their points pass this, so checking a
#: collection takes at most about five times the largest campaign's second. The paper's
#: collection (campaigns/paper.yaml) has 223. Not a setting.
MAX_COLLECTION_POINTS = 5 * MAX_GRID_POINTS
#: Local worker processes allowed per CPU core.
MAX_WORKERS_PER_CORE = 4
#: Peak memory of a run without its arrays: the interpreter, numpy, xarray, py-pde, numba.
BASE_BYTES = 400 * 2**20
#: Peak memory per grid point of a run, in float64 arrays of N x N (measured, with margin).
ARRAYS_PER_POINT = {"linear": 160, "finite": 220}


def run_memory_bytes(resolution: int, mechanics: str = "finite") -> int:
    """The estimated peak memory of one run at ``resolution`` (bytes)."""
    arrays = ARRAYS_PER_POINT.get(mechanics, max(ARRAYS_PER_POINT.values()))
    return BASE_BYTES + arrays * 8 * int(resolution) ** 2


def fmt_bytes(n: float) -> str:
    if n > 2**1000:  # more than a float holds after the division below
        return "more than 1e+250 PiB"
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def physical_memory() -> int | None:
    """The machine's physical memory (bytes), or ``None`` if unknown."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def available_memory() -> int | None:
    """What one process here may use: the physical memory, or less under an address-space
    limit (``ulimit -v``), or ``None`` if neither is known."""
    limits = [m for m in (physical_memory(),) if m]
    soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    if soft != resource.RLIM_INFINITY:
        limits.append(int(soft))
    return min(limits) if limits else None


def parse_size(value: Any) -> int | None:
    """``"4GB"``, ``"512 MiB"``, ``2e9`` -> bytes (dask's notation); ``None`` for ``"auto"``
    or anything not understood."""
    if value is None or isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return int(value) if value > 0 and math.isfinite(value) else None
    try:
        from dask.utils import parse_bytes

        n = parse_bytes(str(value))
    except (ValueError, TypeError):
        return None
    return int(n) if n > 0 else None


def check_run_memory(numerics: Any, limit: int | None, what: str) -> None:
    """Raise :class:`ParameterError` (on ``resolution``) if one run at these numerics needs
    more memory than ``limit`` (bytes; ``what`` says whose limit it is)."""
    if limit is None:
        return
    need = run_memory_bytes(numerics.resolution, numerics.mechanics)
    if need > limit:
        raise ParameterError(
            "resolution",
            numerics.resolution,
            f"a resolution whose run fits in {what} ({fmt_bytes(limit)}): resolution "
            f"{numerics.resolution} ({numerics.mechanics} mechanics) needs about "
            f"{fmt_bytes(need)}",
        )


#: The reason recorded for a run that raised MemoryError (:func:`out_of_memory`).
OUT_OF_MEMORY = "out_of_memory"


def out_of_memory(numerics: Mapping[str, Any], error: BaseException, seeds: int = 1) -> str:
    """What a run's record says when it raised MemoryError: that it needed more memory than
    its process has, at what resolution and mechanics, how many seeds were computed together
    (an accelerated batch), the estimate of one run and what this process may use."""
    n = int(numerics.get("resolution") or 128)
    mechanics = str(numerics.get("mechanics") or "finite")
    limit = available_memory()
    may = f"this process may use {fmt_bytes(limit)}" if limit else "its limit is not known"
    together = f", {seeds} seeds computed together" if seeds > 1 else ""
    return (
        f"the run needed more memory than its process has (resolution {n}, {mechanics} "
        f"mechanics{together}; one run needs about {fmt_bytes(run_memory_bytes(n, mechanics))}, "
        f"{may}): {type(error).__name__}: {error}; allowed: a lower resolution, or more memory "
        "per run (fewer workers, execution.memory_limit, limits.run_memory, a smaller batch)"
    )


def max_local_workers() -> int:
    return MAX_WORKERS_PER_CORE * (os.cpu_count() or 1)
