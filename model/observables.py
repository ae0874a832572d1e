r"""Observables: pure functions of the fields (no I/O).

Definitions (unit domain, :math:`\langle\cdot\rangle` = area mean):

* ``mean_S`` :math:`\langle S \rangle`, :math:`S = \sqrt{q_1^2 + q_2^2}`;
* ``sigma2_S`` :math:`\sigma^2_S = \langle (S - \langle S\rangle)^2 \rangle` (paper, Fig. 2);
* ``cos2theta`` :math:`\langle \cos 2\theta \rangle = \langle q_1 / S \rangle`, points with
  :math:`S < 10^{-12}` (undefined director) count as 0 (isotropic);
* ``lambda`` the pattern size :math:`\lambda = L / \bar n` from the **radial (shell-summed)
  spectrum** :math:`E(n) = \sum_{n - 1/2 \le |k| L / 2\pi < n + 1/2}
  |\widehat{\delta S}(k)|^2` of :math:`\delta S = S - \langle S \rangle`: :math:`\bar n =
  \sum_{n \ge 1} n E(n)^2 / \sum_{n \ge 1} E(n)^2`, the centroid of the squared spectrum (a
  peak position that weights the dominant shells and not the noise floor, and moves
  continuously when two shells compete; :func:`pattern_size`);
* ``lambda_mean`` :math:`2\pi / \bar k` with :math:`\bar k = \sum_k |k|\, |\widehat{\delta S}(k)|^2
  / \sum_k |\widehat{\delta S}(k)|^2` over all nonzero modes (the spectrum-weighted mean
  wavenumber, :func:`pattern_size_mean`); both NaN when :math:`\sigma^2_S = 0`;
* ``rate_margin`` the well-posedness margin of the rate problem
  (:mod:`nematic_solids.model.wellposedness`, 1 passive, 0 at the loss of well-posedness);
* ``mean_I1bar`` :math:`\langle \mathrm{tr}\, C / J \rangle`, ``min_J`` :math:`\min J`,
  ``mean_A`` :math:`\langle A \rangle`;
* ``free_energy`` :math:`\int \Psi` of paper Eq. (1) (small-strain elastic energy in linear
  mechanics), ``residual`` the force-balance residual of :mod:`nematic_solids.model.mechanics`.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import peak_prominences

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


def _power(S: Array, grid: SpectralGrid) -> Array | None:
    """Half-spectrum power of S - <S> with Parseval weights (mean mode zeroed); None if the
    field is uniform."""
    dS_hat = grid.forward(S - S.mean())
    power = grid.weights * np.abs(dS_hat) ** 2
    power[0, 0] = 0.0
    if power.sum() <= 1e-30 * S.size**2:
        return None
    return power


def radial_spectrum(S: Array, grid: SpectralGrid) -> Array:
    r""":math:`E(n)`, n = 0, 1, ..., the power of S - <S> summed over the shells
    :math:`n - 1/2 \le |k| / 2\pi < n + 1/2` (unit box: k = 2 pi (i, j)); E(0) = 0."""
    power = _power(S, grid)
    shell = np.rint(np.sqrt(grid.k2) / (2 * np.pi)).astype(np.int64)
    if power is None:
        return np.zeros(int(shell.max()) + 1)
    return np.bincount(shell.ravel(), weights=power.ravel())


def pattern_size(S: Array, grid: SpectralGrid) -> float:
    r"""Pattern size :math:`L / \bar n`, :math:`\bar n = \sum_n n E(n)^2 / \sum_n E(n)^2` over
    the shells n >= 1 of the radial spectrum (module docstring); NaN for a uniform field."""
    E = radial_spectrum(S, grid)[1:]
    if not np.any(E > 0):
        return float("nan")
    w = (E / E.max()) ** 2
    return float(w.sum() / (np.arange(1, len(E) + 1) * w).sum())


def pattern_size_mean(S: Array, grid: SpectralGrid) -> float:
    r""":math:`2\pi / \bar k`, the spectrum-weighted mean wavenumber (module docstring)."""
    power = _power(S, grid)
    if power is None:
        return float("nan")
    kbar = float((np.sqrt(grid.k2) * power).sum() / power.sum())
    return 2 * np.pi / kbar


def free_energy(
    q1: Array,
    q2: Array,
    A: Array,
    F: Array,
    params: Parameters,
    grid: SpectralGrid,
    *,
    linear: bool,
) -> float:
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


def snapshot_observables(
    q1: Array,
    q2: Array,
    A: Array,
    F: Array,
    residual: float,
    params: Parameters,
    grid: SpectralGrid,
    *,
    linear: bool,
    P: Array | None = None,
) -> dict[str, float]:
    """The observables of one saved state (the series of docs/model/observables.md); with the
    stress ``P`` (first Piola, or the small-strain stress) also the macroscopic stress
    (:func:`macroscopic_stress`)."""
    S = order_parameter(q1, q2)
    J = T.det(F)
    C = T.matmul(T.transpose(F), F)
    return {
        "mean_S": float(S.mean()),
        "sigma2_S": float(np.mean((S - S.mean()) ** 2)),
        "cos2theta": anisotropy(q1, q2),
        "lambda": pattern_size(S, grid),
        "lambda_mean": pattern_size_mean(S, grid),
        "mean_I1bar": float(np.mean(T.trace(C) / J)),
        "min_J": float(J.min()),
        "mean_A": float(A.mean()),
        "free_energy": free_energy(q1, q2, A, F, params, grid, linear=linear),
        "residual": float(residual),
        **(macroscopic_stress(P) if P is not None else {}),
    }


def macroscopic_stress(P: Array) -> dict[str, float]:
    r"""The area means of the stress (the macroscopic stress of the periodic cell, work
    conjugate to the applied :math:`\bar F`): ``stress_shear``
    :math:`\langle (P_{11} - P_{22})/2 \rangle`, the deviatoric part conjugate to the pure
    shear :math:`\epsilon` (:math:`2 G \epsilon` for the passive matrix at small strain, G = 1),
    ``stress_xy`` :math:`\langle P_{12} \rangle` and ``stress_mean``
    :math:`\langle (P_{11} + P_{22})/2 \rangle` (minus the pressure)."""
    return {
        "stress_shear": float(0.5 * np.mean(P[0, 0] - P[1, 1])),
        "stress_xy": float(np.mean(P[0, 1])),
        "stress_mean": float(0.5 * np.mean(P[0, 0] + P[1, 1])),
    }


def first_peak(values: Array, *, significance: float = 0.5) -> int:
    """The paper's literal rule ("at the first peak value of sigma2_S over time"): index of
    the first local maximum that reaches at least ``significance`` times the global maximum
    (so a wiggle of the relaxing initial noise is not taken); the global maximum if there is
    none. On a plateau this picks the first bump of the coarsening phase, however small."""
    v = np.asarray(values, dtype=float)
    if not len(v):
        return 0
    finite = np.where(np.isfinite(v), v, -np.inf)
    top = float(finite.max())
    for i in range(1, len(v) - 1):
        if (
            finite[i] > finite[i - 1]
            and finite[i] >= finite[i + 1]
            and finite[i] >= significance * top
        ):
            return i
    return int(np.argmax(finite))


def growth_peak(
    values: Array,
    times: Array | None = None,
    *,
    rate_fraction: float = 0.1,
    min_prominence: float = 0.1,
    level: float = 0.25,
) -> int:
    r"""Fig. 3's "first peak" read robustly, at the **end of the main growth phase**.

    The main growth phase is the rise that carries the series to its maximum: it starts at
    the deepest point before the maximum (so a maximum of the relaxing initial texture
    before that trough, at t ~ 1-5 on fine textures, is never taken). Within it, a growth
    phase runs from its fastest growth to the first sample from which the logarithmic
    growth rate :math:`d \ln \sigma^2_S / dt` falls below ``rate_fraction`` of that
    fastest rate. If that end is still below ``level`` times the maximum, the growth that
    stalled there was the texture's relaxation, not the pattern's: the search restarts
    from that sample (the next growth phase, with its own fastest rate). At the end found,
    if a local maximum follows within one growth time (the samples from the fastest growth
    to the end) and is a real overshoot (topographic prominence of at least
    ``min_prominence`` times the series' range), that maximum is returned instead. Bumps and
    creep of the coarsening phase (rates ~1 % of the growth rate) are never taken, however
    high; a series still growing at its end gives its last sample (fits treat it as not
    peaked); a series that never grows gives its maximum. Values below 1e-6 of the maximum
    are ignored (round-off level at the start). ``times`` (default: unit spacing) may be
    irregular."""
    v = np.asarray(values, dtype=float)
    n = len(v)
    if not n or not np.isfinite(v).any():
        return 0
    t = np.arange(n, dtype=float) if times is None else np.asarray(times, dtype=float)
    # values below floor * max carry no growth information (sigma2_S starts at exactly 0
    # for a uniform S0 and leaves round-off level in one step)
    top = float(np.nanmax(v))
    floor = 1e-6 * top
    valid = np.isfinite(v) & (v > floor)
    with np.errstate(divide="ignore", invalid="ignore"):
        lv = np.where(valid, np.log(np.where(valid, v, 1.0)), np.nan)
        rate = np.diff(lv) / np.diff(t)
    w = np.where(np.isfinite(v), v, np.nanmin(v))
    i_max = int(np.argmax(w))
    # the main rise starts at the deepest valid sample before the maximum
    before = np.where(valid[: i_max + 1], w[: i_max + 1], np.inf)
    start = int(np.argmin(before))
    while True:
        window = rate[start:i_max]
        if n < 2 or not np.any(np.isfinite(window)) or np.nanmax(window) <= 0:
            return i_max if start == 0 or not np.any(np.isfinite(rate)) else start
        i_fast = start + int(np.nanargmax(window))
        slow = np.nonzero(rate[i_fast:] < rate_fraction * rate[i_fast])[0]
        if not len(slow):
            return n - 1
        end = i_fast + int(slow[0])
        if w[end] >= level * top or end >= i_max:
            break
        start = end  # the texture's relaxation stalled here: look for the pattern's growth
    span = float(w.max() - w.min())
    # an overshoot peaks within one growth time (i_fast -> end) of the end of growth
    for i in range(max(end, 1), min(n - 1, 2 * end - i_fast + 2)):
        if w[i] > w[i - 1] and w[i] >= w[i + 1]:
            prom = float(peak_prominences(w, [i])[0][0])
            return i if prom >= min_prominence * span else end
        if w[i] < w[i - 1]:
            break
    return end
