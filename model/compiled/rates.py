"""Pointwise terms of the rates of Eqs. (4)-(5) (numba).

numpy twin: :mod:`nematic_solids.model.reference_kernels` (the expressions of
:meth:`nematic_solids.model.pde.ActiveNematicPDE.molecular_field` and ``activity_rate``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _bulk(A, q1, q2, C, two_Bp, trace):  # pragma: no cover - compiled
    """The Landau-de Gennes factor :math:`A + C\\, Q:Q - 2 B' \\mathrm{tr}\\, e` at a point
    (Q:Q = 2 (q1^2 + q2^2); ``trace`` is tr e, or J - 1 at finite strain)."""
    return A + C * 2.0 * (q1 * q1 + q2 * q2) - two_Bp * trace


@njit(cache=True)
def bulk_terms(q1, q2, A, tr_e, C, two_Bp):  # pragma: no cover - compiled
    r"""``[-b q1, -b q2]`` with :math:`b = A + C\, Q:Q - 2 B' \mathrm{tr}\, e` (the
    non-constant part of the Landau-de Gennes bulk term in H, Eq. 4; ``A0`` is in L_q)."""
    nx, ny = q1.shape
    out = np.empty((2, nx, ny))
    for x in range(nx):
        for y in range(ny):
            bulk = _bulk(A[x, y], q1[x, y], q2[x, y], C, two_Bp, tr_e[x, y])
            out[0, x, y] = -bulk * q1[x, y]
            out[1, x, y] = -bulk * q2[x, y]
    return out


@njit(cache=True)
def molecular_field_kernel(
    q1, q2, A, Jm1, Ebar_dev, lap, A0, C, two_Bp, B, K
):  # pragma: no cover - compiled
    r"""The molecular field H (components H11, H12) of Eq. (4):
    :math:`-(A + A_0 + C\, Q:Q - 2 B' (J - 1)) q + B\, \mathrm{dev}\, \bar E + K \nabla^2 q`
    (``lap`` the Laplacians of q1, q2, ``Ebar_dev`` the two components of dev E-bar)."""
    nx, ny = q1.shape
    out = np.empty((2, nx, ny))
    for x in range(nx):
        for y in range(ny):
            bulk = _bulk(A[x, y] + A0, q1[x, y], q2[x, y], C, two_Bp, Jm1[x, y])
            out[0, x, y] = -bulk * q1[x, y] + B * Ebar_dev[0, x, y] + K * lap[0, x, y]
            out[1, x, y] = -bulk * q2[x, y] + B * Ebar_dev[1, x, y] + K * lap[1, x, y]
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
def corotational_rate(R, grad_v, q1, q2):  # pragma: no cover - compiled
    r"""``(Qdot, omega)``: the spin :math:`\omega = \tfrac12 (\partial_1 v_2 - \partial_2 v_1)`
    of the displacement rate v from its real-space gradient ``grad_v`` (2, 2, N, N), and
    :math:`\dot Q = R + 2 \omega J q` (Eq. 4), in one pass."""
    nx, ny = q1.shape
    qdot = np.empty((2, nx, ny))
    omega = np.empty((nx, ny))
    for x in range(nx):
        for y in range(ny):
            w = 0.5 * (grad_v[1, 0, x, y] - grad_v[0, 1, x, y])
            omega[x, y] = w
            qdot[0, x, y] = R[0, x, y] - 2.0 * w * q2[x, y]
            qdot[1, x, y] = R[1, x, y] + 2.0 * w * q1[x, y]
    return qdot, omega


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
