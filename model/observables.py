r"""Observables: pure functions of the fields (no I/O).

Definitions (unit domain, :math:`\langle\cdot\rangle` = area mean):

* ``mean_S`` :math:`\langle S \rangle`, :math:`S = \sqrt{q_1^2 + q_2^2}`;
* ``sigma2_S`` :math:`\sigma^2_S = \langle (S - \langle S\rangle)^2 \rangle` (paper, Fig. 2);
* ``cos2theta`` :math:`\langle \cos 2\theta \rangle = \langle q_1 / S \rangle`, points with
  :math:`S < 10^{-12}` (undefined director) count as 0 (isotropic);
* ``lambda`` the pattern size :math:`\lambda = 2\pi / \bar k`, :math:`\bar k = \sum_k |k|\,
  |\widehat{\delta S}(k)|^2 / \sum_k |\widehat{\delta S}(k)|^2` over all nonzero modes
  (isotropic spectrum-weighted mean wavenumber of :math:`\delta S = S - \langle S \rangle`);
  NaN when :math:`\sigma^2_S = 0`;
* ``mean_I1bar`` :math:`\langle \mathrm{tr}\, C / J \rangle`, ``min_J`` :math:`\min J`,
  ``mean_A`` :math:`\langle A \rangle`;
* ``free_energy`` :math:`\int \Psi` of paper Eq. (1) (small-strain elastic energy in linear
  mechanics), ``residual`` the force-balance residual of :mod:`model.mechanics`.
"""

from __future__ import annotations

import numpy as np

from . import constitutive as cl
from . import tensors as T
from .fourier import SpectralGrid
from .parameters import Parameters

Array = np.ndarray


def order_parameter(q1: Array, q2: Array) -> Array:
    return np.sqrt(q1**2 + q2**2)


def anisotropy(q1: Array, q2: Array) -> float:
    S = order_parameter(q1, q2)
    ok = S > 1e-12
    return float(np.mean(np.where(ok, q1 / np.where(ok, S, 1.0), 0.0)))


def pattern_size(S: Array, grid: SpectralGrid) -> float:
    dS_hat = grid.forward(S - S.mean())
    power = grid.weights * np.abs(dS_hat) ** 2
    power[0, 0] = 0.0
    total = power.sum()
    if total <= 1e-30 * S.size**2:
        return float("nan")
    kbar = float((np.sqrt(grid.k2) * power).sum() / total)
    return 2 * np.pi / kbar


def free_energy(q1: Array, q2: Array, A: Array, F: Array, params: Parameters,
                grid: SpectralGrid, *, linear: bool) -> float:
    """:math:`\\int \\Psi\\, dX` of paper Eq. (1) over the unit square."""
    p = params
    QQ = 2.0 * (q1**2 + q2**2)
    g1, g2 = grid.gradient(q1), grid.gradient(q2)
    frank = 0.5 * p.K * 2.0 * (np.sum(g1**2, axis=0) + np.sum(g2**2, axis=0))
    m = cl.Moduli.from_params(p)
    Q = T.nematic(q1, q2)
    if linear:
        elastic = cl.small_strain_energy_density(F - T.identity(q1.shape), Q, m)
    else:
        elastic = cl.energy_density(F, Q, m)
    psi = 0.5 * (A + p.A0) * QQ + 0.25 * p.C * QQ**2 + frank + elastic
    return float(np.mean(psi))


def snapshot_observables(q1: Array, q2: Array, A: Array, F: Array, residual: float,
                         params: Parameters, grid: SpectralGrid, *, linear: bool
                         ) -> dict[str, float]:
    S = order_parameter(q1, q2)
    J = T.det(F)
    C = T.matmul(T.transpose(F), F)
    return {
        "mean_S": float(S.mean()),
        "sigma2_S": float(np.mean((S - S.mean()) ** 2)),
        "cos2theta": anisotropy(q1, q2),
        "lambda": pattern_size(S, grid),
        "mean_I1bar": float(np.mean(T.trace(C) / J)),
        "min_J": float(J.min()),
        "mean_A": float(A.mean()),
        "free_energy": free_energy(q1, q2, A, F, params, grid, linear=linear),
        "residual": float(residual),
    }


def first_peak(values: Array, *, significance: float = 0.5) -> int:
    """Index of the first local maximum of a time series that reaches at least
    ``significance`` times its global maximum (so a small early wiggle of the relaxing
    initial noise is not taken for the pattern's peak); the global maximum if there is none
    (e.g. a series that only grows). Fig. 3 measures lambda "at the first peak value of
    sigma2_S over time"."""
    v = np.asarray(values, dtype=float)
    if not len(v):
        return 0
    finite = np.where(np.isfinite(v), v, -np.inf)
    top = float(finite.max())
    for i in range(1, len(v) - 1):
        if finite[i] > finite[i - 1] and finite[i] >= finite[i + 1] \
                and finite[i] >= significance * top:
            return i
    return int(np.argmax(finite))
