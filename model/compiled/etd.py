"""The pointwise pieces of the exponential integrators (numba): phi functions of the
activity's local Jacobian and the stage combinations.

numpy twin: :mod:`nematic_solids.model.reference_kernels` (its ``phi_functions``); tested to agree
in ``tests/model/test_constitutive.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .arith import rmul

#: 1/j! for j = 0..21, the Taylor coefficients of the phi functions
_RECIP_FACT = np.array([1.0 / float(np.prod(np.arange(1, j + 1))) for j in range(22)])


@njit(cache=True)
def _phi123_from(z, em1):  # pragma: no cover - compiled
    """:math:`\varphi_{1,2,3}(z)` given :math:`e^z - 1`: Taylor series (Horner, 19 terms:
    truncation < 1e-17) for |z| < 1, the recursion :math:`\varphi_{k+1} = (\varphi_k - 1/k!)/z`
    otherwise (the same branches as
    :func:`nematic_solids.model.reference_kernels.phi_functions`)."""
    if abs(z) < 1.0:
        p1 = 0.0
        p2 = 0.0
        p3 = 0.0
        for j in range(18, -1, -1):  # phi_k = sum_j z^j / (j + k)!
            p1 = p1 * z + _RECIP_FACT[j + 1]
            p2 = p2 * z + _RECIP_FACT[j + 2]
            p3 = p3 * z + _RECIP_FACT[j + 3]
        return p1, p2, p3
    p1 = em1 / z
    p2 = (p1 - 1.0) / z
    p3 = (p2 - 0.5) / z
    return p1, p2, p3


@njit(cache=True)
def _phi0123(z):  # pragma: no cover - compiled
    """:math:`e^z, \varphi_1(z), \varphi_2(z), \varphi_3(z)` of a real scalar."""
    p1, p2, p3 = _phi123_from(z, np.expm1(z))
    return np.exp(z), p1, p2, p3


@njit(cache=True)
def activity_exponential(A, h, zeta, s, tau):  # pragma: no cover - compiled
    r"""The pointwise Jacobian :math:`L_A = -(\zeta + 3 s A^2)/\tau` of the local part of
    Eq. (5) and :math:`\varphi_1(h L_A), \varphi_2(h L_A)`; returns ``(L_A, phi1, phi2)``."""
    nx, ny = A.shape
    L = np.empty((nx, ny))
    p1 = np.empty((nx, ny))
    p2 = np.empty((nx, ny))
    for x in range(nx):
        for y in range(ny):
            a = A[x, y]
            lam = -(zeta + 3.0 * s * a * a) / tau
            L[x, y] = lam
            _, p1[x, y], p2[x, y], _ = _phi0123(lam * h)
    return L, p1, p2


@njit(cache=True)
def _taylor_row(z, c0, out):  # pragma: no cover - compiled
    r"""``out[p]`` = :math:`\sum_{j=0}^{18} z_p^j / (j + c_0)!` for a row ``z`` by Horner,
    the loop over the points innermost: the same operations per point as
    :func:`_phi123_from`'s Taylor branch (no FMA contraction), which LLVM vectorises and
    whose dependent multiply-adds of neighbouring points overlap (the point-by-point
    Horner waited on each multiply-add: the latency, not the arithmetic, was the cost)."""
    for p in range(z.size):
        out[p] = 0.0
    for j in range(18, -1, -1):
        c = _RECIP_FACT[j + c0]
        for p in range(z.size):
            out[p] = out[p] * z[p] + c


@njit(cache=True)
def _gather_small(z, out, at):  # pragma: no cover - compiled
    """The entries of the row ``z`` with |z| < 1 (those whose phi functions are summed as a
    series) into ``out[:m]``, their places into ``at[:m]``; returns m."""
    m = 0
    for y in range(z.size):
        if abs(z[y]) < 1.0:
            out[m] = z[y]
            at[m] = y
            m += 1
    return m


@njit(cache=True)
def _phi_row(z, em1, p1, p2, p3, zs, at, t1, t2, t3, third):  # pragma: no cover - compiled
    r""":math:`\varphi_{1,2}(z)` (and :math:`\varphi_3` if ``third``) of the row ``z`` into
    ``p1``, ``p2`` (``p3``), given the row ``em1`` of :math:`e^z - 1`: the recursion of
    :func:`_phi123_from` at every point (branch-free, so LLVM vectorises it; where |z| < 1 it
    divides by 1 instead of z and is overwritten), then the series (:func:`_taylor_row`) at
    the points with |z| < 1, gathered (``zs``, ``at``, ``t1..3`` work rows): each point's
    value is the one :func:`_phi123_from` gives."""
    for y in range(z.size):
        zz = z[y]
        zr = zz if abs(zz) >= 1.0 else 1.0
        a = em1[y] / zr
        b = (a - 1.0) / zr
        p1[y] = a
        p2[y] = b
        if third:
            p3[y] = (b - 0.5) / zr
    m = _gather_small(z, zs, at)
    if m > 0:
        _taylor_row(zs[:m], 1, t1)
        _taylor_row(zs[:m], 2, t2)
        if third:
            _taylor_row(zs[:m], 3, t3)
        for k in range(m):
            p1[at[k]] = t1[k]
            p2[at[k]] = t2[k]
            if third:
                p3[at[k]] = t3[k]


@njit(cache=True)
def activity_krogstad(A, h, zeta, s, tau):  # pragma: no cover - compiled
    r"""For the ETDRK4 step of the activity: :math:`L_A = -(\zeta + 3 s A^2)/\tau` and,
    point by point, Krogstad's weights
    (:meth:`nematic_solids.model.solver.ETDRK4Solver._weights_from`) from :math:`f_k =
    \varphi_k(z)`, :math:`g_k = \varphi_k(z/2)` at :math:`z = h L_A`: ``W[0:2]`` = :math:`e^{z},
    e^{z/2}`; ``W[2]`` = g1/2 (stage a); ``W[3:5]`` = g1/2 - g2, g2 (stage b); ``W[5:7]`` = f1 - 2
    f2, 2 f2 (stage c); ``W[7:10]`` = f1 - 3 f2 + 4 f3, 2 f2 - 4 f3, 4 f3 - f2 (the update). Returns
    ``(L_A, W)``.

    Row by row, in passes that LLVM vectorises except the one transcendental per point
    (:math:`e^{z/2}`, from which :math:`e^z - 1 = (e^{z/2} - 1)(e^{z/2} + 1)`): the phi
    functions by :func:`_phi_row` (the recursion everywhere, the series where |z| < 1), then
    the weights. Bitwise the values of evaluating :func:`_phi123_from` point by point (the
    same operations on each point: tested)."""
    nx, ny = A.shape
    L = np.empty((nx, ny))
    W = np.empty((10, nx, ny))
    z = np.empty(ny)
    zh = np.empty(ny)
    eh = np.empty(ny)  # e^{z/2}
    emh = np.empty(ny)  # e^{z/2} - 1
    em = np.empty(ny)  # e^z - 1 = (e^{z/2} - 1)(e^{z/2} + 1)
    f1 = np.empty(ny)
    f2 = np.empty(ny)
    f3 = np.empty(ny)
    g1 = np.empty(ny)
    g2 = np.empty(ny)
    zs = np.empty(ny)
    at = np.empty(ny, dtype=np.int64)
    t1 = np.empty(ny)
    t2 = np.empty(ny)
    t3 = np.empty(ny)
    for x in range(nx):
        for y in range(ny):
            a = A[x, y]
            lam = -(zeta + 3.0 * s * a * a) / tau
            L[x, y] = lam
            z[y] = lam * h
            zh[y] = 0.5 * z[y]
        for y in range(ny):
            # one transcendental per point, e^{z/2} from exp where it is small (1 + expm1
            # would lose its relative accuracy)
            if z[y] < -1.0:
                e = np.exp(zh[y])
                eh[y] = e
                emh[y] = e - 1.0
            else:
                d = np.expm1(zh[y])
                emh[y] = d
                eh[y] = 1.0 + d
            em[y] = emh[y] * (eh[y] + 1.0)
        _phi_row(z, em, f1, f2, f3, zs, at, t1, t2, t3, True)
        _phi_row(zh, emh, g1, g2, g2, zs, at, t1, t2, t3, False)
        for y in range(ny):
            e = eh[y]
            a1, a2, a3, b1, b2 = f1[y], f2[y], f3[y], g1[y], g2[y]
            W[0, x, y] = e * e
            W[1, x, y] = e
            W[2, x, y] = 0.5 * b1
            W[3, x, y] = 0.5 * b1 - b2
            W[4, x, y] = b2
            W[5, x, y] = a1 - 2.0 * a2
            W[6, x, y] = 2.0 * a2
            W[7, x, y] = a1 - 3.0 * a2 + 4.0 * a3
            W[8, x, y] = 2.0 * a2 - 4.0 * a3
            W[9, x, y] = 4.0 * a3 - a2
    return L, W


@njit(cache=True)
def etd_combination(E, x, h, coef, terms):  # pragma: no cover - compiled
    r""":math:`E x + h \sum_k c_k N_k` in one pass: an ETD stage or update. For the q spectra
    ``x``, ``terms[k]`` are ``(2, N, N//2 + 1)`` and ``E``, ``coef[k]`` real symbols
    ``(N, N//2 + 1)``; for A everything is ``(N, N)`` (then a leading axis of length 1 is
    added by the caller). ``coef`` and ``terms`` are tuples of equal length."""
    nc, nx, ny = x.shape
    out = np.empty_like(x)
    m = len(coef)
    for c in range(nc):
        for i in range(nx):
            for j in range(ny):
                acc = rmul(coef[0][i, j], terms[0][c, i, j])
                for k in range(1, m):
                    acc += rmul(coef[k][i, j], terms[k][c, i, j])
                out[c, i, j] = rmul(E[i, j], x[c, i, j]) + rmul(h, acc)
    return out


@njit(cache=True)
def rk_stage(x0, c, v):  # pragma: no cover - compiled
    r""":math:`x_0 + c\, v` in one pass (a classical Runge-Kutta stage of the integrated
    displacement, L = 0: its spectrum or its real-space gradient), the same arithmetic as
    numpy's ``x0 + c * v`` (a real ``c`` scales a complex ``v`` component by component).
    C-contiguous arrays of one shape."""
    out = np.empty_like(x0)
    of, xf, vf = out.reshape(-1), x0.reshape(-1), v.reshape(-1)
    for p in range(of.size):
        of[p] = xf[p] + rmul(c, vf[p])
    return out


@njit(cache=True)
def rk4_update(x0, c, v0, v1, v2, v3):  # pragma: no cover - compiled
    r""":math:`x_0 + c\, (v_0 + 2 v_1 + 2 v_2 + v_3)` in one pass (the classical RK4 update of
    the integrated displacement with c = h/6), summed in numpy's order for the same
    expression. C-contiguous arrays of one shape."""
    out = np.empty_like(x0)
    of, xf = out.reshape(-1), x0.reshape(-1)
    af, bf, cf, df = v0.reshape(-1), v1.reshape(-1), v2.reshape(-1), v3.reshape(-1)
    for p in range(of.size):
        s = af[p] + rmul(2.0, bf[p])
        s = s + rmul(2.0, cf[p])
        s = s + df[p]
        of[p] = xf[p] + rmul(c, s)
    return out
