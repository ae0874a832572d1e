r"""Linear stability of the homogeneous, sheared state (paper Eq. (6) and Fig. A1).

The model is the *linear-mechanics* variant of paper Eqs. (1)-(5) (small strain, shear modulus
:math:`G = 1`, 2-D bulk modulus :math:`\kappa`, or incompressible), on the periodic unit square
under the applied pure shear
:math:`\bar{\boldsymbol\varepsilon} = \varepsilon\,\mathrm{diag}(1,-1)`. The derivation,
every convention and the comparison with the paper are in ``docs/stability.md``; the
docstrings below state the equations each function implements.

Notation (all dimensionless):

- :math:`\mathbf Q = \begin{pmatrix} q_1 & q_2\\ q_2 & -q_1\end{pmatrix}`,
  :math:`\mathbf Q:\mathbf Q = 2S^2`; :math:`a = \alpha - B`.
- :math:`\hat{\mathbf k} = (\cos\phi, \sin\phi)`, :math:`c = \cos 2\phi`, :math:`s = \sin 2\phi`.
- :math:`\beta = \kappa / (\kappa + 1)` (compressible) or :math:`\beta = 1` (incompressible):
  the fraction of the normal active stress :math:`\hat{\mathbf k}\cdot\boldsymbol\tau\cdot
  \hat{\mathbf k}` that the medium returns as isotropic stress
  :math:`-\tfrac12\mathrm{tr}\,\boldsymbol\sigma`.

Base state (homogeneous, steady, :math:`\tilde{\mathbf u} = 0`, mean pressure 0):

.. math::
    (A_b + A_0 + 2 C q_b^2)\, q_b = B\varepsilon, \qquad q_{2,b} = 0, \qquad
    \zeta A_b + s A_b^3 = 4 \chi B' q_b^2 .

Perturbation :math:`(\delta q_1, \delta q_2, \delta A)\,e^{\omega t + i\mathbf k\cdot\mathbf x}`:
:math:`\omega\,\mathsf M\,\mathbf x = \mathsf L\,\mathbf x`, with :math:`\mathsf M` carrying the
Jaumann spin of the slaved displacement rate. The stationary threshold (:math:`\omega = 0`)
along :math:`\hat{\mathbf k} = \hat{\mathbf y}` (:math:`c = -1`) is

.. math::
    2\chi q_b\,[\beta a - 4(1-\beta) B' q_b] = D\,(\zeta + 3 s A_b^2), \quad
    D = A_b + A_0 + 6 C q_b^2 + K k^2 + (1 - \beta)(a + 4 B' q_b)(B/2 - 2 B' q_b),

which for :math:`B' = 0` is a quadratic in :math:`q_b`; its smallest root gives
:math:`\varepsilon_c = q_b (A_0 + 2 C q_b^2) / B`. With :math:`C \to 0`, :math:`\beta = 1`:
:math:`\varepsilon_c = A_0 (A_0 + K k^2)\,\zeta / (2 B \chi (\alpha - B))`, half the paper's
Eq. (6) (the paper counts the 2-D trace of :math:`-p\mathbf I` as :math:`-p`; see the docs).

Only numpy, scipy and :mod:`nematic_solids.model.parameters` (with
:mod:`nematic_solids.model.errors` and the base state's :mod:`nematic_solids.model.sheared_state`)
are imported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from .errors import ParameterError
from .parameters import Parameters
from .sheared_state import BaseState, _base_activity, base_state

TWO_PI = 2.0 * math.pi

__all__ = [
    "BaseState",
    "CriticalStrain",
    "base_state",
    "critical_eps_closed_form",
    "critical_eps_numerical",
    "growth_rate",
    "growth_rates",
    "lattice_wavevectors",
    "linear_operator",
    "max_growth_rate",
    "paper_eq6",
]


@dataclass(frozen=True)
class CriticalStrain:
    r"""Result of :func:`critical_eps_numerical`.

    Attributes:
        eps: smallest :math:`\varepsilon > 0` with :math:`\max_k \mathrm{Re}\,\omega > 0`
            (``math.inf`` when none below ``eps_max``).
        mode: the integers :math:`(n, m)` of the critical lattice wavevector (``None`` if stable).
        k: the critical wavevector :math:`2\pi (n, m)` (``None`` if stable).
        growth_rate: :math:`\omega` of the critical mode just above threshold.
    """

    eps: float
    mode: tuple[int, int] | None
    k: tuple[float, float] | None
    growth_rate: complex | None


def _beta(params: Parameters, incompressible: bool) -> float:
    return 1.0 if incompressible else params.kappa / (params.kappa + 1.0)


def linear_operator(
    params: Parameters,
    k_vectors: ArrayLike,
    *,
    incompressible: bool = False,
    eps: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""The matrices :math:`(\mathsf M, \mathsf L)` of :math:`\omega\,\mathsf M\mathbf x =
    \mathsf L\mathbf x`, :math:`\mathbf x = (\delta q_1, \delta q_2, \delta A)`.

    Linearization of paper Eqs. (3)-(5) (linear mechanics, ``docs/stability.md``) about
    :func:`base_state` for the mode :math:`e^{i\mathbf k\cdot\mathbf x}`. The displacement is
    slaved through the Green operator of the medium (shear modulus 1, 2-D bulk modulus
    :math:`\kappa`, Lamé :math:`\lambda = \kappa - 1`) loaded by the perturbed stress
    :math:`\boldsymbol\tau = a\,\delta\mathbf Q + b\,\mathbf I`,
    :math:`a = \alpha - B`, :math:`b = -4B' q_b\,\delta q_1`:

    .. math::
        \hat{\mathbf u} = \frac{i}{k}\left[\boldsymbol\tau\hat{\mathbf k}
            - \beta\,\hat{\mathbf k}\,(\hat{\mathbf k}\cdot\boldsymbol\tau\cdot\hat{\mathbf k})
            \right],\qquad
        \mathrm{dev}\,\delta\mathbf e = -\tfrac12\left[a\,\delta\mathbf Q + b\,\mathbf N
            - \beta\,(a P + b)\,\mathbf N\right],\qquad
        \mathrm{tr}\,\delta\mathbf e = -(1-\beta)(aP + b),

    .. math::
        \mathrm{tr}\,\delta\boldsymbol\sigma = -2\beta (aP + b) + 2b,\qquad
        \delta w = -\tfrac a2\,(c\,\delta\dot q_2 - s\,\delta\dot q_1),

    with :math:`\mathbf N = 2\hat{\mathbf k}\hat{\mathbf k} - \mathbf I
    = \begin{pmatrix} c & s\\ s & -c\end{pmatrix}`, :math:`P = c\,\delta q_1 + s\,\delta q_2`
    and :math:`\beta` as in the module docstring. For :math:`\mathbf k = 0` the displacement
    perturbation vanishes (:math:`\delta\mathbf e = 0`, :math:`\delta w = 0`,
    :math:`\mathrm{tr}\,\delta\boldsymbol\sigma = 2b`, the mean pressure being 0). Then

    .. math::
        \gamma\,\delta\dot q_1 &= -q_b\,\delta A - (g + 4 C q_b^2 + K k^2)\,\delta q_1
            + 2 B' q_b\,\mathrm{tr}\,\delta\mathbf e + B\,(\mathrm{dev}\,\delta\mathbf e)_{11},\\
        \gamma\,\delta\dot q_2 + \gamma a q_b\,(c\,\delta\dot q_2 - s\,\delta\dot q_1)
            &= -(g + K k^2)\,\delta q_2 + B\,(\mathrm{dev}\,\delta\mathbf e)_{12},\\
        \tau\,\delta\dot A &= -(\zeta + 3 s A_b^2)\,\delta A
            - \chi\,\mathrm{tr}\,\delta\boldsymbol\sigma,

    :math:`g = A_b + A_0 + 2 C q_b^2`: the variations of :math:`\mathbf H = -(A + A_0 +
    C\,\mathbf Q:\mathbf Q - 2B'(J-1))\mathbf Q + B\,\mathrm{dev}\,\mathbf e + K\nabla^2\mathbf Q`
    (Eq. (4)), the Jaumann term :math:`q_1\dot{} = H_{11}/\gamma - 2wq_2`,
    :math:`q_2\dot{} = H_{12}/\gamma + 2wq_1` (second line) and Eq. (5).

    Args:
        params: the constants (``params.eps`` unless ``eps`` is given).
        k_vectors: wavevector(s), shape ``(2,)`` or ``(..., 2)`` (unit box: ``2 pi (n, m)``).
        incompressible: :math:`\beta = 1` (pressure) instead of :math:`\kappa/(\kappa+1)`.
        eps: applied pure shear, overriding ``params.eps``.

    Returns:
        ``(M, L)``, each of shape ``(..., 3, 3)``.
    """
    k = np.asarray(k_vectors, dtype=float)
    if k.shape[-1:] != (2,):
        raise ParameterError("k_vectors", k_vectors, "an array of shape (2,) or (..., 2)")
    base = base_state(params, eps)
    q, A_b = base.q1, base.A
    a, B, Bp, C = params.alpha - params.B, params.B, params.B_prime, params.C
    beta = _beta(params, incompressible)

    kx, ky = k[..., 0], k[..., 1]
    k2 = kx * kx + ky * ky
    m = (k2 > 0).astype(float)  # elastic response on for k != 0
    safe = np.where(k2 > 0, k2, 1.0)
    c = m * (kx * kx - ky * ky) / safe
    s = m * 2.0 * kx * ky / safe

    aPb_1 = a * c - 4.0 * Bp * q  # coefficient of dq1 in aP + b
    aPb_2 = a * s  # coefficient of dq2 in aP + b
    dev11_1 = -0.5 * m * (a - 4.0 * Bp * q * c - beta * c * aPb_1)
    dev11_2 = -0.5 * m * (-beta * c * aPb_2)
    dev12_1 = -0.5 * m * (-4.0 * Bp * q * s - beta * s * aPb_1)
    dev12_2 = -0.5 * m * (a - beta * s * aPb_2)
    tre_1 = -m * (1.0 - beta) * aPb_1
    tre_2 = -m * (1.0 - beta) * aPb_2
    trs_1 = -2.0 * m * beta * aPb_1 - 8.0 * Bp * q
    trs_2 = -2.0 * m * beta * aPb_2

    g = A_b + params.A0 + 2.0 * C * q * q
    shape = k.shape[:-1]
    L = np.zeros((*shape, 3, 3))
    L[..., 0, 0] = (
        -(g + 4.0 * C * q * q + params.K * k2) + 2.0 * Bp * q * tre_1 + B * dev11_1
    ) / params.gamma
    L[..., 0, 1] = (2.0 * Bp * q * tre_2 + B * dev11_2) / params.gamma
    L[..., 0, 2] = -q / params.gamma
    L[..., 1, 0] = B * dev12_1 / params.gamma
    L[..., 1, 1] = (-(g + params.K * k2) + B * dev12_2) / params.gamma
    L[..., 2, 0] = -params.chi * trs_1
    L[..., 2, 1] = -params.chi * trs_2
    L[..., 2, 2] = -(params.zeta + 3.0 * params.s * A_b * A_b)

    M = np.zeros((*shape, 3, 3))
    M[..., 0, 0] = 1.0
    M[..., 1, 0] = -a * q * s
    M[..., 1, 1] = 1.0 + a * q * c
    M[..., 2, 2] = params.tau
    return M, L


