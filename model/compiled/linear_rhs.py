r"""The linear-mechanics right-hand side as one compiled function (numba + native FFTW).

Computes exactly what :meth:`nematic_solids.model.split.SpectralSplit.reference` computes (its
readable numpy path, which stays the reference and the fallback, tested to agree): from the state
q1, q2, A and the spectra of q1, q2,

.. math::
    \hat H = \widehat{b(q, A)\, q} + B\, \widehat{\mathrm{dev}\, e}, \quad
    R = \hat H/\gamma + L_q \hat q, \quad
    (I - M)\,\hat\omega = \Omega[R], \quad M \hat\omega = \Omega[\widehat{2 \omega J q}], \\
    \hat N_q = R + \widehat{2\omega J q} - L_q \hat q, \qquad
    \dot A = (-\zeta A - \chi\, \mathrm{tr}\,\sigma - s A^3)/\tau \quad (\text{Eq. 5}),

with :math:`b = A + C\, Q:Q - 2 B' \mathrm{tr}\, e` (Eq. 4; A0 and the Frank term are in
:math:`L_q`), the small-strain response of
:func:`nematic_solids.model.compiled.spectral.linear_response` (as its real Fourier symbols ``S``,
:meth:`nematic_solids.model.mechanics.LinearMechanics.response_symbols`, applied point by point),
and the spin equation (the Jaumann term,
:meth:`nematic_solids.model.mechanics.LinearMechanics.corotational_hat`) solved by the same
restarted GMRES as :func:`nematic_solids.model.krylov.gmres_aux` (Saad Alg. 9.5, no preconditioner,
started from zero, Givens-rotated residual, modified Gram-Schmidt, Parseval inner product), here
without leaving compiled code: the transforms run through :mod:`nematic_solids.model.compiled.fftw`.

Only built where :data:`nematic_solids.model.compiled.fftw.AVAILABLE`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numba.extending import overload

from . import fftw as fx
from .arith import rmul
from .krylov import apply_operator, apply_operator_given_aux, gmres, precondition
from .rates import activity_rate, bulk_terms

Array = np.ndarray


@njit(cache=True)
def _spin_operator(x, q1, q2, m1, m2, pf, pi, omega, prod, scratch, out, jout):  # pragma: no cover
    """``out = (I - M) x`` and ``jout`` = the spectra of :math:`2 \\omega J q` for
    :math:`\\hat\\omega = x` (3 transforms); ``omega``, ``prod`` are real work arrays,
    ``scratch`` a half spectrum for the inverse transform."""
    n = q1.shape[0]
    if not fx.unscaled_irfft2_via(pi, x, omega, scratch):
        raise ValueError("the spin work array is not aligned for FFTW")
    two_scale = 2.0 / (n * n)  # the inverse transform's 1/N^2 (a power of two: exact)
    for a in range(n):
        for b in range(n):
            w = two_scale * omega[a, b]
            prod[0, a, b] = -w * q2[a, b]
            prod[1, a, b] = w * q1[a, b]
    fx.rfft2(pf, prod[0], jout[0])
    fx.rfft2(pf, prod[1], jout[1])
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            out[i, j] = x[i, j] - (rmul(m1[i, j], jout[0, i, j]) + rmul(m2[i, j], jout[1, i, j]))


class SpinOperator(NamedTuple):
    """The spin operator :math:`I - M` of :func:`_spin_operator` for the compiled
    :func:`nematic_solids.model.compiled.krylov.gmres` (no preconditioner; the auxiliary output is
    the Jaumann rate): the state's q1, q2, the spin symbols, the plans and the work arrays."""

    q1: Array
    q2: Array
    m1: Array
    m2: Array
    pf: int
    pi: int
    omega: Array
    prod: Array
    scratch: Array


@overload(apply_operator)
def _apply_spin(op, x, out, aux):  # pragma: no cover - compiled
    if getattr(op, "instance_class", None) is SpinOperator:  # the named tuple type

        def impl(op, x, out, aux):
            _spin_operator(
                x, op.q1, op.q2, op.m1, op.m2, op.pf, op.pi, op.omega, op.prod, op.scratch, out, aux
            )

        return impl
    return None


