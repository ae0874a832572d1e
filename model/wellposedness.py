r"""Well-posedness of the rate problem: the margin that every step checks.

The Jaumann derivative of Eq. (4) needs the spin of the displacement rate, and the displacement
rate solves the linearised force balance with the spin fed back through the active stress
(:meth:`nematic_solids.model.mechanics.FiniteMechanics.corotational`):

.. math::
    -\mathrm{Div}\big(\mathbb K : \nabla \dot u + E\, \omega(\dot u)\big)
    = \mathrm{Div}(\partial_Q P : R), \qquad E = \partial_Q P : (2 J q), \qquad
    \omega = \tfrac12 (\partial_1 \dot u_2 - \partial_2 \dot u_1).

Its principal symbol at a point, for a unit wave vector :math:`\hat k = (\cos\phi, \sin\phi)` and
:math:`\hat t = (-\sin\phi, \cos\phi)`, is the 2 x 2 matrix

.. math::
    M_{ik}(\hat k) = \mathbb K_{iJkL} \hat k_J \hat k_L + \tfrac12 (E \hat k)_i \hat t_k .

The problem is elliptic (well posed) while :math:`\det M(\hat k) > 0` for every direction at
every point; the passive medium (shear modulus 1, P-wave modulus :math:`\kappa + 1`) has
:math:`\det M = \kappa + 1`. The **margin** is

.. math::
    m = \min_{x} \min_{\phi} \det M(x, \hat k(\phi)) / (\kappa + 1),

1 for the passive medium and 0 where well-posedness is lost (docs/model/wellposedness.md). For a
uniform Q = S (2 n n - I) at F = I (B' = 0) the symbol gives in closed form
(:func:`uniform_margin`)

* finite strain: :math:`m = (1 - 2 (\alpha - B) S)(1 - (\alpha + B) S / (\kappa + 1))`, at
  :math:`\hat k \perp n`: the geometric stiffness of the prestress :math:`(\alpha - B) Q` and the
  Jaumann feedback each subtract :math:`(\alpha - B) S`, so the limit is
  :math:`(\alpha - B) S = 1/2`;
* small strain: :math:`\det M / (\kappa + 1) = 1 + (\alpha - B) S \cos 2\phi` (angle from n), so
  :math:`m = 1 - (\alpha - B) S` and the limit is :math:`(\alpha - B) S = 1`.

Small strain has no geometric stiffness and its symbol depends on Q alone, so its margin is
exactly :math:`1 - (\alpha - B) \max S` (compressible; with the incompressible projection the
same factor multiplies the shear symbol). Finite strain uses the tangent and E of the current
deformation, point by point (:func:`finite_margin`; its sampling compiled in
:mod:`nematic_solids.model.compiled.wellposedness`, with :func:`finite_margin_samples` the numpy
twin).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from . import tensors

Array = np.ndarray

#: directions sampled on [0, pi) (det M(phi + pi) = det M(phi)); the sampled minimum is
#: refined by a parabola through the smallest sample and its neighbours
N_ANGLES = 48


def finite_symbol(K: Array, E: Array, phi: float) -> Array:
    """:math:`M_{ik}(\\hat k(\\phi))` at every point, shape (2, 2, nx, ny): numpy reference of
    :func:`finite_margin` (``K`` the tangent dP/dF packed as the backends' ``tangent_kernel``
    returns it, (10, nx, ny): :func:`nematic_solids.model.tensors.pack_symmetric`; ``E`` (2, 2, nx,
    ny))."""
    k = np.array([np.cos(phi), np.sin(phi)])
    t = np.array([-np.sin(phi), np.cos(phi)])
    KK = np.einsum("iJkL...,J,L->ik...", tensors.unpack_symmetric(K), k, k)
    Ek = np.einsum("iJ...,J->i...", E, k)
    return KK + 0.5 * Ek[:, None] * t[None, :, None, None]


def finite_symbol_det(K: Array, E: Array, phi: float) -> Array:
    """:math:`\\det M(\\hat k(\\phi))` at every point (numpy reference)."""
    M = finite_symbol(K, E, phi)
    return M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]


def finite_margin_samples(
    K: Array, E: Array, cos_t: Array, sin_t: Array, scale: float
) -> tuple[float, int, int]:
    """(min over points and the sampled directions of det M / scale, flat index, angle
    index), the first in (x, y, angle) order among equal minima: every point sampled (numpy
    twin of :func:`nematic_solids.model.compiled.wellposedness.finite_margin_kernel`, which skips
    the points that cannot beat the minimum)."""
    angles = np.arctan2(sin_t, cos_t)
    D = np.stack([finite_symbol_det(K, E, float(p)) for p in angles], axis=-1) / scale
    flat = int(np.argmin(D))  # (x, y, angle) order
    point, ia = divmod(flat, len(angles))
    return float(D.flat[flat]), point, ia


def finite_margin(
    K: Array,
    E: Array,
    kappa: float,
    n_angles: int = N_ANGLES,
    samples: Callable[..., tuple[float, int, int]] = finite_margin_samples,
) -> tuple[float, int, float]:
    """The finite-strain margin :math:`\\min_x \\min_\\phi \\det M / (\\kappa + 1)` (module
    docstring) with the flat grid index and the direction angle of its minimum, sampled by
    ``samples`` (:func:`finite_margin_samples` or its compiled twin). The sampled minimum is
    refined at its point by a parabola in phi through three samples."""
    angles = np.arange(n_angles) * (np.pi / n_angles)
    m, idx, ia = samples(
        np.ascontiguousarray(K),
        np.ascontiguousarray(E),
        np.cos(angles),
        np.sin(angles),
        kappa + 1.0,
    )
    _nx, ny = E.shape[2], E.shape[3]
    x, y = divmod(int(idx), ny)
    dphi = np.pi / n_angles
    phis = angles[ia] + dphi * np.array([-1.0, 0.0, 1.0])
    d = np.array(
        [
            float(
                finite_symbol_det(K[..., x : x + 1, y : y + 1], E[..., x : x + 1, y : y + 1], p)[
                    0, 0
                ]
            )
            for p in phis
        ]
    ) / (kappa + 1.0)
    curv = d[0] - 2.0 * d[1] + d[2]
    phi = float(angles[ia])
    if curv > 0:
        off = 0.5 * (d[0] - d[2]) / curv  # in units of dphi, |off| <= 1/2 at a sampled min
        phi += off * dphi
        m = min(float(m), float(d[1] - 0.125 * (d[2] - d[0]) ** 2 / curv))
    return float(m), int(idx), phi % np.pi


def linear_margin(q1: Array, q2: Array, alpha_minus_B: float) -> tuple[float, int]:
    """The small-strain margin :math:`1 - (\\alpha - B) \\max S` and the flat index of the
    maximum of :math:`(\\alpha - B) S` (module docstring)."""
    S = np.sqrt(q1**2 + q2**2)
    prod = alpha_minus_B * S
    idx = int(np.argmax(prod))
    return float(1.0 - prod.flat[idx]), idx


def uniform_margin(S: float, alpha: float, B: float, kappa: float, *, linear: bool) -> float:
    """Closed-form margin of a uniform Q at F = I with B' = 0 (module docstring)."""
    amb = alpha - B
    if linear:
        return 1.0 - amb * S
    return (1.0 - 2.0 * amb * S) * (1.0 - (alpha + B) * S / (kappa + 1.0))


def limit_S(alpha_minus_B: float, *, linear: bool) -> float:
    """The order S at which a uniform state loses well-posedness (B' = 0, kappa large):
    :math:`1/(2(\\alpha - B))` (finite strain), :math:`1/(\\alpha - B)` (small strain)."""
    if alpha_minus_B <= 0:
        return float("inf")
    return (1.0 if linear else 0.5) / alpha_minus_B


__all__ = [
    "N_ANGLES",
    "finite_margin",
    "finite_symbol",
    "finite_symbol_det",
    "limit_S",
    "linear_margin",
    "uniform_margin",
]
