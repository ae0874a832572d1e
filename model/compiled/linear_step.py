r"""Krogstad's ETDRK4 step of linear mechanics as one compiled function (numba + native FFTW).

The step of :meth:`nematic_solids.model.solver.ETDRK4Solver.step` (its readable Python, which
stays the reference and the path under a protocol, tested to agree bitwise) for a run whose
right-hand side is :func:`nematic_solids.model.compiled.linear_rhs.linear_split`: from the
state's spectra :math:`\hat q_n` and activity :math:`A_n`, the four right-hand sides

.. math::
    N_u = N(u_n), \quad N_a = N(a), \quad N_b = N(b), \quad N_c = N(c), \qquad
    a = e^{Lh/2} u_n + \tfrac h2 \tilde\varphi_1 N_u, \quad
    b = e^{Lh/2} u_n + h[(\tilde\varphi_1/2 - \tilde\varphi_2) N_u + \tilde\varphi_2 N_a], \\
    c = e^{Lh} u_n + h[(\varphi_1 - 2\varphi_2) N_u + 2\varphi_2 N_b], \quad
    u_{n+1} = e^{Lh} u_n + h[(\varphi_1 - 3\varphi_2 + 4\varphi_3) N_u
      + (2\varphi_2 - 4\varphi_3)(N_a + N_b) + (4\varphi_3 - \varphi_2) N_c]

(Krogstad 2005; :mod:`nematic_solids.model.solver`), with the q weights given and A's computed
point by point (:func:`nematic_solids.model.compiled.etd.activity_krogstad`), every stage's
inverse transforms and the new state's in the same call: the same kernels in the same order
as the Python step, so the same bits, without the Python between the stages (about 25 calls
of the interpreter per step). The step's error estimate in the max norm is formed here too
(:func:`max_norm_error`, the same value as the caller's numpy); its RMS stays with the caller.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import fftw as fx
from .arith import rmul
from .etd import activity_krogstad, etd_combination
from .linear_rhs import linear_split


@njit(cache=True)
def _stage(q_s, A_s, LA, zero_hat, rhs_data, pi, scratch):  # pragma: no cover - compiled
    """The stage's real state from its q spectra and its A, and ``(N_q hat, N_A, spin
    iterations, converged, spin, transforms)`` with :math:`N_A = \\dot A - L_A A` (the
    solver's ``rhs``)."""
    n = A_s.shape[0]
    stage = np.empty((3, n, n))
    for c in range(2):
        fx.irfft2_via(pi, q_s[c], stage[c], scratch)
    stage[2] = A_s
    Nq, Adot, omega, its, ok, nfft = linear_split(
        stage[0], stage[1], stage[2], q_s, zero_hat, rhs_data
    )
    NA = np.empty((n, n))
    for x in range(n):
        for y in range(n):
            NA[x, y] = Adot[x, y] - LA[x, y] * A_s[x, y]
    return Nq, NA, omega, its, ok, nfft + 2


@njit(cache=True)
def _next(
    q_hat, A, h, E, EA, wq, wA, Nq, NA, LA, zero_hat, rhs_data, scratch
):  # pragma: no cover - compiled
    """:func:`_stage` of the stage :math:`E \\hat q_n + h \\sum_k w_k N_k` (and its A
    alike, the terms ``NA`` with a leading axis of one): the solver's ``rhs(combo_q(...),
    combo_A(...))``."""
    return _stage(
        etd_combination(E, q_hat, h, wq, Nq),
        etd_combination(EA, _lead(A), h, wA, NA)[0],
        LA,
        zero_hat,
        rhs_data,
        rhs_data.pi,
        scratch,
    )


@njit(cache=True)
def _lead(a):  # pragma: no cover - compiled
    """The (N, N) field ``a`` with a leading axis of one (the solver's ``x[None]``)."""
    return a.reshape((1,) + a.shape)


@njit(cache=True)
def krogstad_linear_step(
    u, q_hat, h, E, E2, wa, wb, wc, wnew, zeta, s, tau, zero_hat, rhs_data, max_norm
):  # pragma: no cover - compiled
    """One step of size ``h`` from the state ``u`` (3, N, N) with ``q_hat`` (2, N, N//2 + 1)
    the spectra of its q: ``E``, ``E2`` are :math:`e^{L_q h}, e^{L_q h/2}`, ``wa``, ``wb``,
    ``wc``, ``wnew`` the q weights of stages a, b, c and the update (tuples of 1, 2, 2 and 4
    symbols, :meth:`nematic_solids.model.solver.ETDRK4Solver._weights_from`), ``rhs_data``
    the run's :class:`nematic_solids.model.compiled.linear_rhs.LinearRHS`. Returns ``(new
    state (3, N, N), its q spectra, N_q at a and b, N_A at a and b, A's weight of N_a + N_b,
    the spin solves' iterations (4), whether they converged (4), the last stage's spin,
    the error estimate in the max norm if ``max_norm`` (:func:`max_norm_error`; else NaN: the
    caller forms its RMS), transforms)``; every spin solve starts from ``zero_hat``."""
    n = u.shape[1]
    pi = rhs_data.pi
    scratch = fx.aligned_half(n)
    A = u[2]
    LA, W = activity_krogstad(A, h, zeta, s, tau)
    its = np.zeros(4, dtype=np.int64)
    ok = np.zeros(4, dtype=np.bool_)
    Nq_u, Adot_u, omega, it, conv, nfft = linear_split(u[0], u[1], A, q_hat, zero_hat, rhs_data)
    its[0], ok[0] = it, conv
    NA_u = np.empty((n, n))
    for x in range(n):
        for y in range(n):
            NA_u[x, y] = Adot_u[x, y] - LA[x, y] * A[x, y]
    # stage a (t + h/2), b (t + h/2), c (t + h): e^{L h/2} or e^{L h} (q, then A), the
    # weights of the N terms for q and for A, the terms
    Nq_a, NA_a, omega, it, conv, k = _next(
        q_hat, A, h, E2, W[1], wa, (W[2],), (Nq_u,), (_lead(NA_u),), LA, zero_hat, rhs_data, scratch
    )
    its[1], ok[1], nfft = it, conv, nfft + k
    Nq_b, NA_b, omega, it, conv, k = _next(
        q_hat, A, h, E2, W[1], wb, (W[3], W[4]), (Nq_u, Nq_a), (_lead(NA_u), _lead(NA_a)),
        LA, zero_hat, rhs_data, scratch,
    )  # fmt: skip
    its[2], ok[2], nfft = it, conv, nfft + k
    Nq_c, NA_c, omega, it, conv, k = _next(
        q_hat, A, h, E, W[0], wc, (W[5], W[6]), (Nq_u, Nq_b), (_lead(NA_u), _lead(NA_b)),
        LA, zero_hat, rhs_data, scratch,
    )  # fmt: skip
    its[3], ok[3], nfft = it, conv, nfft + k
    new_q_hat = etd_combination(E, q_hat, h, wnew, (Nq_u, Nq_a, Nq_b, Nq_c))
    new = np.empty((3, n, n))
    new[2] = etd_combination(
        W[0],
        _lead(A),
        h,
        (W[7], W[8], W[8], W[9]),
        (_lead(NA_u), _lead(NA_a), _lead(NA_b), _lead(NA_c)),
    )[0]
    for j in range(2):
        fx.irfft2_via(pi, new_q_hat[j], new[j], scratch)
    nfft += 2
    err = np.nan
    if max_norm:
        err = max_norm_error(h, wnew[1], Nq_a, Nq_b, W[8], NA_a, NA_b, pi, scratch)
        nfft += 2
    return new, new_q_hat, Nq_a, Nq_b, NA_a, NA_b, W[8], its, ok, omega, err, nfft


@njit(cache=True)
def max_norm_error(h, wq, Nq_a, Nq_b, wA, NA_a, NA_b, pi, scratch):  # pragma: no cover
    r"""The step's error estimate in the max norm (:meth:`nematic_solids.model.solver_base.
    ETDSolver._finish`): the largest of :math:`|e_q|` in real space, :math:`e_q = h w_{ab}
    (\hat N_{q,b} - \hat N_{q,a})` (each component's inverse transform), and of :math:`|e_A|`,
    :math:`e_A = h w_{ab} (N_{A,b} - N_{A,a})`. The same values as the numpy expressions:
    the products are formed in the same order, and the inverse transform's 1/N^2 applied
    to the largest magnitude (rounding is monotone: the largest of the scaled values).
    ``scratch``: an aligned half spectrum (overwritten)."""
    n = NA_a.shape[0]
    work = fx.aligned_real(n)
    nx, ny = wq.shape
    err = 0.0
    finite = True  # a NaN makes the estimate NaN, as numpy's max does
    for c in range(2):
        for i in range(nx):
            for j in range(ny):
                scratch[i, j] = rmul(h * wq[i, j], Nq_b[c, i, j] - Nq_a[c, i, j])
        if not fx.unscaled_irfft2_via(pi, scratch, work, scratch):
            raise ValueError("the error's work array is not aligned for FFTW")
        big = 0.0
        for x in range(n):
            for y in range(n):
                v = abs(work[x, y])
                big = max(big, v)
                finite &= v == v
        err = max(err, big * (1.0 / (n * n)))
    for x in range(n):
        for y in range(n):
            v = abs(h * wA[x, y] * (NA_b[x, y] - NA_a[x, y]))
            err = max(err, v)
            finite &= v == v
    return err if finite else np.nan