@overload(apply_operator_given_aux)
def _apply_spin_given_jaumann(op, x, aux, out):  # pragma: no cover - compiled
    if getattr(op, "instance_class", None) is SpinOperator:  # the named tuple type

        def impl(op, x, aux, out):  # aux: the Jaumann spectra of x (the last pass above)
            for i in range(x.shape[0]):
                for j in range(x.shape[1]):
                    out[i, j] = x[i, j] - (
                        rmul(op.m1[i, j], aux[0, i, j]) + rmul(op.m2[i, j], aux[1, i, j])
                    )

        return impl
    return None


@overload(precondition)
def _precondition_spin(op, v, out):  # pragma: no cover - compiled
    if getattr(op, "instance_class", None) is SpinOperator:  # the named tuple type

        def impl(op, v, out):  # unpreconditioned: out is v (the basis is its own)
            pass

        return impl
    return None


@njit(cache=True)
def spin_gmres(b, x0, q1, q2, m1, m2, w, pf, pi, rtol, maxiter, V, LZ):  # pragma: no cover
    """Solve :math:`(I - M)\\hat\\omega = b` by :func:`nematic_solids.model.compiled.krylov.gmres`
    from ``x0``; returns ``(omega_hat, j_hat, iterations, converged, operator applications)`` with
    ``j_hat`` the spectra of :math:`2\\omega J q` at the solution (the auxiliary output). The Krylov
    basis ``V`` (restart + 1 spectra) and its Jaumann rates ``LZ`` (restart pairs) are caller-owned
    work arrays."""
    n = q1.shape[0]
    op = SpinOperator(
        q1, q2, m1, m2, pf, pi, np.empty((n, n)), np.empty((2, n, n)), fx.aligned_half(n)
    )
    no_aux = np.empty((0, 1, 1), dtype=np.complex128)  # the start's Jaumann rate: unknown
    x, jx, its, ok, nop, _ = gmres(op, b, x0, no_aux, w, rtol, maxiter, V, V, LZ)
    return x, jx, its, ok, nop


