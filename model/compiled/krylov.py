"""The pieces of the compiled Krylov solvers (numba): Givens rotations, back substitution,
weighted inner products and the fused Arnoldi step, shared by
:func:`model.compiled.linear_rhs.spin_gmres` and :mod:`model.compiled.finite_krylov`.

numpy twin: :mod:`model.krylov` (the same algorithms on arrays with a caller-supplied inner
product); tested to agree in ``tests/test_model_krylov.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .arith import rmul


@njit(cache=True)
def givens_column(H, g, cs, sn, k):  # pragma: no cover - compiled
    """GMRES's least-squares update for Hessenberg column ``k``: apply the previous Givens
    rotations to it, make the k-th one that zeroes ``H[k + 1, k]``, and rotate the residual
    vector ``g`` (|g[k + 1]| is then the residual norm of the current iterate)."""
    for i in range(k):
        t = cs[i] * H[i, k] + sn[i] * H[i + 1, k]
        H[i + 1, k] = -sn[i] * H[i, k] + cs[i] * H[i + 1, k]
        H[i, k] = t
    denom = np.hypot(H[k, k], H[k + 1, k])
    if denom == 0.0:
        denom = 1e-300
    cs[k] = H[k, k] / denom
    sn[k] = H[k + 1, k] / denom
    H[k, k] = denom
    H[k + 1, k] = 0.0
    g[k + 1] = -sn[k] * g[k]
    g[k] = cs[k] * g[k]


@njit(cache=True)
def solve_upper(H, g, m):  # pragma: no cover - compiled
    """``y`` with ``triu(H[:m, :m]) y = g[:m]`` by back substitution."""
    y = np.zeros(m)
    for i in range(m - 1, -1, -1):
        acc = g[i]
        for j in range(i + 1, m):
            acc -= H[i, j] * y[j]
        y[i] = acc / H[i, i]
    return y


@njit(cache=True, fastmath={"reassoc"})
def _wdot(wf, af, bf):  # pragma: no cover - compiled
    """The weighted real inner product of the flat complex arrays ``af``, ``bf`` (one
    block, of the length of ``wf``). Compiled with reassociation allowed (and nothing
    else: no contraction into FMAs), so that LLVM vectorises the sum: its order is then
    that of the compiled loop (SIMD lanes, then a fixed tree), fixed for a given machine and
    independent of the arrays' alignment (tested), not the order of ``numpy.sum``; 3x faster
    than the scalar sum at 128^2 (measured)."""
    s = 0.0
    for i in range(wf.size):
        s += wf[i] * (af[i].real * bf[i].real + af[i].imag * bf[i].imag)
    return s


@njit(cache=True)
def weighted_inner(a, b, w):  # pragma: no cover - compiled
    r""":math:`\sum w\, \mathrm{Re}(\bar a b)` for C-contiguous complex arrays ``a``, ``b``
    whose trailing axes have the shape of ``w`` (``w`` repeats over leading axes): the
    real-space inner product of half spectra when ``w`` holds the Parseval weights / N^2.
    Summed block by block (a block per leading index) in :func:`_wdot`'s order."""
    af = a.reshape(-1)
    bf = b.reshape(-1)
    wf = w.reshape(-1)
    nw = wf.size
    s = 0.0
    for block in range(af.size // nw):
        lo, hi = block * nw, (block + 1) * nw
        s += _wdot(wf, af[lo:hi], bf[lo:hi])
    return s


@njit(cache=True, fastmath={"reassoc"})
def _axpy_wdot(wf, yf, alpha, xf, af):  # pragma: no cover - compiled
    """``y += alpha x`` for one block of the flat arrays (of the length of ``wf``), fused
    with :func:`_wdot` of ``a`` and the updated ``y``. The update is exact as written (no FMA
    contraction); only the sum is reassociated. ``a`` must not overlap ``y`` (LLVM's run-time
    overlap check would take a scalar loop); :func:`_axpy_norm2` is the case ``a = y``."""
    s = 0.0
    for i in range(wf.size):
        yf[i] += rmul(alpha, xf[i])
        s += wf[i] * (af[i].real * yf[i].real + af[i].imag * yf[i].imag)
    return s


@njit(cache=True, fastmath={"reassoc"})
def _axpy_norm2(wf, yf, alpha, xf):  # pragma: no cover - compiled
    """``y += alpha x`` for one block, fused with the weighted squared norm of the updated
    ``y`` (:func:`_axpy_wdot` with ``a = y``, without the overlap that keeps it scalar)."""
    s = 0.0
    for i in range(wf.size):
        v = yf[i] + rmul(alpha, xf[i])
        yf[i] = v
        s += wf[i] * (v.real * v.real + v.imag * v.imag)
    return s


@njit(cache=True)
def axpy_inner(y, alpha, x, a, w):  # pragma: no cover - compiled
    """``y += alpha * x``, then return :func:`weighted_inner` ``(a, y, w)``, in one pass over
    memory (the same as the two calls to roundoff: the vectorised sums may group
    differently). ``a`` is either ``y`` itself (then it is the squared norm of the updated
    ``y``, by :func:`_axpy_norm2`) or does not overlap it."""
    yf = y.reshape(-1)
    xf = x.reshape(-1)
    af = a.reshape(-1)
    wf = w.reshape(-1)
    nw = wf.size
    norm = a.ctypes.data == y.ctypes.data  # a is y (else a must not overlap y)
    s = 0.0
    for block in range(yf.size // nw):
        lo, hi = block * nw, (block + 1) * nw
        if norm:
            s += _axpy_norm2(wf, yf[lo:hi], alpha, xf[lo:hi])
        else:
            s += _axpy_wdot(wf, yf[lo:hi], alpha, xf[lo:hi], af[lo:hi])
    return s


@njit(cache=True)
def mgs_column(V, wv, H, k, w):  # pragma: no cover - compiled
    """Modified Gram-Schmidt of ``wv`` against the basis ``V[0..k]`` (GMRES's Arnoldi
    step): ``H[i, k]`` = <V_i, wv>, ``wv -= H[i, k] V_i`` in turn; returns ``|wv|`` after.
    Each subtraction is fused with the next inner product (:func:`axpy_inner`): the same
    arithmetic as the plain loop, with half the passes over memory."""
    H[0, k] = weighted_inner(V[0], wv, w)
    for i in range(1, k + 1):
        H[i, k] = axpy_inner(wv, -H[i - 1, k], V[i - 1], V[i], w)
    return np.sqrt(max(axpy_inner(wv, -H[k, k], V[k], wv, w), 0.0))


@njit(cache=True)
def arnoldi_column(V, wv, H, g, cs, sn, k, w):  # pragma: no cover - compiled
    """One Arnoldi step of the compiled GMRESes for the new vector ``wv``: Gram-Schmidt
    against ``V[0..k]`` (:func:`mgs_column`), ``H[k + 1, k]`` = its norm, and the Givens
    update of the least-squares problem (:func:`givens_column`); returns the norm."""
    h_next = mgs_column(V, wv, H, k, w)
    H[k + 1, k] = h_next
    givens_column(H, g, cs, sn, k)
    return h_next


@njit(cache=True)
def axpy(y, alpha, x):  # pragma: no cover - compiled
    """``y += alpha * x`` in place (C-contiguous arrays of one shape; no temporary)."""
    yf = y.reshape(-1)
    xf = x.reshape(-1)
    for i in range(yf.size):
        yf[i] += rmul(alpha, xf[i])


@njit(cache=True)
def axpy_sum(x, y, B, m):  # pragma: no cover - compiled
    """``x += y[0] B[0] + ... + y[m-1] B[m-1]`` in one pass over ``x`` (the GMRES solution
    update from a basis ``B``); the terms are added to each element in that order, so it is
    bitwise the same as m calls of :func:`axpy`, with one read and write of ``x`` from memory
    (block by block: each block of x stays in cache while the m terms are added)."""
    xf = x.reshape(-1)
    size = xf.size
    Bf = B.reshape((B.shape[0], size))
    block = 512  # x's block stays in L1 while the m terms are added to it
    for lo in range(0, size, block):
        hi = min(lo + block, size)
        for i in range(m):
            c = y[i]
            for p in range(lo, hi):  # componentwise: the same values as c * (complex)
                b = Bf[i, p]
                xf[p] = complex(xf[p].real + c * b.real, xf[p].imag + c * b.imag)


@njit(cache=True)
def scaled(dst, x, alpha):  # pragma: no cover - compiled
    """``dst[...] = x / alpha`` in place (C-contiguous arrays of one shape)."""
    df = dst.reshape(-1)
    xf = x.reshape(-1)
    for i in range(df.size):  # component by component (numba would divide as complex)
        df[i] = complex(xf[i].real / alpha, xf[i].imag / alpha)
