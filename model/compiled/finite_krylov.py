r"""The finite-strain Krylov solves as compiled functions (numba + native FFTW).

The two linear problems of :class:`nematic_solids.model.mechanics.FiniteMechanics` (module docstring
there):

* Newton's correction, :math:`-\mathrm{Div}(\mathbb K : \nabla \delta u) = \mathrm{Div}\, P`,
  by preconditioned conjugate gradients (:func:`pcg`, Saad Alg. 9.1);
* the displacement rate of the Jaumann spin, :math:`-\mathrm{Div}(\mathbb K : \nabla \dot u
  + E\, \omega(\dot u)) = \mathrm{Div}(\partial_Q P : R)`, by right-preconditioned
  restarted GMRES (:func:`gmres`, Saad Alg. 9.5),

both preconditioned by the Green operator of the homogeneous isotropic reference medium, with
the Parseval inner product of half spectra. They are the same algorithms, step for step, as
:func:`nematic_solids.model.krylov.pcg` / :func:`nematic_solids.model.krylov.gmres_aux` driven by
the numpy operators of ``FiniteMechanics`` (the readable reference and the fallback, tested to
agree); here the whole loop, its eight transforms per operator application included, stays in
compiled code. The rate's GMRES also returns the real-space gradient of its solution, summed from
the gradients of its operator applications (the auxiliary output of
:func:`nematic_solids.model.compiled.krylov.gmres`).

Only used where :data:`nematic_solids.model.compiled.fftw.AVAILABLE`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.extending import overload

from . import fftw as fx
from . import krylov
from .arith import imul
from .constitutive import apply_tangent_into
from .krylov import apply_operator, apply_operator_given_aux, precondition
from .spectral import green_into

Array = np.ndarray


@njit(cache=True)
def _operator(v, K, E, spin, kx, ky, pf, pi, work_hat, G, P, out):  # pragma: no cover
    """``out`` = :math:`-\\mathrm{Div}(\\mathbb K : \\nabla v\\, [+ E\\, \\omega(v)])` for the
    spectrum ``v`` (the E term if ``spin``): 4 inverse and 4 forward transforms. ``G`` and
    ``P`` are work arrays (the gradient and the stress). The inverse transforms' 1/N^2 is
    folded into the gradient's symbol: a power of two, so the result is bitwise that of
    scaling after the transform."""
    nx, ny = kx.shape
    n = G.shape[2]
    scale = 1.0 / (n * n)
    for i in range(2):
        for j in range(2):
            for x in range(nx):
                for y in range(ny):
                    k = kx[x, y] if j == 0 else ky[x, y]
                    work_hat[x, y] = imul(k * scale, v[i, x, y])
            # work_hat is rebuilt each time, so the transform may destroy it
            fx.unscaled_irfft2_into(pi, work_hat, G[i, j], work_hat)
    _operator_of_gradient(G, K, E, spin, kx, ky, pf, work_hat, P, out)


@njit(cache=True)
def _operator_of_gradient(G, K, E, spin, kx, ky, pf, work_hat, P, out):  # pragma: no cover
    r"""The rest of :func:`_operator` for the real-space gradient ``G`` of ``v``: ``out`` =
    :math:`-\mathrm{Div}(\mathbb K : G\, [+ E\, \omega(G)])` (4 forward transforms)."""
    nx, ny = kx.shape
    apply_tangent_into(K, G, E, spin, P)
    for i in range(2):
        fx.rfft2(pf, P[i, 0], work_hat)
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] = imul(-kx[x, y], work_hat[x, y])
        fx.rfft2(pf, P[i, 1], work_hat)
        for x in range(nx):
            for y in range(ny):
                out[i, x, y] -= imul(ky[x, y], work_hat[x, y])


class TangentOperator(NamedTuple):
    """:math:`-\\mathrm{Div}(\\mathbb K : \\nabla v\\, [+ E\\, \\omega(v)])` of
    :func:`_operator` (the E term if ``spin``: the displacement rate; without it Newton's
    tangent) and its Green preconditioner, for the compiled
    :func:`nematic_solids.model.compiled.krylov.pcg` and
    :func:`nematic_solids.model.compiled.krylov.gmres`."""

    K: Array
    E: Array
    spin: bool
    kx: Array
    ky: Array
    khx: Array
    khy: Array
    inv_k2: Array
    a: float
    pf: int
    pi: int
    work_hat: Array
    G: Array
    P: Array


@overload(apply_operator)
def _apply_tangent(op, x, out, aux):  # pragma: no cover - compiled
    if getattr(op, "instance_class", None) is not TangentOperator:  # the named tuple type
        return None
    if isinstance(aux, types.Array) and aux.ndim == 4:

        def impl(op, x, out, aux):  # the auxiliary output: the real-space gradient of x
            _operator(
                x, op.K, op.E, op.spin, op.kx, op.ky, op.pf, op.pi, op.work_hat, aux, op.P, out
            )

        return impl

    def impl_plain(op, x, out, aux):  # no auxiliary output
        _operator(x, op.K, op.E, op.spin, op.kx, op.ky, op.pf, op.pi, op.work_hat, op.G, op.P, out)

    return impl_plain


@overload(apply_operator_given_aux)
def _apply_tangent_given_gradient(op, x, aux, out):  # pragma: no cover - compiled
    if getattr(op, "instance_class", None) is not TangentOperator:  # the named tuple type
        return None

    def impl(op, x, aux, out):  # aux: the real-space gradient of x
        _operator_of_gradient(aux, op.K, op.E, op.spin, op.kx, op.ky, op.pf, op.work_hat, op.P, out)

    return impl


@overload(precondition)
def _precondition_tangent(op, v, out):  # pragma: no cover - compiled
    if getattr(op, "instance_class", None) is TangentOperator:  # the named tuple type

        def impl(op, v, out):
            green_into(v, op.khx, op.khy, op.inv_k2, op.a, out)

        return impl
    return None


@njit(cache=True)
def _tangent_operator(K, E, spin, kx, ky, khx, khy, inv_k2, a, pf, pi):  # pragma: no cover
    """The :class:`TangentOperator` of the packed tangent ``K`` (10, N, N), with its work
    arrays (a half spectrum, the gradient and the stress)."""
    n = K.shape[1]
    return TangentOperator(
        K,
        E,
        spin,
        kx,
        ky,
        khx,
        khy,
        inv_k2,
        a,
        pf,
        pi,
        np.empty(kx.shape, dtype=np.complex128),
        np.empty((2, 2, n, n)),
        np.empty((2, 2, n, n)),
    )


@njit(cache=True)
def pcg(K, b, x0, kx, ky, khx, khy, inv_k2, a, w, pf, pi, rtol, maxiter):  # pragma: no cover
    """Newton's correction by :func:`nematic_solids.model.compiled.krylov.pcg`, preconditioned by
    the Green operator; returns ``(x, iterations, status, operator applications)``, status 0 ok, 1
    maxiter, 2 indefinite (as :func:`nematic_solids.model.krylov.pcg`'s "ok", "maxiter",
    "indefinite")."""
    # no spin term, so E is a placeholder of E's type
    op = _tangent_operator(K, np.zeros((2, 2, 1, 1)), False, kx, ky, khx, khy, inv_k2, a, pf, pi)
    return krylov.pcg(op, b, x0, w, rtol, maxiter)


@njit(cache=True)
def gmres(
    K, E, b, x0, g0, kx, ky, khx, khy, inv_k2, a, w, pf, pi, rtol, maxiter, V, Z, LZ
):  # pragma: no cover
    """The displacement rate by :func:`nematic_solids.model.compiled.krylov.gmres`,
    right-preconditioned by the Green operator, from ``x0`` whose real-space gradient is ``g0``
    (empty: unknown); returns ``(x, grad x, iterations, converged, operator applications,
    applications from a known gradient)`` with ``grad x`` the real-space gradient (2, 2, N, N) of
    the solution, accumulated from the gradients every operator application computes anyway (no
    transform of its own); the start's residual from ``g0`` needs 4 transforms instead of 8. ``V``
    (restart + 1 spectra), ``Z`` (restart) and ``LZ`` (restart gradients) are caller-owned work
    arrays (:func:`workspace`)."""
    op = _tangent_operator(K, E, True, kx, ky, khx, khy, inv_k2, a, pf, pi)
    return krylov.gmres(op, b, x0, g0, w, rtol, maxiter, V, Z, LZ)


def workspace(n: int, restart: int = 30) -> tuple[Array, Array, Array]:
    """The ``(V, Z, LZ)`` work arrays of :func:`gmres` for an N x N grid."""
    shape = (2, n, n // 2 + 1)
    return (
        np.empty((restart + 1,) + shape, dtype=np.complex128),
        np.empty((restart,) + shape, dtype=np.complex128),
        np.empty((restart, 2, 2, n, n)),
    )
