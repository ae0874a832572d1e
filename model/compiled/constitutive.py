"""The finite-strain stress, its tangent and strain measures, point by point (numba).

numpy twin: :mod:`nematic_solids.model.constitutive` (the readable formulas of Eqs. 1-2), through
the signature-compatible wrappers of :mod:`nematic_solids.model.reference_kernels`; tested to agree
in ``tests/model/test_constitutive.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _point_kinematics(F, x, y):  # pragma: no cover - compiled
    """At grid point (x, y): F's components f00, f01, f10, f11, J = det F and the components
    c00, c01, c11 of C = F^T F."""
    f00 = F[0, 0, x, y]
    f01 = F[0, 1, x, y]
    f10 = F[1, 0, x, y]
    f11 = F[1, 1, x, y]
    return (
        f00,
        f01,
        f10,
        f11,
        f00 * f11 - f01 * f10,
        f00 * f00 + f10 * f10,
        f00 * f01 + f10 * f11,
        f01 * f01 + f11 * f11,
    )


#: the packed tangent: K as the symmetric 4 x 4 matrix K[2 i + J, 2 k + L], its upper
#: triangle stored row by row in 10 planes; ``PACKED[a, b]`` is the plane of entry (a, b)
#: (numpy twin: :func:`nematic_solids.model.tensors.pack_symmetric`)
PACKED = np.array([[0, 1, 2, 3], [1, 4, 5, 6], [2, 5, 7, 8], [3, 6, 8, 9]])

#: points per block of :func:`tangent_kernel` (its 10 output planes are written block by block)
_BLOCK = 64


@njit(cache=True, error_model="numpy")
def tangent_kernel(F, q1, q2, kappa, B, Bp, alpha):  # pragma: no cover - compiled
    r""":math:`K_{iJkL} = \partial P_{iJ}/\partial F_{kL}` in closed form, point by point,
    packed: (10, nx, ny), the upper triangle of the symmetric 4 x 4 matrix
    :math:`K_{[2i+J][2k+L]}` (:data:`PACKED`).

    Differentiating :math:`P = F \mathbf S` (``nematic_solids.model.constitutive``) with :math:`dC =
    dF^T F
    + F^T dF` and :math:`H = F^{-T}` (so :math:`F C^{-1} = H`, :math:`F C^{-1} F^T = I`) gives

    .. math::
        K_{iJkL} = \delta_{ik} \Sigma_{LJ} - W_{iJ} H_{kL} - H_{iJ} W_{kL}
            + \eta\, H_{iJ} H_{kL} - \beta\, H_{iL} H_{kJ},

    with :math:`W = F (I - B Q) / J`, :math:`g = (B\, C:Q - I_1) / (2 J)`,
    :math:`\beta = g + \kappa (J^2 - J) - B' (Q:Q) J`,
    :math:`\eta = J (\kappa (2 J - 1) - B' (Q:Q)) - g` and :math:`\Sigma = \mathbf S -
    \beta C^{-1}`. The four terms are major-symmetric (the tangent of a hyperelastic stress
    plus the geometric stiffness of :math:`\alpha Q`), so 10 of the 16 entries determine K:
    the Krylov operators read 10 planes instead of 16 per application. Reference:
    :func:`nematic_solids.model.constitutive.tangent`, the directional derivative
    :func:`~nematic_solids.model.constitutive.first_piola_increment` in the four unit directions,
    packed (tested to agree to roundoff). The output planes lie 8 N^2 bytes apart, on the same cache
    sets, so writing them point by point thrashes the L1 cache: a block of points is computed into a
    small buffer and copied out plane by plane."""
    nx, ny = q1.shape
    n = nx * ny
    K = np.empty((10, nx, ny))
    Kf = K.reshape((10, n))
    Ff = np.ascontiguousarray(F).reshape((4, n))
    qa = np.ascontiguousarray(q1).reshape(n)
    qb = np.ascontiguousarray(q2).reshape(n)
    buf = np.empty((10, _BLOCK))
    for p0 in range(0, n, _BLOCK):
        m = min(_BLOCK, n - p0)
        F0, F1, F2, F3 = (
            Ff[0, p0 : p0 + m],
            Ff[1, p0 : p0 + m],
            Ff[2, p0 : p0 + m],
            Ff[3, p0 : p0 + m],
        )
        qa_b, qb_b = qa[p0 : p0 + m], qb[p0 : p0 + m]
        # scalars only (no tuples indexed in the loop) and 1-D views: the loop vectorises
        # (2.5x faster than with tuples of H, W and Sigma, bitwise the same)
        for o in range(m):
            f00, f01, f10, f11 = F0[o], F1[o], F2[o], F3[o]
            a = qa_b[o]  # Q = [[a, b], [b, -a]]
            b = qb_b[o]
            J = f00 * f11 - f01 * f10
            r = 1.0 / J
            h0, h1, h2, h3 = f11 * r, -f10 * r, -f01 * r, f00 * r  # H = F^-T, flat [2 i + J]
            c00 = f00 * f00 + f10 * f10  # C = F^T F
            c01 = f00 * f01 + f10 * f11
            c11 = f01 * f01 + f11 * f11
            i00 = h0 * h0 + h2 * h2  # C^-1 = H^T H
            i01 = h0 * h1 + h2 * h3
            i11 = h1 * h1 + h3 * h3
            qq = 2.0 * (a * a + b * b)
            g = 0.5 * (B * ((c00 - c11) * a + 2.0 * c01 * b) - (c00 + c11)) * r
            iso = kappa * (J - 1.0) * J - Bp * qq * J  # S's coefficient of C^-1, with g
            beta = g + kappa * (J * J - J) - Bp * qq * J
            eta = J * (kappa * (2.0 * J - 1.0) - Bp * qq) - g
            t = iso + g - beta
            s00 = (1.0 - B * a) * r + t * i00 + alpha * a  # Sigma = S - beta C^-1
            s01 = -B * b * r + t * i01 + alpha * b
            s11 = (1.0 + B * a) * r + t * i11 - alpha * a
            w0 = (f00 * (1.0 - B * a) - f01 * B * b) * r  # W, flat [2 i + J]
            w1 = (f01 * (1.0 + B * a) - f00 * B * b) * r
            w2 = (f10 * (1.0 - B * a) - f11 * B * b) * r
            w3 = (f11 * (1.0 + B * a) - f10 * B * b) * r
            # entry (2i + J, 2k + L) = eta H_iJ H_kL - W_iJ H_kL - H_iJ W_kL
            #   - beta H_iL H_kJ [+ Sigma_LJ if i = k], the upper triangle in PACKED order
            buf[0, o] = eta * h0 * h0 - w0 * h0 - h0 * w0 - beta * h0 * h0 + s00
            buf[1, o] = eta * h0 * h1 - w0 * h1 - h0 * w1 - beta * h1 * h0 + s01
            buf[2, o] = eta * h0 * h2 - w0 * h2 - h0 * w2 - beta * h0 * h2
            buf[3, o] = eta * h0 * h3 - w0 * h3 - h0 * w3 - beta * h1 * h2
            buf[4, o] = eta * h1 * h1 - w1 * h1 - h1 * w1 - beta * h1 * h1 + s11
            buf[5, o] = eta * h1 * h2 - w1 * h2 - h1 * w2 - beta * h0 * h3
            buf[6, o] = eta * h1 * h3 - w1 * h3 - h1 * w3 - beta * h1 * h3
            buf[7, o] = eta * h2 * h2 - w2 * h2 - h2 * w2 - beta * h2 * h2 + s00
            buf[8, o] = eta * h2 * h3 - w2 * h3 - h2 * w3 - beta * h3 * h2 + s01
            buf[9, o] = eta * h3 * h3 - w3 * h3 - h3 * w3 - beta * h3 * h3 + s11
        for c in range(10):
            row, src = Kf[c, p0 : p0 + m], buf[c]
            for o in range(m):
                row[o] = src[o]
    return K


@njit(cache=True)
def apply_tangent_into(K, dF, E, spin, out):  # pragma: no cover - compiled
    r"""``out`` = :math:`K : dF\, [+ E\, \omega(dF)]`, :math:`\omega = \tfrac12 (dF_{10} -
    dF_{01})` (the E term if ``spin``), for the packed tangent ``K`` (:func:`tangent_kernel`),
    row by row and one output component at a time: the loop over a row then reads 9 or 10
    rows and writes one, few enough pointers for LLVM's run-time alias checks, so it
    vectorises (all 22 rows in one loop stayed scalar; the planes lie 8 N^2 bytes apart, on
    the same cache sets), 1.3x faster at 128^2, 2.4x at 64^2 (measured), bitwise the same
    sums. The two kernels below without their allocation (the Krylov operators reuse one
    buffer). Each component is summed in the order :math:`K_{iJ00} dF_{00} + K_{iJ01}
    dF_{01} + K_{iJ10} dF_{10} + K_{iJ11} dF_{11}` (+ :math:`E_{iJ} \omega`)."""
    nx, ny = dF.shape[2], dF.shape[3]
    for x in range(nx):
        g0, g1, g2, g3 = dF[0, 0, x], dF[0, 1, x], dF[1, 0, x], dF[1, 1, x]
        for c in range(4):
            # row c of the symmetric 4 x 4 matrix in PACKED order
            if c == 0:
                ka, kb, kc, kd = K[0, x], K[1, x], K[2, x], K[3, x]
            elif c == 1:
                ka, kb, kc, kd = K[1, x], K[4, x], K[5, x], K[6, x]
            elif c == 2:
                ka, kb, kc, kd = K[2, x], K[5, x], K[7, x], K[8, x]
            else:
                ka, kb, kc, kd = K[3, x], K[6, x], K[8, x], K[9, x]
            o = out[c // 2, c % 2, x]
            if spin:
                e = E[c // 2, c % 2, x]
                for y in range(ny):
                    o[y] = (
                        ka[y] * g0[y]
                        + kb[y] * g1[y]
                        + kc[y] * g2[y]
                        + kd[y] * g3[y]
                        + e[y] * (0.5 * (g2[y] - g1[y]))
                    )
            else:
                for y in range(ny):
                    o[y] = ka[y] * g0[y] + kb[y] * g1[y] + kc[y] * g2[y] + kd[y] * g3[y]


@njit(cache=True)
def apply_tangent_kernel(K, dF):  # pragma: no cover - compiled
    """:math:`dP_{iJ} = K_{iJkL} dF_{kL}` point by point for the packed tangent ``K``
    (reference: :func:`nematic_solids.model.constitutive.apply_tangent` of the unpacked tangent)."""
    out = np.empty(dF.shape)
    apply_tangent_into(K, dF, dF, False, out)
    return out


@njit(cache=True)
def apply_tangent_spin_kernel(K, G, E):  # pragma: no cover - compiled
    r""":math:`K : G + E\, \omega(G)` with :math:`\omega = \tfrac12 (G_{10} - G_{01})`: the
    rate-form stress of the displacement-rate (spin) problem, point by point (packed ``K``)."""
    out = np.empty(G.shape)
    apply_tangent_into(K, G, E, True, out)
    return out


@njit(cache=True, error_model="numpy", inline="always")
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
        S00 = (1.0 - 0.5 * I1 * Ci00) / J + iso * Ci00 - B * (q1 - 0.5 * CQ * Ci00) / J + alpha * q1
        S01 = (-0.5 * I1 * Ci01) / J + iso * Ci01 - B * (q2 - 0.5 * CQ * Ci01) / J + alpha * q2
        S11 = (
            (1.0 - 0.5 * I1 * Ci11) / J + iso * Ci11 - B * (-q1 - 0.5 * CQ * Ci11) / J - alpha * q1
        )
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
    """:func:`_stress_point` at every grid point, as a (2, 2, nx, ny) array: row by row, over
    1-D views of the rows, so the loop over a row vectorises (2.5-3x faster than indexing the
    4-D arrays point by point; bitwise the same)."""
    nx, ny = q1.shape
    P = np.empty((2, 2, nx, ny))
    for x in range(nx):
        f0, f1, f2, f3 = F[0, 0, x], F[0, 1, x], F[1, 0, x], F[1, 1, x]
        qa, qb, da, db = q1[x], q2[x], d1[x], d2[x]
        p0, p1, p2, p3 = P[0, 0, x], P[0, 1, x], P[1, 0, x], P[1, 1, x]
        for y in range(ny):
            p0[y], p1[y], p2[y], p3[y] = _stress_point(
                f0[y], f1[y], f2[y], f3[y], qa[y], qb[y], da[y], db[y], kappa, B, Bp, alpha, active
            )
    return P


@njit(cache=True)
def first_piola_kernel(F, q1, q2, kappa, B, Bp, alpha):  # pragma: no cover - compiled
    """:math:`P = F \\mathbf S(F, Q)`, paper Eq. (2) (reference:
    :func:`nematic_solids.model.constitutive.first_piola`)."""
    return _stress_field(F, q1, q2, q1, q2, kappa, B, Bp, alpha, True)


@njit(cache=True)
def q_increment_kernel(F, q1, q2, d1, d2, B, Bp, alpha):  # pragma: no cover - compiled
    """:math:`\\partial P/\\partial Q : dQ` at fixed F for dQ = nematic(d1, d2) (reference:
    :func:`nematic_solids.model.constitutive.first_piola_q_increment`; kappa does not enter)."""
    return _stress_field(F, q1, q2, d1, d2, 0.0, B, Bp, alpha, False)


@njit(cache=True, error_model="numpy")
def strain_measures_kernel(F, P):  # pragma: no cover - compiled
    r"""From F and P, point by point: the deviatoric part of :math:`\bar E = \tfrac12 (J^{-1}
    C - I)` as ((E11 - E22)/2, E12), J - 1 and tr P (reference:
    :func:`nematic_solids.model.reference_kernels.strain_measures_kernel`)."""
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