def growth_rates(
    params: Parameters,
    k_vectors: ArrayLike,
    *,
    incompressible: bool = False,
    eps: float | None = None,
) -> NDArray[np.complex128]:
    r"""Leading eigenvalue :math:`\omega(\mathbf k)` (largest real part) of
    :math:`\mathsf M^{-1}\mathsf L` (:func:`linear_operator`) for each wavevector.

    A singular :math:`\mathsf M` (:math:`1 + (\alpha - B) q_b c = 0`: the Jaumann spin makes
    :math:`\delta\dot q_2` indeterminate, loss of well-posedness) gives ``inf``.
    """
    M, L = linear_operator(params, k_vectors, incompressible=incompressible, eps=eps)
    det = M[..., 1, 1] * M[..., 2, 2]
    out = np.full(M.shape[:-2], complex(np.inf), dtype=complex)
    ok = np.abs(det) > 1e-14
    if np.any(ok):
        ev = np.linalg.eigvals(np.linalg.solve(M[ok], L[ok]))
        out[ok] = np.take_along_axis(ev, np.argmax(ev.real, axis=-1)[..., None], axis=-1)[..., 0]
    return out


def growth_rate(
    params: Parameters,
    k_vector: ArrayLike,
    *,
    incompressible: bool = False,
    eps: float | None = None,
) -> complex:
    r"""Growth rate :math:`\omega` of the mode :math:`e^{\omega t + i\mathbf k\cdot\mathbf x}`
    about the sheared homogeneous state: the eigenvalue of largest real part of
    :math:`\omega\,\mathsf M\mathbf x = \mathsf L\mathbf x` (:func:`linear_operator`; finite
    :math:`\tau`, any wavevector, time in the units of ``params``).

    Args:
        params: the constants (``params.eps`` is the applied shear unless ``eps`` is given).
        k_vector: :math:`(k_x, k_y)`; the unit box's lattice is :math:`2\pi (n, m)`.
        incompressible: incompressible linear elasticity (pressure) instead of bulk modulus
            :math:`\kappa`.
    """
    k = np.asarray(k_vector, dtype=float)
    if k.shape != (2,):
        raise ParameterError("k_vector", k_vector, "a pair (kx, ky)")
    return complex(growth_rates(params, k, incompressible=incompressible, eps=eps))


