"""Spectral operators on half spectra (numba): gradient, divergence, the Green operator of
the isotropic reference medium, the linear mechanics' response and spin symbols.

numpy twin: :mod:`nematic_solids.model.reference_kernels` (from
:meth:`nematic_solids.model.fourier.SpectralGrid.grad_hat`, ``div_hat`` and
:class:`nematic_solids.model.mechanics.LinearMechanics`' references); tested to agree in
``tests/model/test_constitutive.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .arith import imul, rmul


@njit(cache=True)
def grad_hat_kernel(v, kx, ky):  # pragma: no cover - compiled
    """:math:`\\widehat{\\partial_j v_i} = i k_j \\hat v_i` (reference:
    :meth:`nematic_solids.model.fourier.SpectralGrid.grad_hat`)."""
    nx, ny = kx.shape
    out = np.empty((2, 2, nx, ny), dtype=np.complex128)
    for i in range(2):
        for x in range(nx):
            for y in range(ny):
                z = v[i, x, y]
                out[i, 0, x, y] = imul(kx[x, y], z)
                out[i, 1, x, y] = imul(ky[x, y], z)
    return out


@njit(cache=True)
def neg_div_hat_kernel(T, kx, ky):  # pragma: no cover - compiled
    """:math:`-i k_j \\hat T_{ij}` (reference: minus
    :meth:`nematic_solids.model.fourier.SpectralGrid.div_hat`)."""
    nx, ny = kx.shape
    out = np.empty((2, nx, ny), dtype=np.complex128)
    for i in range(2):
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] = imul(
                    -1.0, rmul(kx[x, y], T[i, 0, x, y]) + rmul(ky[x, y], T[i, 1, x, y])
                )
    return out


@njit(cache=True)
def div_hat_kernel(T, kx, ky):  # pragma: no cover - compiled
    r""":math:`i k_j \hat T_{ij}` (reference:
    :meth:`nematic_solids.model.fourier.SpectralGrid.div_hat`)."""
    nx, ny = kx.shape
    out = np.empty((2, nx, ny), dtype=np.complex128)
    for i in range(2):
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] = imul(
                    1.0, rmul(kx[x, y], T[i, 0, x, y]) + rmul(ky[x, y], T[i, 1, x, y])
                )
    return out


@njit(cache=True)
def green_into(b, khx, khy, inv_k2, a, out):  # pragma: no cover - compiled
    """:func:`green_kernel` into ``out`` (the Krylov preconditioner: no allocation)."""
    nx, ny = khx.shape
    for x in range(nx):
        for y in range(ny):
            h1 = khx[x, y]
            h2 = khy[x, y]
            kb = rmul(a, rmul(h1, b[0, x, y]) + rmul(h2, b[1, x, y]))
            out[0, x, y] = rmul(inv_k2[x, y], b[0, x, y] - rmul(h1, kb))
            out[1, x, y] = rmul(inv_k2[x, y], b[1, x, y] - rmul(h2, kb))


@njit(cache=True)
def green_kernel(b, khx, khy, inv_k2, a):  # pragma: no cover - compiled
    """Green operator of the isotropic reference medium, :math:`(I - a \\hat k \\hat k)
    \\hat b / k^2` (numpy twin: :func:`nematic_solids.model.reference_kernels.green_kernel`)."""
    out = np.empty((2,) + khx.shape, dtype=np.complex128)
    green_into(b, khx, khy, inv_k2, a, out)
    return out


@njit(cache=True)
def balance_residual_kernel(P, P_hat, khx, khy, weights):  # pragma: no cover - compiled
    r"""The force-balance residual :math:`\lVert \hat k_J \hat P_{iJ} \rVert /
    \max(1, \mathrm{RMS}\, P)` (:meth:`nematic_solids.model.mechanics.Mechanics.residual`): the RMS
    of Div P in the :math:`H^{-1}` norm from the half spectrum ``P_hat`` (Parseval ``weights``) over
    the RMS stress, floored at the shear modulus 1."""
    nx, ny = khx.shape
    s = 0.0
    for i in range(2):
        for x in range(nx):
            for y in range(ny):
                r = rmul(khx[x, y], P_hat[i, 0, x, y]) + rmul(khy[x, y], P_hat[i, 1, x, y])
                s += weights[x, y] * (r.real * r.real + r.imag * r.imag)
    n = P.shape[2]
    p2 = 0.0
    for i in range(2):
        for j in range(2):
            for x in range(n):
                for y in range(P.shape[3]):
                    p2 += P[i, j, x, y] * P[i, j, x, y]
    return np.sqrt(s) / (n * n) / max(1.0, np.sqrt(p2 / (n * P.shape[3])))


@njit(cache=True)
def symbol_combination(x, m1, m2, a, b):  # pragma: no cover - compiled
    r""":math:`x - (m_1 a + m_2 b)` for half spectra ``a, b`` and real symbols ``m1, m2``
    (``x`` may be a zero array): the spin multiplier of the linear mechanics, fused."""
    nx, ny = a.shape
    out = np.empty((nx, ny), dtype=np.complex128)
    for i in range(nx):
        for j in range(ny):
            out[i, j] = x[i, j] - (m1[i, j] * a[i, j] + m2[i, j] * b[i, j])
    return out


@njit(cache=True)
def linear_response(
    q1h, q2h, isoh, kx, ky, khx, khy, inv_k2, amb, a, kappa, incompressible, mean_dev
):  # pragma: no cover - compiled
    r"""Fused :meth:`nematic_solids.model.mechanics.LinearMechanics.spectral_response`: from the
    spectra of q1, q2 (and of the isotropic eigenstress ``isoh`` = -B' Q:Q hat, zeros if B' = 0)
    return the spectra ``dev e`` (2 components), ``tr e`` and ``tr sigma`` of the small-strain
    solution; ``a`` is the Green operator's kappa / (kappa + 1) (1 if incompressible) and
    ``mean_dev`` the applied eps times N^2 (the mean of dev e in unnormalised spectra)."""
    nx, ny = q1h.shape
    dev = np.empty((2, nx, ny), dtype=np.complex128)
    tr_e = np.empty((nx, ny), dtype=np.complex128)
    tr_s = np.empty((nx, ny), dtype=np.complex128)
    for i in range(nx):
        for j in range(ny):
            t11 = amb * q1h[i, j]
            t12 = amb * q2h[i, j]
            iso = isoh[i, j]
            k1 = kx[i, j]
            k2 = ky[i, j]
            b1 = 1j * (k1 * (t11 + iso) + k2 * t12)
            b2 = 1j * (k1 * t12 + k2 * (-t11 + iso))
            h1 = khx[i, j]
            h2 = khy[i, j]
            kb = h1 * b1 + h2 * b2
            u1 = (b1 - a * h1 * kb) * inv_k2[i, j]
            u2 = (b2 - a * h2 * kb) * inv_k2[i, j]
            e11 = 1j * k1 * u1
            e22 = 1j * k2 * u2
            e12 = 0.5j * (k2 * u1 + k1 * u2)
            dev[0, i, j] = 0.5 * (e11 - e22)
            dev[1, i, j] = e12
            tr_e[i, j] = e11 + e22
            if incompressible:
                p = (h1 * h1 - h2 * h2) * t11 + 2.0 * h1 * h2 * t12
                if inv_k2[i, j] != 0.0:
                    p += iso
                tr_s[i, j] = -2.0 * p + 2.0 * iso
            else:
                tr_s[i, j] = 2.0 * kappa * (e11 + e22) + 2.0 * iso
    dev[0, 0, 0] += mean_dev
    return dev, tr_e, tr_s
