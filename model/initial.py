r"""Seeded initial conditions: the initial director texture (``Parameters.initial``).

Both textures start from a complex Gaussian field :math:`\psi` with
:math:`\langle |\psi|^2 \rangle = 1`; they differ in its spectrum.

``initial = "band"`` (resolution independent): a band-limited field

.. math:: \psi(x) = \frac{1}{\sqrt{M}} \sum_{n^2 + m^2 \le n_c^2} c_{nm}\, e^{2\pi i (n x + m y)},
          \qquad c_{nm} \sim \mathcal{CN}(0, 1),

(M the number of modes, so :math:`\langle |\psi|^2 \rangle = 1`) is drawn from the seed in a
fixed mode order and evaluated at the cell centres of any grid with N > 2 n_c. The director
angle is :math:`2\theta = \arg \psi` (isotropic, correlation length ~ 1/n_c) and

.. math:: (q_1, q_2) = S_0 (\cos 2\theta, \sin 2\theta)
          + a\, (\mathrm{Re}\,\psi, \mathrm{Im}\,\psi), \qquad A = 0,

with :math:`a` = ``noise_amplitude`` (0 by default). Same seed, any resolution: the same
physical field, with correlation length ~ L / n_c.

``initial = "per_node"`` (the paper's "initial random orientation", per node of its mesh):
:math:`\psi_{ij} = (g_{ij} + i h_{ij}) / \sqrt 2` with independent standard normal
:math:`g, h` at every grid node (white noise), so every node has an independent, uniformly
distributed director angle and the same :math:`q_1, q_2` formula holds. Its correlation
length is the grid spacing: it is a different physical field at every resolution (a finer
grid is a finer texture), and the Frank term erases most of it within t ~ 1 / (K k_max^2).
With ``texture_resolution`` = N_0 (> 0) the white field is drawn on the N_0 x N_0 grid and
carried to the run's N x N grid by spectral interpolation (:func:`spectral_interpolate`): the
trigonometric polynomial through the N_0^2 cell-centre values, evaluated at the finer grid's
cell centres. A run at 2 N_0 then starts from the same physical field as one at N_0, as a
resolution study needs.
"""

from __future__ import annotations

import numpy as np

from .errors import ParameterError
from .parameters import Parameters

Array = np.ndarray


def band_limited_modes(seed: int, modes: int) -> tuple[Array, Array, Array]:
    """The lattice modes ``(n, m)`` with n^2 + m^2 <= modes^2 and their coefficients
    :math:`c_{nm} / \\sqrt{M}`, drawn from ``seed`` in a fixed order."""
    rng = np.random.default_rng(seed)
    ns = np.arange(-modes, modes + 1)
    n, m = np.meshgrid(ns, ns, indexing="ij")
    keep = n**2 + m**2 <= modes**2
    n, m = n[keep], m[keep]
    c = (rng.standard_normal(n.size) + 1j * rng.standard_normal(n.size)) / np.sqrt(2.0)
    return n, m, c / np.sqrt(n.size)


def band_limited_field(seed: int, modes: int, resolution: int) -> Array:
    """The complex field :math:`\\psi` above, sampled at cell centres ``(i + 1/2) / N``."""
    if resolution <= 2 * modes:
        raise ParameterError(
            "resolution",
            resolution,
            f"> 2 * noise_modes = {2 * modes} (the initial field has modes "
            f"up to {modes}; lower noise_modes or raise the resolution)",
        )
    n, m, c = band_limited_modes(seed, modes)
    # shift to cell centres so that every resolution samples the same function
    c = c * np.exp(1j * np.pi * (n + m) / resolution)
    Z = np.zeros((resolution, resolution), dtype=complex)
    Z[n % resolution, m % resolution] = c
    return np.fft.ifft2(Z) * resolution**2


def per_node_field(seed: int, resolution: int) -> Array:
    r"""The complex white field :math:`\psi` above: independent complex normal values of
    unit mean square at the ``resolution`` x ``resolution`` nodes, drawn from ``seed`` (real
    parts of the whole grid first, then the imaginary parts)."""
    rng = np.random.default_rng(seed)
    shape = (resolution, resolution)
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2.0)


def spectral_interpolate(field: Array, resolution: int) -> Array:
    r"""The trigonometric interpolant of ``field`` (values at the cell centres
    :math:`(i + 1/2)/N_0` of an N_0 x N_0 periodic grid, N_0 even) evaluated at the cell
    centres of the N x N grid, N >= N_0. The Nyquist modes :math:`\pm N_0/2` share the
    coarse grid's Nyquist coefficient equally (the interpolant then passes through every
    coarse value, and a real field stays real)."""
    n0 = field.shape[0]
    if field.shape != (n0, n0) or n0 % 2 or resolution < n0:
        raise ValueError(f"cannot interpolate a {field.shape} field to {resolution}^2")
    if resolution == n0:
        return field.copy()
    half = n0 // 2
    ks = np.arange(-half, half + 1)  # the Nyquist wavenumber on both sides
    raw = np.fft.fft2(field)[np.ix_(ks % n0, ks % n0)] / n0**2
    weight = np.where(np.abs(ks) == half, 0.5, 1.0)
    # the coefficient of exp(2 pi i k x) is the DFT value shifted from the coarse cell
    # centres to x = 0; then evaluated at the fine cell centres (j + 1/2) / N
    phase = weight * np.exp(1j * np.pi * ks * (1.0 / resolution - 1.0 / n0))
    Z = np.zeros((resolution, resolution), dtype=complex)
    np.add.at(
        Z,
        (ks[:, None] % resolution, ks[None, :] % resolution),
        raw * phase[:, None] * phase[None, :],
    )
    return np.fft.ifft2(Z) * resolution**2


def texture_field(params: Parameters, resolution: int, seed: int) -> Array:
    r"""The complex field :math:`\psi` of the texture ``params.initial``."""
    if params.initial == "per_node":
        drawn = params.texture_resolution or resolution
        psi = per_node_field(seed, drawn)
        return psi if drawn == resolution else spectral_interpolate(psi, resolution)
    return band_limited_field(seed, params.noise_modes, resolution)


def initial_fields(params: Parameters, resolution: int, seed: int) -> tuple[Array, Array, Array]:
    """Return ``(q1, q2, A)`` at t = 0 for the given seed (see module docstring)."""
    psi = texture_field(params, resolution, seed)
    angle = np.angle(psi)  # = 2 theta
    q1 = params.S0 * np.cos(angle) + params.noise_amplitude * psi.real
    q2 = params.S0 * np.sin(angle) + params.noise_amplitude * psi.imag
    return q1, q2, np.zeros_like(q1)
