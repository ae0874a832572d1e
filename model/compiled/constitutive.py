"""The finite-strain stress, its tangent and strain measures, point by point (numba).

numpy twin: :mod:`model.constitutive` (the readable formulas of Eqs. 1-2), through the
signature-compatible wrappers of :mod:`model.reference_kernels`; tested to agree in
``tests/test_model_constitutive.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


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


@njit(cache=True, error_model="numpy")
def strain_measures_kernel(F, P):  # pragma: no cover - compiled
    r"""From F and P, point by point: the deviatoric part of :math:`\bar E = \tfrac12 (J^{-1}
    C - I)` as ((E11 - E22)/2, E12), J - 1 and tr P (reference:
    :func:`model.reference_kernels.strain_measures_kernel`)."""
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
