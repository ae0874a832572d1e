"""How close the compiled pointwise passes run to this machine's memory speed: each main kernel
of a run's step (linear and finite mechanics) timed alone on arrays of a grid's size, with the
bytes it reads and writes, its rate in GB/s, and its time against a plain copy of the same
traffic (a compiled loop ``dst[i] = src[i]`` over half the bytes, timed in the same process:
1.0 means the pass costs what moving its data costs). One real transform of each size is timed
alongside. Not a test: the numbers depend on the machine and its load.

    .venv/bin/python benchmarks/bench_passes.py                 # 128^2 and 256^2
    .venv/bin/python benchmarks/bench_passes.py --sizes 128

A pass near 1.0 is bound by memory traffic: it gets faster only by moving fewer bytes (fewer
passes, or passes fused), not by faster arithmetic; a pass well above 1.0 is bound by its
arithmetic. Inputs are the kernels' real ones at the default parameters (alpha - B = 1): a
deformation gradient near the identity, an order parameter of a formed pattern (the activity
A near its stable value, so that the activity's phi functions take their recursion branch, as
they do once a pattern has formed), the tangent and spin coupling computed from them. Writes
``benchmarks/bench_passes.json`` (``--out``).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from fftw_timing import fftw_transform_seconds
from numba import njit

from nematic_solids.model.compiled import constitutive as cc
from nematic_solids.model.compiled import etd, krylov, rates, spectral, wellposedness
from nematic_solids.model.parameters import Parameters

HERE = Path(__file__).resolve().parent


@njit(cache=True)
def _copy(src, dst):  # pragma: no cover - compiled
    """The reference pass: ``dst[i] = src[i]`` over flat float64 arrays."""
    for i in range(src.size):
        dst[i] = src[i]


def timed(fn: Callable[[], object], budget: float = 0.05, batches: int = 7) -> float:
    """Seconds per call of ``fn``: the median over ``batches`` batches of about ``budget``
    seconds each (after one call to compile and warm)."""
    fn()
    t0 = time.perf_counter()
    fn()
    once = max(time.perf_counter() - t0, 1e-7)
    reps = max(3, int(budget / once))
    out = []
    for _ in range(batches):
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        out.append((time.perf_counter() - t0) / reps)
    return statistics.median(out)


def copy_time(nbytes: int) -> float:
    """Seconds for :func:`_copy` to read and write ``nbytes`` in all (half each way)."""
    n = max(1, nbytes // 16)
    src = np.random.default_rng(1).standard_normal(n)
    dst = np.empty(n)
    return timed(lambda: _copy(src, dst))


def nbytes(*arrays: np.ndarray) -> int:
    return int(sum(a.nbytes for a in arrays))


def passes(n: int) -> list[tuple[str, str, Callable[[], object], int]]:
    """``(mechanics, name, call, bytes read and written)`` for the kernels at N x N."""
    rng = np.random.default_rng(0)
    p = Parameters.from_dict({"alpha_minus_B": 1.0})
    m = n // 2 + 1

    def spectrum(*lead: int) -> np.ndarray:
        return rng.standard_normal((*lead, n, m)) + 1j * rng.standard_normal((*lead, n, m))

    real = (n, n)
    q1 = 0.1 * rng.standard_normal(real)
    q2 = 0.1 * rng.standard_normal(real)
    A = np.sqrt(p.chi / p.s) + 0.05 * rng.standard_normal(real)  # a formed pattern's A
    F = np.zeros((2, 2, n, n))
    F[0, 0] = F[1, 1] = 1.0
    F += 0.02 * rng.standard_normal(F.shape)
    kappa, B, Bp, alpha = p.kappa, p.B, p.B_prime, p.alpha
    K = cc.tangent_kernel(F, q1, q2, kappa, B, Bp, alpha)
    E = cc.q_increment_kernel(F, q1, q2, -2.0 * q2, 2.0 * q1, B, Bp, alpha)
    dF = 0.01 * rng.standard_normal(F.shape)
    out4 = np.empty_like(F)
    sym = [rng.random((n, m)) for _ in range(5)]
    x_hat = spectrum(2)
    terms = tuple(spectrum(2) for _ in range(4))
    wA = tuple(rng.random(real) for _ in range(5))
    tA = tuple(rng.standard_normal((1, n, n)) for _ in range(4))
    w = rng.random((n, m))
    V = spectrum(4)
    wv = spectrum()
    y = np.array([0.3, -0.2, 0.1])
    tr_e = np.zeros(real)
    trP = rng.standard_normal(real)
    b2 = spectrum(2)
    g2 = np.empty_like(b2)
    khx, khy, inv_k2 = rng.random((n, m)), rng.random((n, m)), rng.random((n, m))
    angles = np.arange(32) * (np.pi / 32)
    cos_t, sin_t = np.cos(angles), np.sin(angles)
    h = 0.25
    S = nbytes(wv)  # one spectrum
    R = q1.nbytes  # one real field
    return [
        ("linear", "etd_combination, q, 4 terms", lambda: etd.etd_combination(
            sym[0], x_hat, h, tuple(sym[1:]), terms), 5 * nbytes(sym[0]) + 6 * 2 * S),
        ("linear", "etd_combination, A, 4 terms", lambda: etd.etd_combination(
            wA[0], A.reshape(1, n, n), h, wA[1:], tA), 11 * R),
        ("linear", "activity_krogstad (10 weights)", lambda: etd.activity_krogstad(
            A, h, p.zeta, p.s, p.tau), 12 * R),
        ("linear", "bulk_terms", lambda: rates.bulk_terms(q1, q2, A, tr_e, p.C, 0.0), 6 * R),
        ("linear", "activity_rate", lambda: rates.activity_rate(
            A, trP, p.zeta, p.chi, p.s, p.tau), 3 * R),
        ("linear", "weighted_inner", lambda: krylov.weighted_inner(V[0], wv, w),
         2 * S + w.nbytes),
        ("linear", "axpy_inner (Gram-Schmidt step)", lambda: krylov.axpy_inner(
            wv, 1e-30, V[0], V[1], w), 4 * S + w.nbytes),
        ("linear", "scaled", lambda: krylov.scaled(V[3], wv, 1.0), 2 * S),
        ("linear", "axpy_sum, 3 terms", lambda: krylov.axpy_sum(wv, y, V, 3), 5 * S),
        ("finite", "tangent_kernel", lambda: cc.tangent_kernel(
            F, q1, q2, kappa, B, Bp, alpha), 16 * R),
        ("finite", "apply_tangent_into (with spin)", lambda: cc.apply_tangent_into(
            K, dF, E, True, out4), 22 * R),
        ("finite", "first_piola_kernel", lambda: cc.first_piola_kernel(
            F, q1, q2, kappa, B, Bp, alpha), 10 * R),
        ("finite", "q_increment_kernel", lambda: cc.q_increment_kernel(
            F, q1, q2, q2, q1, B, Bp, alpha), 12 * R),
        ("finite", "finite_margin_kernel", lambda: wellposedness.finite_margin_kernel(
            K, E, cos_t, sin_t, kappa + 1.0), 14 * R),
        ("finite", "green_into", lambda: spectral.green_into(
            b2, khx, khy, inv_k2, 0.5, g2), 4 * S + 3 * khx.nbytes),
    ]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="128,256", help="N,...")
    ap.add_argument("--out", default=str(HERE / "bench_passes.json"))
    args = ap.parse_args()
    result: dict = {"machine": platform.processor() or platform.machine(), "sizes": {}}
    for n in (int(s) for s in args.sizes.split(",")):
        fft = fftw_transform_seconds(n)
        print(f"\n{n}^2: one real transform {fft * 1e6:.1f} us")
        print(f"  {'kernel':34s} {'us':>8s} {'MB':>6s} {'GB/s':>6s} {'x copy':>7s} {'x fft':>6s}")
        rows = []
        for mech, name, call, moved in passes(n):
            t = timed(call)
            c = copy_time(moved)
            row = {
                "mechanics": mech,
                "kernel": name,
                "us": t * 1e6,
                "MB": moved / 1e6,
                "GB_per_s": moved / t / 1e9,
                "x_copy": t / c,
                "x_transform": t / fft,
            }
            rows.append(row)
            print(
                f"  {name:34s} {row['us']:8.1f} {row['MB']:6.2f} {row['GB_per_s']:6.1f} "
                f"{row['x_copy']:7.2f} {row['x_transform']:6.2f}"
            )
        result["sizes"][str(n)] = {"transform_us": fft * 1e6, "kernels": rows}
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
