r"""The homogeneous steady state under the applied pure shear: the base state of the linear
stability analysis (:mod:`nematic_solids.model.stability`).

Linear mechanics on the periodic unit square under
:math:`\bar{\boldsymbol\varepsilon} = \varepsilon\,\mathrm{diag}(1,-1)`, with
:math:`\tilde{\mathbf u} = 0`: :math:`\mathbf H = 0` (paper Eq. (4)) and :math:`\dot A = 0`
(paper Eq. (5)) give

.. math::
    (A_b + A_0 + 2 C q_b^2)\, q_b = B\varepsilon, \qquad q_{2,b} = 0, \qquad
    \zeta A_b + s A_b^3 = 4 \chi B' q_b^2

(:func:`base_state`; the derivation is in ``docs/stability.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .errors import ParameterError
from .parameters import Parameters


@dataclass(frozen=True)
class BaseState:
    r"""The homogeneous steady state under the applied shear :math:`\varepsilon`.

    Attributes:
        eps: applied pure shear :math:`\varepsilon`.
        q1: :math:`q_{1,b} = Q_{11}` (:math:`q_{2,b} = 0`, :math:`S_b = |q_{1,b}|`).
        A: :math:`A_b`.
    """

    eps: float
    q1: float
    A: float


def _activity_root(r: float, zeta: float, s: float) -> float:
    r"""The unique real root of :math:`s A^3 + \zeta A = r` (:math:`\zeta, s \ge 0`)."""
    if s == 0.0:
        if zeta == 0.0:
            if r == 0.0:
                return 0.0
            raise ParameterError(
                "zeta",
                zeta,
                "zeta > 0 or s > 0 when chi * B_prime != 0 (else the activity "
                "equation has no homogeneous steady state)",
            )
        return r / zeta
    # Cardano for the depressed cubic A^3 + p A - r/s = 0 with p = zeta/s >= 0 (one real root)
    p, h = zeta / s, 0.5 * r / s
    root = math.sqrt(h * h + (p / 3.0) ** 3)
    A = float(np.cbrt(h + root) + np.cbrt(h - root))
    for _ in range(3):  # Newton polish against cancellation
        f, df = s * A**3 + zeta * A - r, 3 * s * A**2 + zeta
        if df == 0.0:
            break
        A -= f / df
    return A


def _base_activity(params: Parameters, q: float) -> float:
    r""":math:`A_b(q)`: :math:`\zeta A + s A^3 = 4\chi B' q^2` (steady paper Eq. (5) with
    :math:`\mathrm{tr}\,\boldsymbol\sigma_b = -B'(\mathbf Q:\mathbf Q)\,\mathrm{tr}\,\mathbf I
    = -4 B' q^2`)."""
    return _activity_root(4.0 * params.chi * params.B_prime * q * q, params.zeta, params.s)


def base_state(params: Parameters, eps: float | None = None) -> BaseState:
    r"""Homogeneous steady state of the linear-mechanics model under pure shear.

    With :math:`\tilde{\mathbf u} = 0` (a homogeneous stress is divergence free), the strain is
    :math:`\bar{\boldsymbol\varepsilon} = \varepsilon\,\mathrm{diag}(1, -1)` (traceless, so
    :math:`J - 1 = 0`), :math:`\mathrm{dev}\,\bar{\mathbf E} = \bar{\boldsymbol\varepsilon}`, and
    :math:`\mathbf H = 0` (paper Eq. (4) with :math:`\mathbf W = 0`), :math:`\dot A = 0` (Eq. (5)):

    .. math::
        (A_b + A_0 + 2 C q_b^2)\, q_b = B\varepsilon, \qquad q_{2,b} = 0, \qquad
        \zeta A_b + s A_b^3 = -\chi\,\mathrm{tr}\,\boldsymbol\sigma_b = 4\chi B' q_b^2 .

    The incompressible model's pressure has zero mean, so :math:`\mathrm{tr}\,\boldsymbol
    \sigma_b` is the same in both variants. Of the roots of the scalar equation in
    :math:`q_b` (odd in :math:`q_b`), the one of smallest :math:`|q_b|` with the sign of
    :math:`\varepsilon` is returned: the branch that starts at the isotropic state
    :math:`q_b = 0` when :math:`\varepsilon = 0` (unique when :math:`A_0 > 0`, :math:`B' = 0`).

    Args:
        params: the constants; ``params.eps`` is used unless ``eps`` is given.
        eps: applied pure shear :math:`\varepsilon` (any real number).
    """
    e = params.eps if eps is None else float(eps)
    if e == 0.0 or params.B == 0.0:
        return BaseState(eps=e, q1=0.0, A=_base_activity(params, 0.0))
    target = params.B * abs(e)

    def residual(q: float) -> float:
        return (_base_activity(params, q) + params.A0 + 2.0 * params.C * q * q) * q - target

    grid = np.concatenate([[0.0], np.geomspace(1e-12, 1e6, 400)])
    values = np.array([residual(float(q)) for q in grid])
    change = np.nonzero((values[:-1] < 0.0) & (values[1:] >= 0.0))[0]
    if change.size == 0:
        raise ParameterError(
            "eps",
            e,
            "a strain with a homogeneous steady state (none found for |q1| < 1e6: "
            "check that A0 > 0 or C > 0)",
        )
    lo, hi = float(grid[change[0]]), float(grid[change[0] + 1])
    q = hi if values[change[0] + 1] == 0.0 else brentq(residual, lo, hi, xtol=1e-16, rtol=1e-15)
    q = math.copysign(float(q), e)
    return BaseState(eps=e, q1=q, A=_base_activity(params, q))
