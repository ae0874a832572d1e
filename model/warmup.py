"""Compile the model's numba kernels once, before any real run needs them.

The kernels are compiled on first use and cached on disk (``cache=True``: ``*.nbi`` /
``*.nbc`` files in a folder named by the hash of the compiled sources,
:func:`model.compiled.cache_dir`), so only the first run on a machine (or after a change to
the compiled code) pays the compilation, about a minute. Without a warm-up, every
worker of a campaign's first run compiles the same kernels at the same time. :func:`warm_up`
runs a tiny simulation (16^2, to t = 0.5) of each kind a campaign uses, in one process;
afterwards every other process loads the compiled code from the cache.

``python -m model.warmup`` (run by ``scripts/bootstrap.sh``) warms both mechanics.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable
from typing import Any

from .parameters import Numerics, Parameters

#: Modules holding the compiled kernels.
KERNEL_MODULES = ("model.compiled.arith", "model.compiled.constitutive",
                  "model.compiled.spectral", "model.compiled.etd", "model.compiled.rates",
                  "model.compiled.wellposedness", "model.compiled.krylov",
                  "model.compiled.linear_rhs", "model.compiled.finite_krylov",
                  "model.compiled.fftw")
WARM_RESOLUTION = 16
WARM_T_FINAL = 0.5


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


def warm_numerics(numerics: Numerics) -> Numerics:
    """The tiny numerics that take the same code paths as ``numerics``."""
    return numerics.replace(resolution=WARM_RESOLUTION, t_final=WARM_T_FINAL,
                            save_every=WARM_T_FINAL, snapshot_times=(), dt=min(numerics.dt,
                                                                               0.05))


def warm_up(kinds: Iterable[tuple[Parameters, Numerics]] | None = None) -> dict[str, Any]:
    """Run a tiny simulation for each ``(parameters, numerics)`` (default: the model's
    defaults with finite and with linear mechanics) so that every kernel they use is
    compiled (or loaded from the cache). Returns the wall time and :func:`compile_counts`.
    Never raises for a failed tiny run (the real run reports its own failure)."""
    from .simulate import run

    if kinds is None:
        kinds = [(Parameters(), Numerics(mechanics=m)) for m in ("finite", "linear")]
    t0 = time.perf_counter()
    errors = []
    for params, numerics in kinds:
        small = params.replace(noise_modes=min(params.noise_modes, WARM_RESOLUTION // 2 - 1))
        try:
            run(small, warm_numerics(numerics), seed=0)
        except Exception as e:  # noqa: BLE001 - a warm-up never stops the real work
            errors.append(f"{type(e).__name__}: {e}")
    return {"seconds": time.perf_counter() - t0, **compile_counts(), "errors": errors}


def main() -> int:  # pragma: no cover - exercised by scripts/bootstrap.sh
    print("compiling the model's numba kernels (cached on disk; about a minute the first "
          "time, a few seconds when already cached) ...", flush=True)
    if not os.environ.get("NUMBA_CACHE_DIR"):  # the hashed folders are ours to tidy
        from .compiled import prune_stale_caches

        for path in prune_stale_caches():
            print(f"removed the kernel cache of an earlier version: {path}", flush=True)
    info = warm_up()
    print(f"kernels ready in {info['seconds']:.0f} s ({info['compiled']} compiled, "
          f"{info['loaded']} loaded from the cache)", flush=True)
    for e in info["errors"]:
        print(f"warning: warm-up run failed: {e}", file=sys.stderr)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
