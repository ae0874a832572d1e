r"""The finite-strain Krylov solves as compiled functions (numba + native FFTW).

The two linear problems of :class:`model.mechanics.FiniteMechanics` (module docstring there):

* Newton's correction, :math:`-\mathrm{Div}(\mathbb K : \nabla \delta u) = \mathrm{Div}\, P`,
  by preconditioned conjugate gradients (:func:`pcg`, Saad Alg. 9.1);
* the displacement rate of the Jaumann spin, :math:`-\mathrm{Div}(\mathbb K : \nabla \dot u
  + E\, \omega(\dot u)) = \mathrm{Div}(\partial_Q P : R)`, by right-preconditioned
  restarted GMRES (:func:`gmres`, Saad Alg. 9.5),

both preconditioned by the Green operator of the homogeneous isotropic reference medium, with
the Parseval inner product of half spectra. They are the same algorithms, step for step, as
:func:`model.krylov.pcg` / :func:`model.krylov.gmres` driven by the numpy operators of
``FiniteMechanics`` (the readable reference and the fallback, tested to agree); here the whole
loop, its eight transforms per operator application included, stays in compiled code.

Only used where :data:`model.compiled.fftw.AVAILABLE`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import fftw as fx
from .arith import imul
from .constitutive import apply_tangent_kernel, apply_tangent_spin_kernel
from .krylov import arnoldi_column, axpy, axpy_sum, scaled, solve_upper, weighted_inner
from .spectral import green_kernel

Array = np.ndarray


@njit(cache=True)
def _operator(v, K, E, spin, kx, ky, pf, pi, work_hat, G, out):  # pragma: no cover
    """``out`` = :math:`-\\mathrm{Div}(\\mathbb K : \\nabla v\\, [+ E\\, \\omega(v)])` for the
    spectrum ``v`` (the E term if ``spin``): 4 inverse and 4 forward transforms."""
    nx, ny = kx.shape
    for i in range(2):
        for j in range(2):
            for x in range(nx):
                for y in range(ny):
                    k = kx[x, y] if j == 0 else ky[x, y]
                    work_hat[x, y] = imul(k, v[i, x, y])
            fx.irfft2_via(pi, work_hat, G[i, j], work_hat)  # work_hat is rebuilt each time
    P = apply_tangent_spin_kernel(K, G, E) if spin else apply_tangent_kernel(K, G)
    for i in range(2):
        fx.rfft2(pf, P[i, 0], work_hat)
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] = imul(-kx[x, y], work_hat[x, y])
        fx.rfft2(pf, P[i, 1], work_hat)
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] -= imul(ky[x, y], work_hat[x, y])


@njit(cache=True)
def pcg(K, b, x0, kx, ky, khx, khy, inv_k2, a, w, pf, pi, rtol, maxiter):  # pragma: no cover
    """Preconditioned CG for Newton's correction; returns ``(x, iterations, status,
    operator applications)``, status 0 ok, 1 maxiter, 2 indefinite (as
    :func:`model.krylov.pcg`'s "ok", "maxiter", "indefinite")."""
    n = K.shape[4]
    work_hat = np.empty(kx.shape, dtype=np.complex128)
    G = np.empty((2, 2, n, n))
    x = x0.copy()
    nop = 0
    if np.any(x != 0):
        Ax = np.empty_like(b)
        _operator(x, K, K[0, 0], False, kx, ky, pf, pi, work_hat, G, Ax)
        nop += 1
        r = b - Ax
    else:
        r = b.copy()
    z = green_kernel(r, khx, khy, inv_k2, a)
    p = z.copy()
    rz = weighted_inner(r, z, w)
    ref = np.sqrt(abs(weighted_inner(b, green_kernel(b, khx, khy, inv_k2, a), w)))
    if ref == 0.0:
        ref = 1.0
    Ap = np.empty_like(b)
    for it in range(maxiter + 1):
        if np.sqrt(abs(rz)) <= rtol * ref:
            return x, it, 0, nop
        if it == maxiter:
            break
        _operator(p, K, K[0, 0], False, kx, ky, pf, pi, work_hat, G, Ap)
        nop += 1
        pAp = weighted_inner(p, Ap, w)
        if pAp <= 0:
            return x, it, 2, nop
        step = rz / pAp
        axpy(x, step, p)
        axpy(r, -step, Ap)
        z = green_kernel(r, khx, khy, inv_k2, a)
        rz_new = weighted_inner(r, z, w)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, maxiter, 1, nop


@njit(cache=True)
def gmres(K, E, b, x0, kx, ky, khx, khy, inv_k2, a, w, pf, pi, rtol, maxiter, V, Z
          ):  # pragma: no cover
    """Right-preconditioned restarted GMRES for the displacement rate; returns ``(x,
    iterations, converged, operator applications)``. ``V`` (restart + 1 spectra) and ``Z``
    (restart) are caller-owned work arrays."""
    n = K.shape[4]
    restart = Z.shape[0]
    work_hat = np.empty(kx.shape, dtype=np.complex128)
    G = np.empty((2, 2, n, n))
    Ax = np.empty_like(b)
    wv = np.empty_like(b)
    H = np.zeros((restart + 1, restart))
    g = np.zeros(restart + 1)
    cs = np.zeros(restart)
    sn = np.zeros(restart)
    x = x0.copy()
    bnorm = np.sqrt(weighted_inner(b, b, w))
    if bnorm == 0.0:
        bnorm = 1.0
    total = 0
    nop = 0
    zero_start = not np.any(x)  # then r = b: no operator application
    while True:
        if zero_start:
            Ax[...] = 0.0
            zero_start = False
        else:
            _operator(x, K, E, True, kx, ky, pf, pi, work_hat, G, Ax)
            nop += 1
        r = b - Ax
        beta = np.sqrt(weighted_inner(r, r, w))
        if beta <= rtol * bnorm:
            return x, total, True, nop
        if total >= maxiter:
            return x, total, False, nop
        scaled(V[0], r, beta)
        H[:, :] = 0.0
        g[:] = 0.0
        g[0] = beta
        k = 0
        h_next = 0.0
        for k in range(restart):
            Z[k] = green_kernel(V[k], khx, khy, inv_k2, a)
            _operator(Z[k], K, E, True, kx, ky, pf, pi, work_hat, G, wv)
            nop += 1
            h_next = arnoldi_column(V, wv, H, g, cs, sn, k, w)
            total += 1
            if abs(g[k + 1]) <= rtol * bnorm or total >= maxiter or h_next <= 1e-14 * beta:
                break
            scaled(V[k + 1], wv, h_next)
        m = k + 1
        y = solve_upper(H, g, m)
        axpy_sum(x, y, Z, m)
        if abs(g[m]) <= rtol * bnorm or h_next <= 1e-14 * beta:
            return x, total, True, nop


def workspace(n: int, restart: int = 30) -> tuple[Array, Array]:
    """The ``(V, Z)`` work arrays of :func:`gmres` for an N x N grid."""
    shape = (2, n, n // 2 + 1)
    return (np.empty((restart + 1,) + shape, dtype=np.complex128),
            np.empty((restart,) + shape, dtype=np.complex128))