def lattice_wavevectors(nmax: int) -> tuple[NDArray[np.int_], NDArray[np.float64]]:
    r"""Lattice modes :math:`(n, m)`, :math:`|n|, |m| \le n_{max}`, one of each pair
    :math:`\pm\mathbf k` (same :math:`\omega`: the operator is even in :math:`\mathbf k`),
    including :math:`\mathbf k = 0`; and the wavevectors :math:`2\pi(n, m)` (unit box)."""
    if nmax < 1:
        raise ParameterError("nmax", nmax, "an integer >= 1")
    r = np.arange(-nmax, nmax + 1)
    n, mm = np.meshgrid(r, r, indexing="ij")
    modes = np.stack([n.ravel(), mm.ravel()], axis=-1)
    keep = (modes[:, 0] > 0) | ((modes[:, 0] == 0) & (modes[:, 1] >= 0))
    modes = modes[keep]
    return modes, TWO_PI * modes.astype(float)


def max_growth_rate(
    params: Parameters,
    *,
    incompressible: bool = False,
    eps: float | None = None,
    nmax: int = 8,
) -> tuple[complex, tuple[int, int]]:
    r""":math:`\max_{\mathbf k}\,\mathrm{Re}\,\omega(\mathbf k)` over the lattice
    :math:`\mathbf k = 2\pi(n, m)`, :math:`|n|, |m| \le n_{max}` (:func:`lattice_wavevectors`):
    returns :math:`\omega` of the leading mode and its :math:`(n, m)` (ties: smallest
    :math:`|\mathbf k|`, then the listing order)."""
    modes, ks = lattice_wavevectors(nmax)
    om = growth_rates(params, ks, incompressible=incompressible, eps=eps)
    order = np.lexsort((np.sum(modes**2, axis=-1), -np.round(om.real, 12)))
    i = int(order[0])
    return complex(om[i]), (int(modes[i, 0]), int(modes[i, 1]))


