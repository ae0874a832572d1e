r"""Krylov solves in JAX for one right-hand side (``jax.vmap`` batches them): restarted GMRES
with an auxiliary linear output, the algorithm of :func:`nematic_solids.model.krylov.gmres_aux`
(Saad, *Iterative Methods for Sparse Linear Systems*, Alg. 9.5, right-preconditioned where a
preconditioner is given, modified Gram-Schmidt, Givens-rotated residual), and preconditioned
conjugate gradients from zero, the algorithm of :func:`nematic_solids.model.krylov.pcg` (Alg.
9.1), step for step.

GMRES's operator returns ``(A v, L v)``; the solution's ``L x`` is accumulated from the basis'
``L v`` (so a converged cycle needs no extra application). The zero start's residual is the
right-hand side itself (no application); a warm start brings its residual (and ``L x0``); a
restart takes the true residual. The stopping rules are the reference's: :math:`|g_{k+1}|
\le \mathrm{rtol}\, \lVert b \rVert` (the rotated residual estimate), ``maxiter``
iterations, or a happy breakdown :math:`h_{k+1,k} \le 10^{-14} \beta`. Right
preconditioning solves :math:`A M y = r` and updates :math:`x \mathrel{+}= M (\sum_i y_i
v_i)`, one application of the linear M per cycle instead of keeping every :math:`M v_i`
(the same sum, in another order of rounding). Loops are ``lax.while_loop``; the sizes are
fixed by ``restart`` (the Krylov basis is a ``(restart + 1, ...)`` array, the unused rows
masked).

**Precision**: the basis, the iterates and the operator's fields are in the precision of the
right-hand side (float32 or float64); ``inner`` accumulates in float64
(:func:`nematic_solids.model.accelerated.linear_rhs.weighted_inner`), and the Hessenberg
matrix, the rotations and the residual estimate stay float64, so the stopping tests compare
float64 numbers; a coefficient is narrowed to the fields' precision where it scales a field
(:func:`nematic_solids.model.accelerated.dtypes.narrow`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, TypeAlias

import jax
import jax.numpy as jnp
from jax import lax

from .dtypes import narrow

Array: TypeAlias = jax.Array
Operator = Callable[[Array], tuple[Array, Array]]
Inner = Callable[[Array, Array], Array]
Preconditioner = Callable[[Array], Array]


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
    ``H[k + 1, k]``, rotating ``g`` (:func:`nematic_solids.model.krylov.givens_column`)."""

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
    batch_axis: str | None = None,
    precondition: Preconditioner | None = None,
    start: tuple[Array, Array, Array] | None = None,
    aux_dtype: jnp.dtype | None = None,
) -> Solution:
    """Solve ``A x = b`` (module docstring) from ``x = 0``, or from ``start = (x0, L x0,
    b - A x0)``; ``aux_shape`` is the shape of ``L v``, of ``aux_dtype`` (default: ``b``'s);
    ``precondition`` the right preconditioner M (linear). Under ``jax.vmap(...,
    axis_name=batch_axis)`` the Arnoldi loop runs while any seed of the batch iterates (its
    condition is then the same for all seeds, so vmap adds no select of the whole Krylov
    basis per iteration; the seeds that have stopped are masked here)."""

    def anyone(flag: Array) -> Array:
        if batch_axis is None:
            return flag
        return lax.psum(flag.astype(jnp.int32), batch_axis) > 0

    cdtype = b.dtype
    adtype = cdtype if aux_dtype is None else aux_dtype

    def M(v: Array) -> Array:
        return v if precondition is None else precondition(v)

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
        V = jnp.zeros((restart + 1,) + b.shape, cdtype).at[0].set(r / narrow(safe_beta, r))
        LZ = jnp.zeros((restart,) + aux_shape, adtype)
        H = jnp.zeros((restart + 1, restart))
        g = jnp.zeros(restart + 1).at[0].set(beta)
        cs = jnp.zeros(restart)
        sn = jnp.zeros(restart)

        def more(c):
            return anyone(~c[-1])

        def arnoldi(c):
            k, V, LZ, H, g, cs, sn, total, h_next, end = c
            active = ~end  # (a seed that has ended repeats its last column, masked below)
            w, Lz = op(M(V[k]))
            LZ = LZ.at[k].set(Lz)  # an ended seed writes the same values again

            def gram_schmidt(i, wH):  # modified Gram-Schmidt against V[0..k]
                w, H = wH
                hik = inner(V[i], w)
                return w - narrow(hik, w) * V[i], H.at[i, k].set(hik)

            w, Hn = lax.fori_loop(0, k + 1, gram_schmidt, (w, H))
            hn = jnp.sqrt(jnp.maximum(inner(w, w), 0.0))
            Hn = Hn.at[k + 1, k].set(hn)
            Hn, gn, csn, snn = _givens(Hn, g, cs, sn, k)
            total = total + active.astype(total.dtype)
            stop = (jnp.abs(gn[k + 1]) <= tol) | (total >= maxiter) | (hn <= 1e-14 * beta)
            # V[k + 1] is read only after a step that did not stop: written unconditionally,
            # so the basis is never copied (a select of the whole basis per iteration)
            V = V.at[k + 1].set(w / narrow(jnp.where(hn > 0.0, hn, 1.0), w))
            ends = active & (stop | (k == restart - 1))
            return (
                jnp.where(active & ~ends, k + 1, k),
                V,
                LZ,
                jnp.where(active, Hn, H),
                jnp.where(active, gn, g),
                jnp.where(active, csn, cs),
                jnp.where(active, snn, sn),
                total,
                jnp.where(active, hn, h_next),
                end | ends,
            )

        start = (jnp.int32(0), V, LZ, H, g, cs, sn, total, jnp.float64(0.0), met | spent)
        k, V, LZ, H, g, cs, sn, total, h_next, _ = lax.while_loop(more, arnoldi, start)
        m = k + 1
        y = _back_substitution(H, g, m)
        skip = met | spent
        x = jnp.where(skip, x, x + M(jnp.tensordot(y.astype(cdtype), V[:restart], axes=1)))
        Lx = jnp.where(skip, Lx, Lx + jnp.tensordot(y.astype(adtype), LZ, axes=1))
        converged = jnp.where(skip, met, (jnp.abs(g[m]) <= tol) | (h_next <= 1e-14 * beta))
        done = converged | spent  # out of budget: one more true residual decides, as there
        return x, Lx, total, done, converged

    if start is None:
        x0, Lx0, r0 = jnp.zeros_like(b), jnp.zeros(aux_shape, adtype), b
    else:
        x0, Lx0, r0 = start
    x, Lx, total, done, converged = cycle(x0, Lx0, r0, jnp.int32(0))

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


