r"""Constitutive law: (F, Q) -> first Piola stress P and its tangent. Knows nothing about FFTs.
Takes numpy or JAX arrays alike (:func:`nematic_solids.model.tensors.namespace`).

Finite strain (paper Eqs. 1-3). With :math:`C = F^T F`, :math:`J = \det F`,
:math:`I_1 = \operatorname{tr} C`, :math:`q = Q:Q = 2 S^2` and the 2-D isochoric invariant
:math:`\bar I_1 = I_1 / J`, the part of Eq. (1) that depends on F is

.. math::
    W(F, Q) = \tfrac12 (\bar I_1 - 2) + \tfrac12 \kappa (J - 1)^2
              - \tfrac{B}{2} \frac{C : Q}{J} - B' (J - 1)\, Q:Q ,

(using :math:`\bar E : Q = \tfrac12 \bar C : Q = \tfrac12 J^{-1} C : Q` since Q is
traceless). Its exact derivative plus the active stress (paper Eq. 2) is

.. math::
    \mathbf S = 2 \frac{\partial W}{\partial C} + \alpha Q
      = J^{-1}\big(I - \tfrac12 I_1 C^{-1}\big) + \kappa (J - 1) J C^{-1}
        - B J^{-1}\big(Q - \tfrac12 (C:Q) C^{-1}\big) - B' (Q:Q) J C^{-1} + \alpha Q,
    \qquad P = F \mathbf S .

At small strain (:math:`F = I + \nabla u`, :math:`e = \operatorname{sym}\nabla u`) this is
:math:`\sigma = 2\,\mathrm{dev}\, e + \kappa\, \mathrm{tr}\, e\, I + (\alpha - B) Q - B' (Q:Q) I`;
the paper prints :math:`\bar E` where the exact limit is :math:`2 \bar E \approx 2\,\mathrm{dev}\,e`
(shear modulus G = 1, see docs/model/index.md). Because :math:`F \alpha Q = \partial_F (\tfrac12
\alpha\, C : Q)` at fixed Q, the tangent :math:`\partial P / \partial F` is symmetric.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import tensors as T

#: a numpy array or a JAX array (:func:`nematic_solids.model.tensors.namespace`)
Array = T.Array


@dataclass(frozen=True)
class Moduli:
    """The constants of the stress: a subset of
    :class:`nematic_solids.model.parameters.Parameters`."""

    kappa: float
    B: float
    B_prime: float
    alpha: float

    @classmethod
    def from_params(cls, p) -> Moduli:  # p: Parameters (duck-typed to avoid a cycle)
        return cls(kappa=p.kappa, B=p.B, B_prime=p.B_prime, alpha=p.alpha)


def _kinematics(F: Array) -> tuple[Array, Array, Array, Array]:
    C = T.matmul(T.transpose(F), F)
    J = T.det(F)
    return C, J, T.trace(C), T.inv(C)


def energy_density(F: Array, Q: Array, m: Moduli) -> Array:
    """The F-dependent part W(F, Q) of paper Eq. (1) (no active term: it is not an energy)."""
    C, J, I1, _ = _kinematics(F)
    q = T.ddot(Q, Q)
    return (
        0.5 * (I1 / J - 2.0)
        + 0.5 * m.kappa * (J - 1.0) ** 2
        - 0.5 * m.B * T.ddot(C, Q) / J
        - m.B_prime * (J - 1.0) * q
    )


def second_piola(F: Array, Q: Array, m: Moduli) -> Array:
    """:math:`\\mathbf S = 2 \\partial W / \\partial C + \\alpha Q` (paper Eq. 2, exact)."""
    C, J, I1, Ci = _kinematics(F)
    eye = T.identity(J.shape, like=J)
    q = T.ddot(Q, Q)
    CQ = T.ddot(C, Q)
    return (
        (eye - 0.5 * I1 * Ci) / J
        + m.kappa * (J - 1.0) * J * Ci
        - m.B * (Q - 0.5 * CQ * Ci) / J
        - m.B_prime * q * J * Ci
        + m.alpha * Q
    )


def first_piola(F: Array, Q: Array, m: Moduli) -> Array:
    """:math:`P = F \\mathbf S` (paper Eq. 3)."""
    return T.matmul(F, second_piola(F, Q, m))


def first_piola_increment(F: Array, Q: Array, dF: Array, m: Moduli) -> Array:
    r"""Directional derivative :math:`dP = \partial P/\partial F : dF` (exact, analytic).

    .. math::
        dP = dF\, \mathbf S + F\, d\mathbf S, \quad dC = dF^T F + F^T dF,
        \quad c = C^{-1} : dC, \quad dC^{-1} = -C^{-1} dC\, C^{-1},
        \quad dJ = \tfrac12 J c .
    """
    C, J, I1, Ci = _kinematics(F)
    eye = T.identity(J.shape, like=J)
    q = T.ddot(Q, Q)
    CQ = T.ddot(C, Q)
    dC = T.matmul(T.transpose(dF), F) + T.matmul(T.transpose(F), dF)
    c = T.ddot(Ci, dC)
    dCi = -T.matmul(T.matmul(Ci, dC), Ci)
    S1 = (eye - 0.5 * I1 * Ci) / J
    dS1 = -0.5 * c * S1 + (-0.5 * T.trace(dC) * Ci - 0.5 * I1 * dCi) / J
    dS2 = m.kappa * ((2.0 * J - 1.0) * 0.5 * J * c * Ci + (J * J - J) * dCi)
    S3 = -m.B * (Q - 0.5 * CQ * Ci) / J
    dS3 = -0.5 * c * S3 + m.B * (0.5 * T.ddot(dC, Q) * Ci + 0.5 * CQ * dCi) / J
    dS4 = -m.B_prime * q * (0.5 * J * c * Ci + J * dCi)
    S = S1 + m.kappa * (J - 1.0) * J * Ci + S3 - m.B_prime * q * J * Ci + m.alpha * Q
    return T.matmul(dF, S) + T.matmul(F, dS1 + dS2 + dS3 + dS4)


def tangent(F: Array, Q: Array, m: Moduli) -> Array:
    """The tangent :math:`K_{iJkL} = \\partial P_{iJ} / \\partial F_{kL}`, shape (2,2,2,2,...).

    Assembled column by column from :func:`first_piola_increment` (exact).
    """
    shape = F.shape[2:]
    unit = np.zeros((2, 2, 2, 2) + (1,) * len(shape))  # [i, j, k, L]: the direction e_k e_L
    for k in range(2):
        for L in range(2):
            unit[k, L, k, L] = 1.0
    xp = T.namespace(F, Q)
    dF = xp.broadcast_to(xp.asarray(unit, dtype=F.dtype), (2, 2, 2, 2, *shape))
    # all four directions at once, broadcasting F and Q over the direction axes (k, L)
    dP = first_piola_increment(F[:, :, None, None], Q[:, :, None, None], dF, m)
    return dP


def apply_tangent(K: Array, dF: Array) -> Array:
    """:math:`dP_{iJ} = K_{iJkL}\\, dF_{kL}`."""
    shape = dF.shape[2:]
    return (K.reshape(2, 2, 4, *shape) * dF.reshape(1, 1, 4, *shape)).sum(axis=2)


def first_piola_q_increment(F: Array, Q: Array, dQ: Array, m: Moduli) -> Array:
    r""":math:`\partial P/\partial Q : dQ` at fixed F (drives the displacement rate).

    .. math::
        F\Big[-B J^{-1}\big(dQ - \tfrac12 (C:dQ) C^{-1}\big) - 2 B' (Q:dQ) J C^{-1}
        + \alpha\, dQ\Big]
    """
    C, J, _, Ci = _kinematics(F)
    dS = (
        -m.B * (dQ - 0.5 * T.ddot(C, dQ) * Ci) / J
        - 2.0 * m.B_prime * T.ddot(Q, dQ) * J * Ci
        + m.alpha * dQ
    )
    return T.matmul(F, dS)


def second_piola_trace(F: Array, P: Array) -> Array:
    r""":math:`\mathrm{tr}\, \mathbf S = \mathrm{tr}(F^{-1} P)`, :math:`F^{-1} = \mathrm{adj}\,
    F / J` (the ``coupling = "trS"`` of Eq. 5)."""
    adj = F[1, 1] * P[0, 0] - F[0, 1] * P[1, 0] - F[1, 0] * P[0, 1] + F[0, 0] * P[1, 1]
    return adj / T.det(F)


def small_strain_stress(grad_u: Array, Q: Array, m: Moduli) -> Array:
    r"""Linear ("small strain") stress, the linearisation of :func:`first_piola`:

    .. math:: \sigma = 2\,\mathrm{dev}\,e + \kappa\, \mathrm{tr}\,e\, I + (\alpha - B) Q
              - B' (Q:Q) I, \qquad e = \operatorname{sym} \nabla u .
    """
    e = 0.5 * (grad_u + T.transpose(grad_u))
    tr = T.trace(e)
    eye = T.identity(tr.shape, like=tr)
    return (
        2.0 * (e - 0.5 * tr * eye)
        + m.kappa * tr * eye
        + (m.alpha - m.B) * Q
        - m.B_prime * T.ddot(Q, Q) * eye
    )


def small_strain_energy_density(grad_u: Array, Q: Array, m: Moduli) -> Array:
    """Quadratic energy whose derivative is the passive part of :func:`small_strain_stress`
    (up to the B' term, which is kept at its leading order ``-B' tr(e) Q:Q``)."""
    e = 0.5 * (grad_u + T.transpose(grad_u))
    tr = T.trace(e)
    dev = e - 0.5 * tr * T.identity(tr.shape, like=tr)
    return (
        T.ddot(dev, dev)
        + 0.5 * m.kappa * tr**2
        - m.B * T.ddot(e, Q)
        - m.B_prime * tr * T.ddot(Q, Q)
    )