def _threshold_residual(params: Parameters, q: float, k2: float, beta: float) -> float:
    r""":math:`D\,\zeta' - 2\chi q\,[\beta a - 4(1-\beta)B'q]` for :math:`\hat{\mathbf k} =
    \hat{\mathbf y}` (``docs/stability.md``, "Threshold"); negative means unstable."""
    a, Bp = params.alpha - params.B, params.B_prime
    A_b = _base_activity(params, q)
    D = (
        A_b
        + params.A0
        + 6.0 * params.C * q * q
        + params.K * k2
        + (1.0 - beta) * (a + 4.0 * Bp * q) * (0.5 * params.B - 2.0 * Bp * q)
    )
    zeta_eff = params.zeta + 3.0 * params.s * A_b * A_b
    return D * zeta_eff - 2.0 * params.chi * q * (beta * a - 4.0 * (1.0 - beta) * Bp * q)


def _eps_of_q(params: Parameters, q: float) -> float:
    return (_base_activity(params, q) + params.A0 + 2.0 * params.C * q * q) * q / params.B


def critical_eps_closed_form(
    params: Parameters,
    *,
    incompressible: bool = False,
    k: float = TWO_PI,
) -> float:
    r"""Critical applied shear :math:`\varepsilon_c > 0` of the mode :math:`\mathbf k = k\,
    \hat{\mathbf y}` (for :math:`\varepsilon > 0` the most unstable direction; the lattice's
    smallest :math:`k = 2\pi/L`), from the stationary threshold :math:`\det\mathsf L = 0`.

    For :math:`B' = 0` (closed form; ``docs/stability.md`` Eqs. (S9)-(S10)):

    .. math::
        q_c = \frac{\zeta R}{\chi\beta a + \sqrt{\chi^2\beta^2 a^2 - 6 C\zeta^2 R}},\quad
        R = A_0 + K k^2 + (1 - \beta)\,\frac{a B}{2},\quad
        \varepsilon_c = \frac{q_c\,(A_0 + 2 C q_c^2)}{B},

    :math:`a = \alpha - B`, :math:`\beta = 1` (incompressible) or :math:`\kappa/(\kappa+1)`.
    No instability (``inf``) when :math:`\chi^2\beta^2 a^2 < 6 C\zeta^2 R` or :math:`\chi\beta a
    \le 0` or :math:`B = 0`. For :math:`C = 0`, :math:`\beta = 1` this is
    :math:`A_0 (A_0 + K k^2)\zeta / (2 B\chi(\alpha - B))`: half of paper Eq. (6).

    For :math:`B' \ne 0` the threshold (module docstring) is solved for :math:`q_b` by a scalar
    root find (Brent), the first sign change on :math:`0 < q_b < 10^3`.
    """
    beta = _beta(params, incompressible)
    a, k2 = params.alpha - params.B, float(k) ** 2
    if params.B <= 0.0:
        return math.inf
    if params.B_prime == 0.0:
        R = params.A0 + params.K * k2 + (1.0 - beta) * a * params.B / 2.0
        X = params.chi * beta * a
        disc = X * X - 6.0 * params.C * params.zeta**2 * R
        if X <= 0.0 or disc < 0.0:
            return math.inf
        q = params.zeta * R / (X + math.sqrt(disc))
        if q < 0.0:  # R < 0: the isotropic state is itself unstable
            return 0.0
        return _eps_of_q(params, q)
    grid = np.concatenate([[0.0], np.geomspace(1e-10, 1e3, 2000)])
    vals = np.array([_threshold_residual(params, float(x), k2, beta) for x in grid])
    if vals[0] <= 0.0:
        return 0.0
    idx = np.nonzero(vals[1:] <= 0.0)[0]
    if idx.size == 0:
        return math.inf
    i = int(idx[0])
    q = brentq(
        lambda x: _threshold_residual(params, x, k2, beta),
        grid[i],
        grid[i + 1],
        xtol=1e-16,
        rtol=1e-15,
    )
    return _eps_of_q(params, float(q))