def workspace(n: int, restart: int = 30) -> tuple[Array, Array]:
    """The ``(V, LZ)`` work arrays of :func:`spin_gmres` for an N x N grid."""
    shape = (n, n // 2 + 1)
    return (
        np.empty((restart + 1,) + shape, dtype=np.complex128),
        np.empty((restart, 2) + shape, dtype=np.complex128),
    )


class LinearRHS(NamedTuple):
    """What :func:`linear_split` needs besides the state, fixed for a run: the symbols
    (``Lq``, the spin symbols ``m1``, ``m2``, the small-strain response ``S``), the Parseval
    weights ``w``, the FFTW plans, the applied mean strain ``mean_dev`` (eps N^2), the
    constants of Eqs. (4)-(5), the spin solve's tolerance and iteration cap, its work
    arrays ``V``, ``LZ`` (:func:`workspace`), and under a protocol the rate of alpha - B
    ``spin_rate`` with the spin symbols per unit alpha - B ``mu1``, ``mu2`` (the spin source
    :meth:`nematic_solids.model.mechanics.LinearMechanics.spin_source`). The constants that a
    protocol changes are replaced with ``_replace``
    (:class:`nematic_solids.model.split.SpectralSplit`)."""

    Lq: Array
    m1: Array
    m2: Array
    S: Array
    w: Array
    pf: int
    pi: int
    mean_dev: float
    B: float
    Bp: float
    C: float
    gamma: float
    zeta: float
    chi: float
    s: float
    tau: float
    spin_tol: float
    maxiter: int
    V: Array
    LZ: Array
    mu1: Array
    mu2: Array
    spin_rate: float


@njit(cache=True)
def linear_split(q1, q2, A, q_hat, omega_hat, rhs_data):  # pragma: no cover
    """``(N_q hat, Adot, omega_hat, spin iterations, converged, transforms)`` for the state
    (see the module docstring) and the run's fixed data ``rhs_data`` (a :class:`LinearRHS`);
    ``omega_hat`` is the start of the spin solve (zeros from the solver: no operator
    application for its residual). The small-strain response ``S[r, c]`` (outputs r: dev e
    (2 comps), tr e, tr sigma; inputs c: q1 hat, q2 hat, -B' Q:Q hat; the symbols of
    :meth:`nematic_solids.model.mechanics.LinearMechanics.response_symbols`) is applied point by
    point where it is used, so that no response spectra are stored (the passes over memory, not the
    arithmetic, are what this costs); with B' = 0 the Q:Q column and tr e are skipped."""
    (
        Lq,
        m1,
        m2,
        S,
        w,
        pf,
        pi,
        mean_dev,
        B,
        Bp,
        C,
        gamma,
        zeta,
        chi,
        s,
        tau,
        spin_tol,
        maxiter,
        V,
        LZ,
        mu1,
        mu2,
        spin_rate,
    ) = rhs_data
    n = q1.shape[0]
    shape = q_hat.shape[1:]
    nx, ny = shape
    nfft = 0
    tr_s_hat = np.empty(shape, dtype=np.complex128)
    tr_e = np.zeros((n, n))
    if Bp != 0.0:
        qq = np.empty((n, n))
        for x in range(n):
            for y in range(n):
                qq[x, y] = 2.0 * (q1[x, y] ** 2 + q2[x, y] ** 2)
        iso = np.empty(shape, dtype=np.complex128)
        fx.rfft2(pf, qq, iso)
        nfft += 1
        tr_e_hat = np.empty(shape, dtype=np.complex128)
        for i in range(nx):
            for j in range(ny):
                a = q_hat[0, i, j]
                b = q_hat[1, i, j]
                c = rmul(-Bp, iso[i, j])
                iso[i, j] = c
                tr_e_hat[i, j] = (
                    rmul(S[2, 0, i, j], a) + rmul(S[2, 1, i, j], b) + rmul(S[2, 2, i, j], c)
                )
                tr_s_hat[i, j] = (
                    rmul(S[3, 0, i, j], a) + rmul(S[3, 1, i, j], b) + rmul(S[3, 2, i, j], c)
                )
        fx.irfft2_via(pi, tr_e_hat, tr_e, tr_e_hat)
        nfft += 1
    else:
        iso = np.empty((1, 1), dtype=np.complex128)  # not read
        for i in range(nx):
            for j in range(ny):
                tr_s_hat[i, j] = rmul(S[3, 0, i, j], q_hat[0, i, j]) + rmul(
                    S[3, 1, i, j], q_hat[1, i, j]
                )
    tr_s = np.empty((n, n))
    fx.irfft2_via(pi, tr_s_hat, tr_s, tr_s_hat)
    nfft += 1
    bulk = bulk_terms(q1, q2, A, tr_e, C, 2.0 * Bp)
    R = np.empty((2,) + shape, dtype=np.complex128)
    fx.rfft2(pf, bulk[0], R[0])
    fx.rfft2(pf, bulk[1], R[1])
    nfft += 2
    rhs = np.empty(shape, dtype=np.complex128)
    for i in range(nx):
        for j in range(ny):
            a = q_hat[0, i, j]
            b = q_hat[1, i, j]
            d0 = rmul(S[0, 0, i, j], a) + rmul(S[0, 1, i, j], b)
            d1 = rmul(S[1, 0, i, j], a) + rmul(S[1, 1, i, j], b)
            if Bp != 0.0:
                d0 += rmul(S[0, 2, i, j], iso[i, j])
                d1 += rmul(S[1, 2, i, j], iso[i, j])
            if i == 0 and j == 0:
                d0 += mean_dev  # the applied mean strain
            h0 = R[0, i, j] + rmul(B, d0)  # H / gamma, divided component by component
            h1 = R[1, i, j] + rmul(B, d1)  # (numba would divide by gamma as complex)
            r0 = complex(h0.real / gamma, h0.imag / gamma) + rmul(Lq[i, j], a)
            r1 = complex(h1.real / gamma, h1.imag / gamma) + rmul(Lq[i, j], b)
            R[0, i, j] = r0
            R[1, i, j] = r1
            rhs[i, j] = rmul(m1[i, j], r0) + rmul(m2[i, j], r1)
            if spin_rate != 0.0:  # the spin a rate of alpha - B drives at fixed Q
                rhs[i, j] += spin_rate * (rmul(mu1[i, j], a) + rmul(mu2[i, j], b))
    omega_hat, j_hat, its, ok, nop = spin_gmres(
        rhs, omega_hat, q1, q2, m1, m2, w, pf, pi, spin_tol, maxiter, V, LZ
    )
    nfft += 3 * nop
    for c in range(2):
        for i in range(nx):
            for j in range(ny):
                R[c, i, j] += j_hat[c, i, j] - rmul(Lq[i, j], q_hat[c, i, j])
    Adot = activity_rate(A, tr_s, zeta, chi, s, tau)
    return R, Adot, omega_hat, its, ok, nfft
