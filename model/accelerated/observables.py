r"""The per-save observables of one seed on the device (``jax.vmap`` batches them), with the
definitions of :mod:`nematic_solids.model.observables` (docs/model/observables.md): ``mean_S``
:math:`\langle S\rangle`, ``sigma2_S`` :math:`\langle (S - \langle S\rangle)^2\rangle`,
``cos2theta`` :math:`\langle q_1/S\rangle` (0 where S < 1e-12), ``lambda`` :math:`L/\bar n`
from the shell-summed spectrum :math:`E(n)` of :math:`S - \langle S\rangle`,
:math:`\bar n = \sum_{n\ge1} n E^2 / \sum_{n\ge1} E^2`, ``lambda_mean`` :math:`2\pi/\bar k`
(the spectrum-weighted mean wavenumber), ``mean_A`` :math:`\langle A\rangle` and the
small-strain ``rate_margin`` :math:`1 - \max (\alpha - B) S`; both sizes NaN for a uniform S
(a variance below the rounding of the run's precision).
"""

from __future__ import annotations

from typing import NamedTuple, TypeAlias

import jax
import jax.numpy as jnp
import numpy as np

from ..fourier import SpectralGrid
from .linear_rhs import Constant, forward

Array: TypeAlias = jax.Array

#: the names :func:`observe` returns, in order
NAMES = ("mean_S", "sigma2_S", "cos2theta", "lambda", "lambda_mean", "mean_A", "rate_margin")


class ShellData(NamedTuple):
    """What the spectra need of the grid: the shell index ``rint(|k| / 2 pi)`` and ``|k|``
    of every mode of the half spectrum, the Parseval weights, and the number of shells."""

    shell: Constant
    kabs: Constant
    weights: Constant


def shell_data(n: int) -> tuple[ShellData, int]:
    """The :class:`ShellData` (numpy arrays) of an n x n grid and its number of shells."""
    g = SpectralGrid(n, fft_backend="scipy")
    shell = np.rint(np.sqrt(g.k2) / (2 * np.pi)).astype(np.int32)
    return ShellData(shell, np.sqrt(g.k2), g.weights), int(shell.max()) + 1


def observe(q: Array, A: Array, data: ShellData, nshell: int, alpha_minus_B: float) -> Array:
    """The observables :data:`NAMES` of one seed's fields, as one float64 vector: the fields
    of a float32 run are widened to float64 first (exactly), so every mean, the spectrum and
    its sums are float64 whatever the run's precision."""
    # a field is uniform below the rounding of the run's precision: float64's floor, scaled
    # by the squared ratio of the machine epsilons in a float32 run (its rounding alone gives
    # sigma2_S ~ 1e-18 at t = 0, and a pattern size of that noise)
    floor = 1e-30 * (float(jnp.finfo(q.dtype).eps) / float(jnp.finfo(jnp.float64).eps)) ** 2
    q, A = q.astype(jnp.float64), A.astype(jnp.float64)
    S = jnp.sqrt(q[0] ** 2 + q[1] ** 2)
    mean_S = jnp.mean(S)
    dS = S - mean_S
    ok = S > 1e-12
    cos2theta = jnp.mean(jnp.where(ok, q[0] / jnp.where(ok, S, 1.0), 0.0))
    power = data.weights * jnp.abs(forward(dS)) ** 2
    power = power.at[0, 0].set(0.0)
    total = jnp.sum(power)
    uniform = total <= floor * S.size**2
    E = jnp.zeros(nshell).at[data.shell.ravel()].add(power.ravel())[1:]
    peak = jnp.max(E)
    wE = (E / jnp.where(peak > 0.0, peak, 1.0)) ** 2
    moment = jnp.sum(jnp.arange(1, nshell) * wE)
    lam = jnp.where(
        uniform | (peak <= 0.0), jnp.nan, jnp.sum(wE) / jnp.where(moment > 0.0, moment, 1.0)
    )
    kbar = jnp.sum(data.kabs * power) / jnp.where(uniform, 1.0, total)
    lam_mean = jnp.where(uniform, jnp.nan, 2 * jnp.pi / jnp.where(kbar > 0, kbar, 1.0))
    margin = 1.0 - jnp.max(alpha_minus_B * S)
    return jnp.stack([mean_S, jnp.mean(dS**2), cos2theta, lam, lam_mean, jnp.mean(A), margin])
