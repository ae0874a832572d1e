r"""Restarted GMRES in JAX for one right-hand side (``jax.vmap`` batches it), with an
auxiliary linear output: the algorithm of :func:`model.krylov.gmres_aux` started from zero
(Saad, *Iterative Methods for Sparse Linear Systems*, Alg. 9.5 without a preconditioner,
modified Gram-Schmidt, Givens-rotated residual), step for step.

The operator returns ``(A v, L v)``; the solution's ``L x`` is accumulated from the basis'
``L v`` (so a converged cycle needs no extra application). The zero start's residual is the
right-hand side itself (no application); a restart takes the true residual. The stopping
rules are the reference's: :math:`|g_{k+1}| \le \mathrm{rtol}\, \lVert b \rVert` (the
rotated residual estimate), ``maxiter`` iterations, or a happy breakdown
:math:`h_{k+1,k} \le 10^{-14} \beta`. Loops are ``lax.while_loop``; the sizes are fixed by
``restart`` (the Krylov basis is a ``(restart + 1, ...)`` array, the unused rows masked).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

Array = jax.Array
Operator = Callable[[Array], tuple[Array, Array]]
Inner = Callable[[Array, Array], Array]


class Solution(NamedTuple):
    """A GMRES solve: ``x``, ``L x``, the iterations, whether it converged, and the operator
    applications (iterations plus the restarts' true residuals)."""

    x: Array
    Lx: Array
    iterations: Array
    converged: Array
    applications: Array


def _givens(H: Array, g: Array, cs: Array, sn: Array, k: Array):
    """Apply the rotations 0..k-1 to column ``k`` of ``H``, then the k-th one that zeroes
    ``H[k + 1, k]``, rotating ``g`` (:func:`model.krylov.givens_column`)."""

    def rotate(i, H):
        t = cs[i] * H[i, k] + sn[i] * H[i + 1, k]
        H = H.at[i + 1, k].set(-sn[i] * H[i, k] + cs[i] * H[i + 1, k])
        return H.at[i, k].set(t)

    H = lax.fori_loop(0, k, rotate, H)
    denom = jnp.hypot(H[k, k], H[k + 1, k])
    denom = jnp.where(denom == 0.0, 1e-300, denom)
    cs = cs.at[k].set(H[k, k] / denom)
    sn = sn.at[k].set(H[k + 1, k] / denom)
    H = H.at[k, k].set(denom).at[k + 1, k].set(0.0)
    g = g.at[k + 1].set(-sn[k] * g[k])
    g = g.at[k].set(cs[k] * g[k])
    return H, g, cs, sn


def _back_substitution(H: Array, g: Array, m: Array) -> Array:
    """``y`` with ``triu(H[:m, :m]) y = g[:m]``, zero beyond ``m`` (``m`` traced)."""
    n = H.shape[1]

    def row(j, y):
        i = n - 1 - j
        diag = jnp.where(i < m, H[i, i], 1.0)
        value = (g[i] - jnp.dot(H[i, :n], y)) / diag  # y[j] = 0 for j <= i so far
        return y.at[i].set(jnp.where(i < m, value, 0.0))

    return lax.fori_loop(0, n, row, jnp.zeros(n, dtype=g.dtype))


def gmres_aux(
    op: Operator,
    b: Array,
    aux_shape: tuple[int, ...],
    inner: Inner,
    *,
    rtol: float,
    maxiter: int,
    restart: int = 30,
) -> Solution:
    """Solve ``A x = b`` from ``x = 0`` (module docstring); ``aux_shape`` is the shape of
    ``L v`` (complex)."""
    cdtype = b.dtype
    bnorm0 = jnp.sqrt(inner(b, b))
    bnorm = jnp.where(bnorm0 == 0.0, 1.0, bnorm0)
    tol = rtol * bnorm

    def cycle(x, Lx, r, total):
        """One Arnoldi cycle from the residual ``r`` of ``x`` (skipped where ``r`` already
        meets the tolerance or the budget is spent); returns ``(x, Lx, total, done,
        converged)``."""
        beta = jnp.sqrt(inner(r, r))
        met = beta <= tol
        spent = total >= maxiter
        safe_beta = jnp.where(beta > 0.0, beta, 1.0)
        V = jnp.zeros((restart + 1,) + b.shape, cdtype).at[0].set(r / safe_beta)
        LZ = jnp.zeros((restart,) + aux_shape, cdtype)
        H = jnp.zeros((restart + 1, restart))
        g = jnp.zeros(restart + 1).at[0].set(beta)
        cs = jnp.zeros(restart)
        sn = jnp.zeros(restart)

        def more(c):
            return ~c[-1]

        def arnoldi(c):
            k, V, LZ, H, g, cs, sn, total, h_next, _ = c
            w, Lz = op(V[k])
            LZ = LZ.at[k].set(Lz)

            def gram_schmidt(i, wH):  # modified Gram-Schmidt against V[0..k]
                w, H = wH
                hik = inner(V[i], w)
                return w - hik * V[i], H.at[i, k].set(hik)

            w, H = lax.fori_loop(0, k + 1, gram_schmidt, (w, H))
            h_next = jnp.sqrt(jnp.maximum(inner(w, w), 0.0))
            H = H.at[k + 1, k].set(h_next)
            H, g, cs, sn = _givens(H, g, cs, sn, k)
            total = total + 1
            stop = (jnp.abs(g[k + 1]) <= tol) | (total >= maxiter) | (h_next <= 1e-14 * beta)
            safe_h = jnp.where(h_next > 0.0, h_next, 1.0)
            V = jnp.where(stop, V, V.at[k + 1].set(w / safe_h))
            end = stop | (k == restart - 1)
            return (jnp.where(end, k, k + 1), V, LZ, H, g, cs, sn, total, h_next, end)

        start = (jnp.int32(0), V, LZ, H, g, cs, sn, total, jnp.float64(0.0), met | spent)
        k, V, LZ, H, g, cs, sn, total, h_next, _ = lax.while_loop(more, arnoldi, start)
        m = k + 1
        y = _back_substitution(H, g, m).astype(cdtype)
        skip = met | spent
        x = jnp.where(skip, x, x + jnp.tensordot(y, V[:restart], axes=1))
        Lx = jnp.where(skip, Lx, Lx + jnp.tensordot(y, LZ, axes=1))
        converged = jnp.where(skip, met, (jnp.abs(g[m]) <= tol) | (h_next <= 1e-14 * beta))
        done = converged | spent  # out of budget: one more true residual decides, as there
        return x, Lx, total, done, converged

    x0 = jnp.zeros_like(b)
    Lx0 = jnp.zeros(aux_shape, cdtype)
    x, Lx, total, done, converged = cycle(x0, Lx0, b, jnp.int32(0))

    def restarting(c):
        return ~c[3]

    def restart_cycle(c):
        x, Lx, total, _, _, nop = c
        Ax, Lx = op(x)  # the true residual (and L x of the current iterate)
        x, Lx, total, done, converged = cycle(x, Lx, b - Ax, total)
        return x, Lx, total, done, converged, nop + 1

    x, Lx, total, _, converged, restarts = lax.while_loop(
        restarting, restart_cycle, (x, Lx, total, done, converged, jnp.int32(0))
    )
    return Solution(x, Lx, total, converged, total + restarts)
