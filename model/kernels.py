"""Fast pointwise kernels (numba, compiled once per machine: ``cache=True``).

Each kernel has a readable numpy reference in :mod:`model.constitutive` and a test that they
agree (``tests/test_model_constitutive.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import overload


def rmul(c, z):
    """``c * z`` for a real ``c``; compiled, a complex ``z`` is scaled component by component
    (numba would promote ``c`` to complex and multiply as complex numbers: twice the work, and
    in the hot loops below that work, not memory, was the limit; the values are the same)."""
    return c * z


@overload(rmul)
def _rmul_compiled(c, z):  # pragma: no cover - compiled
    if isinstance(z, types.Complex):
        return lambda c, z: complex(c * z.real, c * z.imag)
    return lambda c, z: c * z


def imul(c, z):
    """``1j * c * z`` for a real ``c`` and a complex ``z``, compiled as
    ``complex(-c z.imag, c z.real)`` (see :func:`rmul`)."""
    return 1j * c * z


@overload(imul)
def _imul_compiled(c, z):  # pragma: no cover - compiled
    return lambda c, z: complex(-c * z.imag, c * z.real)


@njit(cache=True, inline="always", error_model="numpy")
def _dS(d00, d01, d11, i00, i01, i11, s1_00, s1_01, s1_11, s3_00, s3_01, s3_11, J, I1, CQ,
        qq, a, b, kappa, B, Bp):  # pragma: no cover - compiled
    """The increment of the second Piola stress S (symmetric: components 00, 01, 11) for the
    symmetric increment dC = [[d00, d01], [d01, d11]] of C (:func:`tangent_kernel`)."""
    c = i00 * d00 + 2.0 * i01 * d01 + i11 * d11  # C^-1 : dC
    dCQ = d00 * a + 2.0 * d01 * b - d11 * a  # dC : Q
    trdC = d00 + d11
    t00 = d00 * i00 + d01 * i01  # dC C^-1
    t01 = d00 * i01 + d01 * i11
    t10 = d01 * i00 + d11 * i01
    t11 = d01 * i01 + d11 * i11
    e00 = -(i00 * t00 + i01 * t10)  # dC^-1 = -C^-1 dC C^-1
    e01 = -(i00 * t01 + i01 * t11)
    e11 = -(i01 * t01 + i11 * t11)
    k1 = kappa * (2.0 * J - 1.0) * 0.5 * J * c
    k2 = kappa * (J * J - J)
    b1 = 0.5 * B * dCQ / J
    b2 = 0.5 * B * CQ / J
    p1 = Bp * qq * 0.5 * J * c
    p2 = Bp * qq * J
    out00 = (-0.5 * c * (s1_00 + s3_00) + (-0.5 * trdC * i00 - 0.5 * I1 * e00) / J
             + k1 * i00 + k2 * e00 + b1 * i00 + b2 * e00 - p1 * i00 - p2 * e00)
    out01 = (-0.5 * c * (s1_01 + s3_01) + (-0.5 * trdC * i01 - 0.5 * I1 * e01) / J
             + k1 * i01 + k2 * e01 + b1 * i01 + b2 * e01 - p1 * i01 - p2 * e01)
    out11 = (-0.5 * c * (s1_11 + s3_11) + (-0.5 * trdC * i11 - 0.5 * I1 * e11) / J
             + k1 * i11 + k2 * e11 + b1 * i11 + b2 * e11 - p1 * i11 - p2 * e11)
    return out00, out01, out11


@njit(cache=True, inline="always")
def _point_kinematics(F, x, y):  # pragma: no cover - compiled
    """At grid point (x, y): F's components f00, f01, f10, f11, J = det F and the components
    c00, c01, c11 of C = F^T F."""
    f00 = F[0, 0, x, y]
    f01 = F[0, 1, x, y]
    f10 = F[1, 0, x, y]
    f11 = F[1, 1, x, y]
    return (f00, f01, f10, f11, f00 * f11 - f01 * f10, f00 * f00 + f10 * f10,
            f00 * f01 + f10 * f11, f01 * f01 + f11 * f11)


@njit(cache=True, error_model="numpy")
def tangent_kernel(F, q1, q2, kappa, B, Bp, alpha):  # pragma: no cover - compiled
    r""":math:`K_{iJkL} = \partial P_{iJ}/\partial F_{kL}`, the same formulas as
    :func:`model.constitutive.first_piola_increment` applied to the four unit directions
    :math:`dF = e_k \otimes e_L` (then :math:`dC = dF^T F + F^T dF`, symmetric), evaluated
    point by point with scalars: :math:`dP = dF\, S + F\, dS`."""
    nx, ny = q1.shape
    K = np.empty((2, 2, 2, 2, nx, ny))
    for x in range(nx):
        for y in range(ny):
            f00, f01, f10, f11, J, c00, c01, c11 = _point_kinematics(F, x, y)
            a = q1[x, y]  # Q = [[a, b], [b, -a]]
            b = q2[x, y]
            I1 = c00 + c11
            detC = c00 * c11 - c01 * c01
            i00 = c11 / detC
            i01 = -c01 / detC
            i11 = c00 / detC
            qq = 2.0 * (a * a + b * b)
            CQ = c00 * a + 2.0 * c01 * b - c11 * a
            s1_00 = (1.0 - 0.5 * I1 * i00) / J
            s1_01 = (-0.5 * I1 * i01) / J
            s1_11 = (1.0 - 0.5 * I1 * i11) / J
            s3_00 = -B * (a - 0.5 * CQ * i00) / J
            s3_01 = -B * (b - 0.5 * CQ * i01) / J
            s3_11 = -B * (-a - 0.5 * CQ * i11) / J
            iso = kappa * (J - 1.0) * J - Bp * qq * J
            S00 = s1_00 + iso * i00 + s3_00 + alpha * a
            S01 = s1_01 + iso * i01 + s3_01 + alpha * b
            S11 = s1_11 + iso * i11 + s3_11 - alpha * a
            for k in range(2):
                fk0 = f00 if k == 0 else f10
                fk1 = f01 if k == 0 else f11
                for L in range(2):
                    # dC_ab = delta_aL F_kb + delta_bL F_ka
                    if L == 0:
                        d00, d01, d11 = 2.0 * fk0, fk1, 0.0
                    else:
                        d00, d01, d11 = 0.0, fk0, 2.0 * fk1
                    ds00, ds01, ds11 = _dS(d00, d01, d11, i00, i01, i11, s1_00, s1_01, s1_11,
                                           s3_00, s3_01, s3_11, J, I1, CQ, qq, a, b, kappa,
                                           B, Bp)
                    # (dF S)_ij = delta_ik S_Lj, (F dS)_ij = F_i0 dS_0j + F_i1 dS_1j
                    SL0 = S00 if L == 0 else S01
                    SL1 = S01 if L == 0 else S11
                    K[0, 0, k, L, x, y] = f00 * ds00 + f01 * ds01 + (SL0 if k == 0 else 0.0)
                    K[0, 1, k, L, x, y] = f00 * ds01 + f01 * ds11 + (SL1 if k == 0 else 0.0)
                    K[1, 0, k, L, x, y] = f10 * ds00 + f11 * ds01 + (SL0 if k == 1 else 0.0)
                    K[1, 1, k, L, x, y] = f10 * ds01 + f11 * ds11 + (SL1 if k == 1 else 0.0)
    return K


@njit(cache=True)
def apply_tangent_kernel(K, dF):  # pragma: no cover - compiled
    """:math:`dP_{iJ} = K_{iJkL} dF_{kL}` point by point (reference:
    :func:`model.constitutive.apply_tangent`)."""
    nx, ny = dF.shape[2], dF.shape[3]
    out = np.empty((2, 2, nx, ny))
    for i in range(2):
        for j in range(2):
            for x in range(nx):
                for y in range(ny):
                    out[i, j, x, y] = (K[i, j, 0, 0, x, y] * dF[0, 0, x, y]
                                       + K[i, j, 0, 1, x, y] * dF[0, 1, x, y]
                                       + K[i, j, 1, 0, x, y] * dF[1, 0, x, y]
                                       + K[i, j, 1, 1, x, y] * dF[1, 1, x, y])
    return out


# --- pointwise pieces of the time stepper (references: model.solver / model.pde) -----------

#: 1/j! for j = 0..21, the Taylor coefficients of the phi functions
_RECIP_FACT = np.array([1.0 / float(np.prod(np.arange(1, j + 1))) for j in range(22)])


@njit(cache=True)
def _phi123_from(z, em1):  # pragma: no cover - compiled
    """:math:`\varphi_{1,2,3}(z)` given :math:`e^z - 1`: Taylor series (Horner, 19 terms:
    truncation < 1e-17) for |z| < 1, the recursion :math:`\varphi_{k+1} = (\varphi_k - 1/k!)/z`
    otherwise (the same branches as :func:`model.solver.phi_functions`)."""
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
def activity_krogstad(A, h, zeta, s, tau):  # pragma: no cover - compiled
    r"""For the ETDRK4 step of the activity: :math:`L_A = -(\zeta + 3 s A^2)/\tau` and,
    point by point, Krogstad's weights (:meth:`model.solver.ETDRK4Solver._weights_from`) from
    :math:`f_k = \varphi_k(z)`, :math:`g_k = \varphi_k(z/2)` at :math:`z = h L_A`:
    ``W[0:2]`` = :math:`e^{z}, e^{z/2}`; ``W[2]`` = g1/2 (stage a); ``W[3:5]`` = g1/2 - g2, g2
    (stage b); ``W[5:7]`` = f1 - 2 f2, 2 f2 (stage c); ``W[7:10]`` = f1 - 3 f2 + 4 f3,
    2 f2 - 4 f3, 4 f3 - f2 (the update). Returns ``(L_A, W)``; one pass, no temporaries."""
    nx, ny = A.shape
    L = np.empty((nx, ny))
    W = np.empty((10, nx, ny))
    for x in range(nx):
        for y in range(ny):
            a = A[x, y]
            lam = -(zeta + 3.0 * s * a * a) / tau
            L[x, y] = lam
            z = lam * h
            # one transcendental per point: e^z - 1 = (e^{z/2} - 1)(e^{z/2} + 1), with
            # e^{z/2} from exp where it is small (1 + expm1 would lose its relative accuracy)
            if z < -1.0:
                e_half = np.exp(0.5 * z)
                em1_half = e_half - 1.0
            else:
                em1_half = np.expm1(0.5 * z)
                e_half = 1.0 + em1_half
            f1, f2, f3 = _phi123_from(z, em1_half * (e_half + 1.0))
            g1, g2, _ = _phi123_from(0.5 * z, em1_half)
            W[0, x, y] = e_half * e_half
            W[1, x, y] = e_half
            W[2, x, y] = 0.5 * g1
            W[3, x, y] = 0.5 * g1 - g2
            W[4, x, y] = g2
            W[5, x, y] = f1 - 2.0 * f2
            W[6, x, y] = 2.0 * f2
            W[7, x, y] = f1 - 3.0 * f2 + 4.0 * f3
            W[8, x, y] = 2.0 * f2 - 4.0 * f3
            W[9, x, y] = 4.0 * f3 - f2
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
def bulk_terms(q1, q2, A, tr_e, C, two_Bp):  # pragma: no cover - compiled
    r"""``[-b q1, -b q2]`` with :math:`b = A + C\, Q:Q - 2 B' \mathrm{tr}\, e` (the
    non-constant part of the Landau-de Gennes bulk term in H, Eq. 4; ``A0`` is in L_q)."""
    nx, ny = q1.shape
    out = np.empty((2, nx, ny))
    for x in range(nx):
        for y in range(ny):
            a = q1[x, y]
            b = q2[x, y]
            bulk = A[x, y] + C * 2.0 * (a * a + b * b) - two_Bp * tr_e[x, y]
            out[0, x, y] = -bulk * a
            out[1, x, y] = -bulk * b
    return out


@njit(cache=True)
def activity_rate(A, trP, zeta, chi, s, tau):  # pragma: no cover - compiled
    r"""Paper Eq. (5): :math:`(-\zeta A - \chi\, \mathrm{tr} P - s A^3)/\tau`."""
    nx, ny = A.shape
    out = np.empty((nx, ny))
    for x in range(nx):
        for y in range(ny):
            a = A[x, y]
            out[x, y] = (-zeta * a - chi * trP[x, y] - s * a * a * a) / tau
    return out


@njit(cache=True)
def jaumann_products(omega, q1, q2):  # pragma: no cover - compiled
    r"""The corotational rate :math:`2 \omega J q = [-2 \omega q_2, 2 \omega q_1]`."""
    nx, ny = q1.shape
    out = np.empty((2, nx, ny))
    for x in range(nx):
        for y in range(ny):
            w = 2.0 * omega[x, y]
            out[0, x, y] = -w * q2[x, y]
            out[1, x, y] = w * q1[x, y]
    return out


@njit(cache=True)
def symbol_combination(x, m1, m2, a, b):  # pragma: no cover - compiled
    r""":math:`x - (m_1 a + m_2 b)` for half spectra ``a, b`` and real symbols ``m1, m2``
    (``x`` may be a zero array): the spin multiplier of the linear mechanics, fused."""
    nx, ny = a.shape
    out = np.empty((nx, ny), dtype=np.complex128)
    for i in range(nx):
        for j in range(ny):
            out[i, j] = x[i, j] - (m1[i, j] * a[i, j] + m2[i, j] * b[i, j])
    return out


@njit(cache=True)
def linear_response(q1h, q2h, isoh, kx, ky, khx, khy, inv_k2, amb, a, kappa,
                    incompressible, mean_dev):  # pragma: no cover - compiled
    r"""Fused :meth:`model.mechanics.LinearMechanics.spectral_response`: from the spectra of
    q1, q2 (and of the isotropic eigenstress ``isoh`` = -B' Q:Q hat, zeros if B' = 0) return
    the spectra ``dev e`` (2 components), ``tr e`` and ``tr sigma`` of the small-strain
    solution; ``a`` is the Green operator's kappa / (kappa + 1) (1 if incompressible) and
    ``mean_dev`` the applied eps times N^2 (the mean of dev e in unnormalised spectra)."""
    nx, ny = q1h.shape
    dev = np.empty((2, nx, ny), dtype=np.complex128)
    tr_e = np.empty((nx, ny), dtype=np.complex128)
    tr_s = np.empty((nx, ny), dtype=np.complex128)
    for i in range(nx):
        for j in range(ny):
            t11 = amb * q1h[i, j]
            t12 = amb * q2h[i, j]
            iso = isoh[i, j]
            k1 = kx[i, j]
            k2 = ky[i, j]
            b1 = 1j * (k1 * (t11 + iso) + k2 * t12)
            b2 = 1j * (k1 * t12 + k2 * (-t11 + iso))
            h1 = khx[i, j]
            h2 = khy[i, j]
            kb = h1 * b1 + h2 * b2
            u1 = (b1 - a * h1 * kb) * inv_k2[i, j]
            u2 = (b2 - a * h2 * kb) * inv_k2[i, j]
            e11 = 1j * k1 * u1
            e22 = 1j * k2 * u2
            e12 = 0.5j * (k2 * u1 + k1 * u2)
            dev[0, i, j] = 0.5 * (e11 - e22)
            dev[1, i, j] = e12
            tr_e[i, j] = e11 + e22
            if incompressible:
                p = (h1 * h1 - h2 * h2) * t11 + 2.0 * h1 * h2 * t12
                if inv_k2[i, j] != 0.0:
                    p += iso
                tr_s[i, j] = -2.0 * p + 2.0 * iso
            else:
                tr_s[i, j] = 2.0 * kappa * (e11 + e22) + 2.0 * iso
    dev[0, 0, 0] += mean_dev
    return dev, tr_e, tr_s


# --- finite-strain stress and spectral operators (references: model.constitutive,
#     model.fourier.SpectralGrid, model.mechanics) ----------------------------------------

@njit(cache=True, error_model="numpy")
def _stress_point(a, b, c, d, q1, q2, d1, d2, kappa, B, Bp, alpha, active):  # pragma: no cover
    """First Piola stress at one point, F = [[a, b], [c, d]]; if ``active`` the full Eq. (2)
    stress for Q = (q1, q2), else the Q-increment :math:`\\partial P/\\partial Q : dQ` for
    dQ = (d1, d2). Returns (P00, P01, P10, P11)."""
    C00 = a * a + c * c
    C01 = a * b + c * d
    C11 = b * b + d * d
    J = a * d - b * c
    J2 = J * J
    Ci00 = C11 / J2
    Ci01 = -C01 / J2
    Ci11 = C00 / J2
    if active:
        I1 = C00 + C11
        CQ = (C00 - C11) * q1 + 2.0 * C01 * q2
        qq = 2.0 * (q1 * q1 + q2 * q2)
        iso = kappa * (J - 1.0) * J - Bp * qq * J  # coefficient of C^-1
        S00 = (1.0 - 0.5 * I1 * Ci00) / J + iso * Ci00 - B * (q1 - 0.5 * CQ * Ci00) / J \
            + alpha * q1
        S01 = (-0.5 * I1 * Ci01) / J + iso * Ci01 - B * (q2 - 0.5 * CQ * Ci01) / J + alpha * q2
        S11 = (1.0 - 0.5 * I1 * Ci11) / J + iso * Ci11 - B * (-q1 - 0.5 * CQ * Ci11) / J \
            - alpha * q1
    else:
        CdQ = (C00 - C11) * d1 + 2.0 * C01 * d2
        QdQ = 2.0 * (q1 * d1 + q2 * d2)
        iso = -2.0 * Bp * QdQ * J
        S00 = -B * (d1 - 0.5 * CdQ * Ci00) / J + iso * Ci00 + alpha * d1
        S01 = -B * (d2 - 0.5 * CdQ * Ci01) / J + iso * Ci01 + alpha * d2
        S11 = -B * (-d1 - 0.5 * CdQ * Ci11) / J + iso * Ci11 - alpha * d1
    return (a * S00 + b * S01, a * S01 + b * S11, c * S00 + d * S01, c * S01 + d * S11)


@njit(cache=True, error_model="numpy")
def _stress_field(F, q1, q2, d1, d2, kappa, B, Bp, alpha, active):  # pragma: no cover
    """:func:`_stress_point` at every grid point, as a (2, 2, nx, ny) array."""
    nx, ny = q1.shape
    P = np.empty((2, 2, nx, ny))
    for x in range(nx):
        for y in range(ny):
            p00, p01, p10, p11 = _stress_point(F[0, 0, x, y], F[0, 1, x, y], F[1, 0, x, y],
                                               F[1, 1, x, y], q1[x, y], q2[x, y], d1[x, y],
                                               d2[x, y], kappa, B, Bp, alpha, active)
            P[0, 0, x, y] = p00
            P[0, 1, x, y] = p01
            P[1, 0, x, y] = p10
            P[1, 1, x, y] = p11
    return P


@njit(cache=True)
def first_piola_kernel(F, q1, q2, kappa, B, Bp, alpha):  # pragma: no cover - compiled
    """:math:`P = F \\mathbf S(F, Q)`, paper Eq. (2) (reference:
    :func:`model.constitutive.first_piola`)."""
    return _stress_field(F, q1, q2, q1, q2, kappa, B, Bp, alpha, True)


@njit(cache=True)
def q_increment_kernel(F, q1, q2, d1, d2, B, Bp, alpha):  # pragma: no cover - compiled
    """:math:`\\partial P/\\partial Q : dQ` at fixed F for dQ = nematic(d1, d2) (reference:
    :func:`model.constitutive.first_piola_q_increment`; kappa does not enter)."""
    return _stress_field(F, q1, q2, d1, d2, 0.0, B, Bp, alpha, False)


@njit(cache=True)
def grad_hat_kernel(v, kx, ky):  # pragma: no cover - compiled
    """:math:`\\widehat{\\partial_j v_i} = i k_j \\hat v_i` (reference:
    :meth:`model.fourier.SpectralGrid.grad_hat`)."""
    nx, ny = kx.shape
    out = np.empty((2, 2, nx, ny), dtype=np.complex128)
    for i in range(2):
        for x in range(nx):
            for y in range(ny):
                z = v[i, x, y]
                out[i, 0, x, y] = imul(kx[x, y], z)
                out[i, 1, x, y] = imul(ky[x, y], z)
    return out


@njit(cache=True)
def neg_div_hat_kernel(T, kx, ky):  # pragma: no cover - compiled
    """:math:`-i k_j \\hat T_{ij}` (reference: minus
    :meth:`model.fourier.SpectralGrid.div_hat`)."""
    nx, ny = kx.shape
    out = np.empty((2, nx, ny), dtype=np.complex128)
    for i in range(2):
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] = imul(-1.0, rmul(kx[x, y], T[i, 0, x, y])
                                    + rmul(ky[x, y], T[i, 1, x, y]))
    return out


@njit(cache=True)
def div_hat_kernel(T, kx, ky):  # pragma: no cover - compiled
    r""":math:`i k_j \hat T_{ij}` (reference: :meth:`model.fourier.SpectralGrid.div_hat`)."""
    nx, ny = kx.shape
    out = np.empty((2, nx, ny), dtype=np.complex128)
    for i in range(2):
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] = imul(1.0, rmul(kx[x, y], T[i, 0, x, y])
                                    + rmul(ky[x, y], T[i, 1, x, y]))
    return out


@njit(cache=True, error_model="numpy")
def strain_measures_kernel(F, P):  # pragma: no cover - compiled
    r"""From F and P, point by point: the deviatoric part of :math:`\bar E = \tfrac12 (J^{-1}
    C - I)` as ((E11 - E22)/2, E12), J - 1 and tr P (reference:
    :meth:`model.mechanics.FiniteMechanics._state_reference`)."""
    nx, ny = F.shape[2], F.shape[3]
    dev = np.empty((2, nx, ny))
    Jm1 = np.empty((nx, ny))
    trP = np.empty((nx, ny))
    for x in range(nx):
        for y in range(ny):
            _, _, _, _, J, c00, c01, c11 = _point_kinematics(F, x, y)
            dev[0, x, y] = 0.25 * (c00 - c11) / J
            dev[1, x, y] = 0.5 * c01 / J
            Jm1[x, y] = J - 1.0
            trP[x, y] = P[0, 0, x, y] + P[1, 1, x, y]
    return dev, Jm1, trP


@njit(cache=True)
def green_kernel(b, khx, khy, inv_k2, a):  # pragma: no cover - compiled
    """Green operator of the isotropic reference medium, :math:`(I - a \\hat k \\hat k)
    \\hat b / k^2` (reference: ``model.mechanics._Mechanics._green``)."""
    nx, ny = khx.shape
    out = np.empty((2, nx, ny), dtype=np.complex128)
    for x in range(nx):
        for y in range(ny):
            h1 = khx[x, y]
            h2 = khy[x, y]
            kb = rmul(a, rmul(h1, b[0, x, y]) + rmul(h2, b[1, x, y]))
            out[0, x, y] = rmul(inv_k2[x, y], b[0, x, y] - rmul(h1, kb))
            out[1, x, y] = rmul(inv_k2[x, y], b[1, x, y] - rmul(h2, kb))
    return out


@njit(cache=True)
def apply_tangent_spin_kernel(K, G, E):  # pragma: no cover - compiled
    """:math:`K : G + E\\, \\omega(G)` with :math:`\\omega = \\tfrac12 (G_{10} - G_{01})`: the
    rate-form stress of the displacement-rate (spin) problem, point by point."""
    nx, ny = G.shape[2], G.shape[3]
    out = np.empty((2, 2, nx, ny))
    for x in range(nx):
        for y in range(ny):
            g00 = G[0, 0, x, y]
            g01 = G[0, 1, x, y]
            g10 = G[1, 0, x, y]
            g11 = G[1, 1, x, y]
            w = 0.5 * (g10 - g01)
            for i in range(2):
                for j in range(2):
                    out[i, j, x, y] = (K[i, j, 0, 0, x, y] * g00 + K[i, j, 0, 1, x, y] * g01
                                       + K[i, j, 1, 0, x, y] * g10 + K[i, j, 1, 1, x, y] * g11
                                       + E[i, j, x, y] * w)
    return out