def critical_eps_numerical(
    params: Parameters,
    *,
    incompressible: bool = False,
    nmax: int = 8,
    eps_max: float = 0.49,
    n_scan: int = 64,
    rtol: float = 1e-10,
) -> CriticalStrain:
    r"""Smallest :math:`\varepsilon \in (0, \varepsilon_{max}]` with
    :math:`\max_{\mathbf k}\mathrm{Re}\,\omega(\mathbf k; \varepsilon) > 0` over the lattice
    :math:`\mathbf k = 2\pi(n, m)`, :math:`|n|, |m| \le n_{max}` (:func:`max_growth_rate`,
    the leading eigenvalue of the full 3x3 operator at finite :math:`\tau`, no closed form used).

    A scan of ``n_scan`` equally spaced strains brackets the first unstable one (so a
    re-stabilising band above it is not skipped), then bisection to relative width ``rtol``.
    ``eps_max`` stays inside ``Parameters``' range :math:`|\varepsilon| < 0.5`. The sign of
    :math:`\varepsilon` does not matter (the problem is symmetric under a quarter turn).
    """
    if not 0.0 < eps_max < 0.5:
        raise ParameterError("eps_max", eps_max, "0 < eps_max < 0.5")

    def unstable(e: float) -> bool:
        om, _ = max_growth_rate(params, incompressible=incompressible, eps=e, nmax=nmax)
        return om.real > 0.0

    if unstable(0.0):
        om, mode = max_growth_rate(params, incompressible=incompressible, eps=0.0, nmax=nmax)
        return CriticalStrain(0.0, mode, (TWO_PI * mode[0], TWO_PI * mode[1]), om)
    scan = np.linspace(0.0, eps_max, n_scan + 1)
    lo = 0.0
    hi = math.nan
    for e in scan[1:]:
        if unstable(float(e)):
            hi = float(e)
            break
        lo = float(e)
    if math.isnan(hi):
        return CriticalStrain(math.inf, None, None, None)
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if unstable(mid):
            hi = mid
        else:
            lo = mid
    om, mode = max_growth_rate(params, incompressible=incompressible, eps=hi, nmax=nmax)
    return CriticalStrain(hi, mode, (TWO_PI * mode[0], TWO_PI * mode[1]), om)


def paper_eq6(params: Parameters, *, k: float = TWO_PI) -> float:
    r"""Paper Eq. (6) as printed:
    :math:`\varepsilon_c = \frac{A_0}{B}\frac{(A_0 + K k^2)\zeta}{\chi(\alpha - B)}`,
    :math:`k = 2\pi/L` (for comparison only; ours is :func:`critical_eps_closed_form`)."""
    denom = params.B * params.chi * (params.alpha - params.B)
    if denom <= 0.0:
        return math.inf
    return params.A0 * (params.A0 + params.K * float(k) ** 2) * params.zeta / denom
