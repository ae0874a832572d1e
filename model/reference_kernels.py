r"""The numpy twins of the compiled kernels: the same names and signatures as
:mod:`nematic_solids.model.compiled.kernels` (the interface
:class:`nematic_solids.model.backend.Kernels`, which the type checker compares this module with),
written as array expressions over the readable references (:mod:`nematic_solids.model.constitutive`,
:mod:`nematic_solids.model.wellposedness`, :func:`phi_functions`). The finite-strain and rate
kernels that the accelerated backend shares (the gradient, divergence and Green operator of
half spectra, the strain measures, the molecular field, the rates of Eqs. 4-5) take JAX arrays
too (:func:`nematic_solids.model.tensors.namespace`). ``Numerics.backend = "numpy"``
runs these (:func:`nematic_solids.model.backend.kernels`); the tests check that each pair agrees
(``tests/model/test_constitutive.py``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from . import constitutive as cl
from . import tensors
from .wellposedness import finite_margin_samples, linear_margin

Array = np.ndarray

__all__ = [
    "activity_exponential",
    "activity_krogstad",
    "activity_rate",
    "apply_tangent_kernel",
    "apply_tangent_spin_kernel",
    "balance_residual_kernel",
    "bulk_terms",
    "corotational_rate",
    "div_hat_kernel",
    "etd_combination",
    "finite_margin_kernel",
    "linear_margin_kernel",
    "first_piola_kernel",
    "grad_hat_kernel",
    "green_kernel",
    "jaumann_products",
    "linear_response",
    "molecular_field_kernel",
    "neg_div_hat_kernel",
    "q_increment_kernel",
    "rk4_update",
    "rk_stage",
    "strain_measures_kernel",
    "symbol_combination",
    "tangent_kernel",
]


def _moduli(kappa: float, B: float, Bp: float, alpha: float) -> cl.Moduli:
    return cl.Moduli(kappa=kappa, B=B, B_prime=Bp, alpha=alpha)


# --- finite-strain stress (twins of nematic_solids.model.compiled.constitutive)
# ---------------------------


def tangent_kernel(
    F: Array, q1: Array, q2: Array, kappa: float, B: float, Bp: float, alpha: float
) -> Array:
    """:func:`nematic_solids.model.constitutive.tangent`, packed
    (:func:`nematic_solids.model.tensors.pack_symmetric`)."""
    return tensors.pack_symmetric(
        cl.tangent(F, tensors.nematic(q1, q2), _moduli(kappa, B, Bp, alpha))
    )


def apply_tangent_kernel(K: Array, dF: Array) -> Array:
    """:func:`nematic_solids.model.constitutive.apply_tangent` of the packed tangent ``K``."""
    return cl.apply_tangent(tensors.unpack_symmetric(K), dF)


def apply_tangent_spin_kernel(K: Array, G: Array, E: Array) -> Array:
    r""":math:`K : G + E\, \omega(G)`, :math:`\omega = \tfrac12 (G_{10} - G_{01})` (packed
    ``K``)."""
    return cl.apply_tangent(tensors.unpack_symmetric(K), G) + E * (0.5 * (G[1, 0] - G[0, 1]))


def first_piola_kernel(
    F: Array, q1: Array, q2: Array, kappa: float, B: float, Bp: float, alpha: float
) -> Array:
    """:func:`nematic_solids.model.constitutive.first_piola`."""
    return cl.first_piola(F, tensors.nematic(q1, q2), _moduli(kappa, B, Bp, alpha))


def q_increment_kernel(
    F: Array, q1: Array, q2: Array, d1: Array, d2: Array, B: float, Bp: float, alpha: float
) -> Array:
    """:func:`nematic_solids.model.constitutive.first_piola_q_increment` (kappa does not enter)."""
    return cl.first_piola_q_increment(
        F, tensors.nematic(q1, q2), tensors.nematic(d1, d2), _moduli(0.0, B, Bp, alpha)
    )


def strain_measures_kernel(F: Array, P: Array) -> tuple[Array, Array, Array]:
    r"""(deviatoric part of :math:`\bar E = \tfrac12 (J^{-1} C - I)` as ((E11 - E22)/2, E12),
    J - 1, tr P)."""
    J = tensors.det(F)
    C = tensors.matmul(tensors.transpose(F), F)
    xp = tensors.namespace(F)
    Ebar_dev = xp.stack([0.25 * (C[0, 0] - C[1, 1]) / J, 0.5 * C[0, 1] / J])
    return Ebar_dev, J - 1.0, tensors.trace(P)


# --- spectral operators (twins of nematic_solids.model.compiled.spectral)
# ---------------------------------


def grad_hat_kernel(v: Array, kx: Array, ky: Array) -> Array:
    r""":math:`\widehat{\partial_j v_i} = i k_j \hat v_i`."""
    xp = tensors.namespace(v)
    return 1j * xp.stack([xp.stack([kx * v[i], ky * v[i]]) for i in range(2)])


def div_hat_kernel(T: Array, kx: Array, ky: Array) -> Array:
    r""":math:`i k_j \hat T_{ij}`."""
    return 1j * (kx * T[:, 0] + ky * T[:, 1])


def balance_residual_kernel(
    P: Array, P_hat: Array, khx: Array, khy: Array, weights: Array
) -> float:
    r""":math:`\lVert \hat k_J \hat P_{iJ} \rVert / \max(1, \mathrm{RMS}\, P)`."""
    n = P.shape[2]
    r = khx * P_hat[:, 0] + khy * P_hat[:, 1]
    norm = float(np.sqrt(np.sum(weights * np.abs(r) ** 2))) / n**2
    return norm / max(1.0, float(np.sqrt(np.mean(np.sum(P**2, axis=(0, 1))))))


def neg_div_hat_kernel(T: Array, kx: Array, ky: Array) -> Array:
    r""":math:`-i k_j \hat T_{ij}`."""
    return -div_hat_kernel(T, kx, ky)


def green_kernel(b: Array, khx: Array, khy: Array, inv_k2: Array, a: float) -> Array:
    r""":math:`(I - a \hat k \hat k)\, \hat b / k^2`."""
    kb = a * (khx * b[0] + khy * b[1])
    xp = tensors.namespace(b)
    return xp.stack([(b[0] - khx * kb) * inv_k2, (b[1] - khy * kb) * inv_k2])


def symbol_combination(x: Array, m1: Array, m2: Array, a: Array, b: Array) -> Array:
    """:math:`x - (m_1 a + m_2 b)`."""
    return x - (m1 * a + m2 * b)


def linear_response(
    q1h: Array,
    q2h: Array,
    isoh: Array,
    kx: Array,
    ky: Array,
    khx: Array,
    khy: Array,
    inv_k2: Array,
    amb: float,
    a: float,
    kappa: float,
    incompressible: bool,
    mean_dev: float,
) -> tuple[Array, Array, Array]:
    r"""The small-strain solution's spectra ``dev e`` (2 components), ``tr e``, ``tr sigma``
    for the eigenstress :math:`\tau = (\alpha - B) Q + \mathrm{iso}\, I` (docs/model/equations.md):
    :math:`\hat b = i \hat\tau k`, :math:`\hat u = (I - a \hat k \hat k) \hat b /
    k^2`, :math:`\hat e = \mathrm{sym}(i k \hat u)`; incompressible: the pressure
    :math:`\hat p = \hat k \cdot \hat\tau \cdot \hat k`."""
    t11, t12 = amb * q1h, amb * q2h
    b = np.stack([1j * (kx * (t11 + isoh) + ky * t12), 1j * (kx * t12 + ky * (-t11 + isoh))])
    u = green_kernel(b, khx, khy, inv_k2, a)
    e11, e22 = 1j * kx * u[0], 1j * ky * u[1]
    e12 = 0.5j * (ky * u[0] + kx * u[1])
    dev = np.stack([0.5 * (e11 - e22), e12])
    dev[0, 0, 0] += mean_dev
    tr_e = e11 + e22
    if incompressible:
        p = (khx**2 - khy**2) * t11 + 2.0 * khx * khy * t12 + np.where(inv_k2 != 0.0, isoh, 0.0)
        tr_s = -2.0 * p + 2.0 * isoh
    else:
        tr_s = 2.0 * kappa * tr_e + 2.0 * isoh
    return dev, tr_e, tr_s


# --- rates of Eqs. (4)-(5) (twins of nematic_solids.model.compiled.rates)
# ----------------------------------


def bulk_terms(q1: Array, q2: Array, A: Array, tr_e: Array, C: float, two_Bp: float) -> Array:
    r"""``[-b q1, -b q2]``, :math:`b = A + C\, Q:Q - 2 B' \mathrm{tr}\, e`."""
    bulk = A + C * 2.0 * (q1 * q1 + q2 * q2) - two_Bp * tr_e
    return np.stack([-bulk * q1, -bulk * q2])


def molecular_field_kernel(
    q1: Array,
    q2: Array,
    A: Array,
    Jm1: Array,
    Ebar_dev: Array,
    lap: Array,
    A0: float,
    C: float,
    two_Bp: float,
    B: float,
    K: float,
) -> Array:
    r"""H of Eq. (4): :math:`-(A + A_0 + C\, Q:Q - 2 B' (J - 1)) q + B\, \mathrm{dev}\, \bar E
    + K \nabla^2 q`."""
    bulk = A + A0 + C * 2.0 * (q1**2 + q2**2) - two_Bp * Jm1
    xp = tensors.namespace(q1)
    return xp.stack([-bulk * q1, -bulk * q2]) + B * Ebar_dev + K * lap


def activity_rate(A: Array, trP: Array, zeta: float, chi: float, s: float, tau: float) -> Array:
    r"""Paper Eq. (5): :math:`(-\zeta A - \chi\, \mathrm{tr} P - s A^3)/\tau`."""
    return (-zeta * A - chi * trP - s * A * A * A) / tau


def corotational_rate(R: Array, grad_v: Array, q1: Array, q2: Array) -> tuple[Array, Array]:
    r"""``(R + 2 omega J q, omega)``, :math:`\omega = \tfrac12 (\partial_1 v_2 - \partial_2
    v_1)` from the gradient of v."""
    omega = 0.5 * (grad_v[1, 0] - grad_v[0, 1])
    return R + jaumann_products(omega, q1, q2), omega


def jaumann_products(omega: Array, q1: Array, q2: Array) -> Array:
    r""":math:`2 \omega J q = [-2 \omega q_2, 2 \omega q_1]`."""
    xp = tensors.namespace(omega)
    return xp.stack([-2.0 * omega * q2, 2.0 * omega * q1])


# --- the exponential integrators' pointwise pieces (twins of nematic_solids.model.compiled.etd)
# -----------


def phi_functions(z: Array, kmax: int = 2) -> tuple[Array, ...]:
    """:math:`e^z, \\varphi_1(z), \\ldots, \\varphi_{k_{max}}(z)` (real ``z``),
    :math:`\\varphi_k(z) = \\sum_j z^j / (j + k)!`: the Taylor series for ``|z| < 1``, the
    recursion :math:`\\varphi_{k+1} = (\\varphi_k - 1/k!)/z` otherwise."""
    z = np.asarray(z, dtype=float)
    small = np.abs(z) < 1.0
    zr = np.where(small, 1.0, z)
    out = [np.exp(z)]
    prev = np.expm1(zr)  # phi_0 - 1 on the recursion branch
    zs = z[small]  # the series is summed where it is used (elementwise: the same values)
    for k in range(1, kmax + 1):
        rec = prev / zr if k == 1 else (prev - 1.0 / math.factorial(k - 1)) / zr
        taylor = np.zeros_like(zs)
        term = np.ones_like(zs)
        for j in range(20):
            taylor += term / math.prod(range(j + 1, j + k + 1))
            term = term * zs / (j + 1)
        phi = np.array(rec)  # a new array (0-d for a scalar z, as np.where gives)
        phi[small] = taylor
        out.append(phi)
        prev = rec
    return tuple(out)


def activity_exponential(
    A: Array, h: float, zeta: float, s: float, tau: float
) -> tuple[Array, Array, Array]:
    r"""``(L_A, phi1(h L_A), phi2(h L_A))``, :math:`L_A = -(\zeta + 3 s A^2)/\tau`."""
    L = -(zeta + 3.0 * s * A * A) / tau
    _, p1, p2 = phi_functions(L * h, 2)
    return L, p1, p2


def activity_krogstad(A: Array, h: float, zeta: float, s: float, tau: float) -> tuple[Array, Array]:
    """``(L_A, W)`` with Krogstad's ten pointwise weights (order as
    :func:`nematic_solids.model.compiled.etd.activity_krogstad`)."""
    L = -(zeta + 3.0 * s * A * A) / tau
    W = np.stack(krogstad_from_phi(*phi_functions(L * h, 3), *phi_functions(0.5 * L * h, 2)))
    return L, W


def krogstad_from_phi(
    E: Any, f1: Any, f2: Any, f3: Any, E2: Any, g1: Any, g2: Any
) -> tuple[Any, ...]:
    """Krogstad's ten weights ``(E, E2, a, b_u, b_a, c_u, c_b, new_u, new_ab, new_c)`` from
    the phi functions of the step (``E, f1, f2, f3`` of hL) and of the half step (``E2, g1,
    g2`` of hL/2): plain arithmetic, for numpy arrays and the accelerated backend's JAX
    arrays alike."""
    return (
        E,
        E2,
        0.5 * g1,
        0.5 * g1 - g2,
        g2,
        f1 - 2.0 * f2,
        2.0 * f2,
        f1 - 3.0 * f2 + 4.0 * f3,
        2.0 * f2 - 4.0 * f3,
        4.0 * f3 - f2,
    )


def etd_combination(
    E: Array, x: Array, h: float, coef: tuple[Array, ...], terms: tuple[Array, ...]
) -> Array:
    r""":math:`E x + h \sum_k c_k N_k`."""
    return E * x + h * sum(c * t for c, t in zip(coef, terms, strict=True))


def rk_stage(x0: Array, c: float, v: Array) -> Array:
    r""":math:`x_0 + c\, v`."""
    return x0 + c * v


def rk4_update(x0: Array, c: float, v0: Array, v1: Array, v2: Array, v3: Array) -> Array:
    r""":math:`x_0 + c\, (v_0 + 2 v_1 + 2 v_2 + v_3)`."""
    return x0 + c * (v0 + 2.0 * v1 + 2.0 * v2 + v3)


# --- well-posedness (twin of nematic_solids.model.compiled.wellposedness)
# ----------------------------------

finite_margin_kernel = finite_margin_samples
linear_margin_kernel = linear_margin
