"""Fast pointwise kernels (numba, compiled once per machine: ``cache=True``).

Each kernel has a readable numpy reference in :mod:`model.constitutive` and a test that they
agree (``tests/test_model_constitutive.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def tangent_kernel(F, q1, q2, kappa, B, Bp, alpha):  # pragma: no cover - compiled
    r""":math:`K_{iJkL} = \partial P_{iJ}/\partial F_{kL}`, the same formulas as
    :func:`model.constitutive.first_piola_increment` applied to the four unit directions
    :math:`dF = e_k \otimes e_L`, evaluated point by point."""
    nx, ny = q1.shape
    K = np.empty((2, 2, 2, 2, nx, ny))
    Fp = np.empty((2, 2))
    Q = np.empty((2, 2))
    C = np.empty((2, 2))
    Ci = np.empty((2, 2))
    S = np.empty((2, 2))
    S1 = np.empty((2, 2))
    S3 = np.empty((2, 2))
    dC = np.empty((2, 2))
    dCi = np.empty((2, 2))
    tmp = np.empty((2, 2))
    dS = np.empty((2, 2))
    for x in range(nx):
        for y in range(ny):
            for a in range(2):
                for b in range(2):
                    Fp[a, b] = F[a, b, x, y]
            Q[0, 0] = q1[x, y]
            Q[0, 1] = q2[x, y]
            Q[1, 0] = q2[x, y]
            Q[1, 1] = -q1[x, y]
            for a in range(2):
                for b in range(2):
                    C[a, b] = Fp[0, a] * Fp[0, b] + Fp[1, a] * Fp[1, b]
            J = Fp[0, 0] * Fp[1, 1] - Fp[0, 1] * Fp[1, 0]
            I1 = C[0, 0] + C[1, 1]
            detC = C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]
            Ci[0, 0] = C[1, 1] / detC
            Ci[1, 1] = C[0, 0] / detC
            Ci[0, 1] = -C[0, 1] / detC
            Ci[1, 0] = -C[1, 0] / detC
            qq = 2.0 * (q1[x, y] ** 2 + q2[x, y] ** 2)
            CQ = 0.0
            for a in range(2):
                for b in range(2):
                    CQ += C[a, b] * Q[a, b]
            for a in range(2):
                for b in range(2):
                    eye = 1.0 if a == b else 0.0
                    S1[a, b] = (eye - 0.5 * I1 * Ci[a, b]) / J
                    S3[a, b] = -B * (Q[a, b] - 0.5 * CQ * Ci[a, b]) / J
                    S[a, b] = (S1[a, b] + kappa * (J - 1.0) * J * Ci[a, b] + S3[a, b]
                               - Bp * qq * J * Ci[a, b] + alpha * Q[a, b])
            for k in range(2):
                for L in range(2):
                    # dC_ab = delta_aL F_kb + delta_bL F_ka
                    for a in range(2):
                        for b in range(2):
                            dC[a, b] = ((Fp[k, b] if a == L else 0.0)
                                        + (Fp[k, a] if b == L else 0.0))
                    c = 0.0
                    dCQ = 0.0
                    for a in range(2):
                        for b in range(2):
                            c += Ci[a, b] * dC[a, b]
                            dCQ += dC[a, b] * Q[a, b]
                    trdC = dC[0, 0] + dC[1, 1]
                    for a in range(2):
                        for b in range(2):
                            tmp[a, b] = dC[a, 0] * Ci[0, b] + dC[a, 1] * Ci[1, b]
                    for a in range(2):
                        for b in range(2):
                            dCi[a, b] = -(Ci[a, 0] * tmp[0, b] + Ci[a, 1] * tmp[1, b])
                    for a in range(2):
                        for b in range(2):
                            dS1 = -0.5 * c * S1[a, b] + (-0.5 * trdC * Ci[a, b]
                                                         - 0.5 * I1 * dCi[a, b]) / J
                            dS2 = kappa * ((2.0 * J - 1.0) * 0.5 * J * c * Ci[a, b]
                                           + (J * J - J) * dCi[a, b])
                            dS3 = -0.5 * c * S3[a, b] + B * (0.5 * dCQ * Ci[a, b]
                                                             + 0.5 * CQ * dCi[a, b]) / J
                            dS4 = -Bp * qq * (0.5 * J * c * Ci[a, b] + J * dCi[a, b])
                            dS[a, b] = dS1 + dS2 + dS3 + dS4
                    for i in range(2):
                        for j in range(2):
                            # dP = dF S + F dS, (dF S)_ij = delta_ik S_Lj
                            v = Fp[i, 0] * dS[0, j] + Fp[i, 1] * dS[1, j]
                            if i == k:
                                v += S[L, j]
                            K[i, j, k, L, x, y] = v
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
