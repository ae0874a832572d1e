"""Spectral machinery on the periodic unit square, built once per grid.

Conventions: arrays are ``[..., x, y]`` (py-pde's Cartesian layout), real FFTs over the last
two axes with numpy's normalisation (forward unnormalised, inverse divides by N^2), so the
half spectrum has shape ``(N, N // 2 + 1)``. Wavevectors ``k = 2 pi (n, m)`` (L = 1).

Derivatives use ``i k`` with the Nyquist components set to zero (the derivative of the
Nyquist mode is not defined on a real grid); the Laplacian uses the exact ``-|k|^2``.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import scipy.fft

from .compiled import fftw

log = logging.getLogger(__name__)

Array = np.ndarray

#: FFTW through :mod:`nematic_solids.model.compiled.fftw` (2.5-3x faster than numpy's FFT at 128^2
#: here, and callable from compiled code); scipy.fft where the FFTW library cannot be loaded.
#: FFTW_MEASURE at run time would time candidate algorithms and may pick a different one in another
#: process (seen: a campaign's local and dask-cluster runs differed in the last digits), so results
#: would not be bitwise reproducible across processes. The plans therefore come from wisdom shipped
#: with the code (FFTW_PATIENT, made once) or, for sizes it does not hold, from FFTW_ESTIMATE: both
#: deterministic (:mod:`nematic_solids.model.compiled.fftw`).
HAVE_FFTW = fftw.AVAILABLE


class FFT:
    """Real 2-D FFTs over the last two axes (one FFTW plan pair per grid size)."""

    def __init__(self, n: int, *, backend: str = "auto"):
        self.n = n
        if backend == "auto":
            backend = "fftw" if HAVE_FFTW else "scipy"
        if backend == "fftw" and not HAVE_FFTW:
            raise ImportError(
                "the FFTW library (shipped with pyfftw) cannot be loaded; use backend='scipy'"
            )
        if backend not in ("fftw", "scipy"):
            raise ValueError(f"unknown FFT backend {backend!r} (fftw, scipy)")
        self.backend = backend
        #: the (r2c, c2r) plans for compiled code (None for scipy)
        self.plans = fftw.plans(n) if backend == "fftw" else None
        #: where the plans came from: "wisdom", "estimate" (FFTW), or "" (scipy)
        self.plan_source = fftw.plan_source(n) if backend == "fftw" else ""
        self.count = 0  # number of 2-D transforms performed (for the benchmark)

    def forward(self, a: Array) -> Array:
        """``rfft2`` over the last two axes (unnormalised)."""
        lead = a.shape[:-2]
        k = math.prod(lead)  # (np.prod costs ~30 us a call)
        self.count += k
        if self.plans is None:
            return scipy.fft.rfftn(a, axes=(-2, -1), workers=1)
        n = self.n
        src = np.ascontiguousarray(a, dtype=np.float64).reshape(k, n, n)
        out = np.empty((k, n, n // 2 + 1), dtype=np.complex128)
        fftw.rfft2_many(self.plans[0], src, out)
        return out.reshape(lead + (n, n // 2 + 1))

    def inverse(self, a: Array, out: Array | None = None) -> Array:
        """``irfft2`` over the last two axes (divides by N^2), into ``out`` if given (a
        C-contiguous float array of the result's shape, e.g. a slice of a larger state)."""
        lead = a.shape[:-2]
        k = math.prod(lead)  # (np.prod costs ~30 us a call)
        self.count += k
        n = self.n
        if self.plans is None:
            res = scipy.fft.irfftn(a, s=(n, n), axes=(-2, -1), workers=1)
            if out is None:
                return res
            out[...] = res
            return out
        src = np.ascontiguousarray(a, dtype=np.complex128).reshape(k, n, n // 2 + 1)
        if out is None:
            out = np.empty(lead + (n, n), dtype=np.float64)
        elif out.shape != lead + (n, n) or not out.flags.c_contiguous:
            raise ValueError(f"out must be C-contiguous of shape {lead + (n, n)}")
        fftw.irfft2_many(self.plans[1], src, out.reshape(k, n, n))
        return out


class SpectralGrid:
    """Wavevectors, Parseval weights and derivative operators for an N x N periodic grid."""

    def __init__(self, n: int, *, fft_backend: str = "auto"):
        if n % 2:
            raise ValueError(f"resolution must be even, got {n}")
        self.n = n
        self.dx = 1.0 / n
        self.x = (np.arange(n) + 0.5) / n  # cell centres, as py-pde's CartesianGrid
        self.fft = FFT(n, backend=fft_backend)
        kx = 2 * np.pi * np.fft.fftfreq(n, d=1.0 / n)
        ky = 2 * np.pi * np.fft.rfftfreq(n, d=1.0 / n)
        KX, KY = np.meshgrid(kx, ky, indexing="ij")
        self.k2 = KX**2 + KY**2  # exact |k|^2, for the Laplacian
        nyq = np.zeros_like(self.k2, dtype=bool)
        nyq[n // 2, :] = True
        nyq[:, -1] = True
        self.nyquist = nyq
        self.kx = np.where(nyq, 0.0, KX)  # derivative wavevectors (Nyquist removed)
        self.ky = np.where(nyq, 0.0, KY)
        kd2 = self.kx**2 + self.ky**2
        self.active = kd2 > 0  # modes a periodic displacement may carry
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(self.active, 1.0 / np.sqrt(np.where(self.active, kd2, 1.0)), 0.0)
        self.khat = np.stack([self.kx * inv, self.ky * inv])  # unit wavevector (0 off-mask)
        self.kd2 = kd2
        w = np.full(self.k2.shape, 2.0)
        w[:, 0] = 1.0
        w[:, -1] = 1.0
        self.weights = w  # Parseval weights of the half spectrum

    # --- transforms -------------------------------------------------------------------
    def forward(self, a: Array) -> Array:
        return self.fft.forward(a)

    def inverse(self, a: Array, out: Array | None = None) -> Array:
        return self.fft.inverse(a, out)

    # --- spectral calculus (inputs and outputs in Fourier space) ----------------------
    def grad_hat(self, a_hat: Array) -> Array:
        """``d_j a -> i k_j a_hat``; a new last-but-two axis j of length 2."""
        return np.stack([1j * self.kx * a_hat, 1j * self.ky * a_hat], axis=-3)

    def div_hat(self, t_hat: Array) -> Array:
        """Divergence over the last tensor index: ``d_j T_ij -> i k_j T_ij``."""
        return 1j * (self.kx * t_hat[..., 0, :, :] + self.ky * t_hat[..., 1, :, :])

    def laplacian(self, a: Array) -> Array:
        """Real-space Laplacian of a real field (exact spectral ``-|k|^2``)."""
        return self.inverse(-self.k2 * self.forward(a))

    def gradient(self, a: Array) -> Array:
        """Real-space gradient ``[..., j, x, y]`` of a real field."""
        return self.inverse(self.grad_hat(self.forward(a)))

    def inner(self, a_hat: Array, b_hat: Array) -> float:
        """Real-space inner product sum_x a b, computed from half spectra (Parseval): weight 2
        on every column of the half spectrum but the first and the last (Nyquist)."""
        full = np.vdot(a_hat, b_hat).real
        edges = (
            np.vdot(a_hat[..., 0], b_hat[..., 0]).real
            + np.vdot(a_hat[..., -1], b_hat[..., -1]).real
        )
        return float(2.0 * full - edges) / self.n**2

    def rms_hat(self, a_hat: Array) -> float:
        """RMS over the grid (and over leading components summed) from a half spectrum."""
        return float(np.sqrt(np.sum(self.weights * np.abs(a_hat) ** 2))) / self.n**2