class CGSolution(NamedTuple):
    """A conjugate-gradient solve: ``x``, the iterations, and its outcome (0 converged,
    :data:`INDEFINITE`, :data:`MAXITER`)."""

    x: Array
    iterations: Array
    status: Array


#: :class:`CGSolution` outcomes besides 0 (converged)
INDEFINITE, MAXITER = 1, 2


def pcg(
    op: Callable[[Array], Array],
    b: Array,
    precondition: Preconditioner,
    inner: Inner,
    *,
    rtol: Array | float,
    maxiter: int,
) -> CGSolution:
    r"""Preconditioned conjugate gradients from ``x = 0`` for a symmetric positive definite
    ``op`` (:func:`nematic_solids.model.krylov.pcg`): stops when the preconditioned residual
    norm :math:`\sqrt{r \cdot M r}` is at most ``rtol`` times that of ``b``, after
    ``maxiter`` iterations, or at a direction of non-positive curvature (the operator is
    not positive definite: :data:`INDEFINITE`)."""
    z = precondition(b)
    rz = inner(b, z)
    ref0 = jnp.sqrt(jnp.abs(rz))
    ref = jnp.where(ref0 == 0.0, 1.0, ref0)

    def going(c):
        _, _, _, rz, it, status = c
        return (status < 0) & ~(jnp.sqrt(jnp.abs(rz)) <= rtol * ref)

    def iterate(c):
        x, r, p, rz, it, status = c
        at_cap = it >= maxiter
        Ap = op(p)
        pAp = inner(p, Ap)
        indefinite = ~at_cap & (pAp <= 0.0)
        step = rz / jnp.where(pAp == 0.0, 1.0, pAp)
        x_new = x + narrow(step, p) * p
        r_new = r - narrow(step, Ap) * Ap
        z = precondition(r_new)
        rz_new = inner(r_new, z)
        p_new = z + narrow(rz_new / jnp.where(rz == 0.0, 1.0, rz), p) * p
        move = ~at_cap & ~indefinite
        status = jnp.where(at_cap, MAXITER, jnp.where(indefinite, INDEFINITE, status))
        return (
            jnp.where(move, x_new, x),
            jnp.where(move, r_new, r),
            jnp.where(move, p_new, p),
            jnp.where(move, rz_new, rz),
            jnp.where(move, it + 1, it),
            status,
        )

    start = (jnp.zeros_like(b), b, z, rz, jnp.int32(0), jnp.int32(-1))
    x, _, _, rz, it, status = lax.while_loop(going, iterate, start)
    return CGSolution(x, it, jnp.where(status < 0, 0, status))
