"""The time of one real 2-D transform on the compiled path, shared by the benchmarks that
compare against it (``bench_device.py``, ``bench_passes.py``; ``bench_floor.py`` runs the same
measurement inside its child process, which may import another checkout's code). Not a
benchmark itself."""

from __future__ import annotations

import time

import numpy as np


def fftw_transform_seconds(n: int) -> float:
    """Seconds of one real 2-D transform of an n x n field on the compiled path: the mean of a
    forward and an inverse (FFTW's new-array execute on aligned arrays, as the compiled code
    runs them; benchmarks/bench_floor.py's measurement), median of 7 batches."""
    from nematic_solids.model.compiled import fftw as fx

    pf, pi = fx.plans(n)
    a = fx.aligned_empty((n, n), np.float64)
    a[...] = np.random.default_rng(0).standard_normal((n, n))
    b = fx.aligned_empty((n, n // 2 + 1), np.complex128)
    half = fx.aligned_half(n)
    reps = max(5, int(2e6 / n**2))
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        for _ in range(reps):
            fx.rfft2(pf, a, b)
            fx.irfft2_via(pi, b, a, half)
        times.append((time.perf_counter() - t0) / (2 * reps))
    return float(np.median(times))
