r"""Finite-strain mechanics in JAX, for one seed (``jax.vmap`` batches it): the force balance
(paper Eq. 3) by Newton-Krylov and the split right-hand side at an integrated stage's
displacement, what :class:`nematic_solids.model.mechanics.FiniteMechanics` and
:class:`nematic_solids.model.split.ForceBalanceSplit` compute (the numpy reference, tested to
agree).

The stress and its derivatives are the reference's own formulas
(:mod:`nematic_solids.model.constitutive`, which takes JAX arrays). With
:math:`F = \bar F + \nabla \tilde u` (:math:`\bar F = \mathrm{diag}(1 + \epsilon, 1 -
\epsilon)`):

* **Force balance** (:func:`force_balance`): Newton on :math:`\hat{\tilde u}`, each correction
  :math:`-\mathrm{Div}(\mathbb K : \nabla \delta u) = \mathrm{Div}\, P` by conjugate gradients
  from zero preconditioned by the Green operator of the isotropic reference medium
  (:math:`\mu_0 = 1`, :math:`\kappa_0 = \kappa`), to the relative tolerance
  :math:`\mathrm{clip}(0.5\, \mathrm{tol}/r, 10^{-8}, 0.1)`, with a backtracking line search
  (at most 12 halvings) that keeps :math:`J > 0` and decreases the residual
  :math:`r = \lVert \hat k_J \hat P_{iJ} \rVert / \max(1, \mathrm{RMS}\, P)`; a start with
  :math:`J \le 0` somewhere restarts from the homogeneous state.
* **A stage's rates** (:func:`finite_split`): at the given displacement and deformation
  gradient, :math:`H = -(A + A_0 + C\, Q:Q - 2 B'(J - 1)) q + B\, \mathrm{dev}\, \bar E + K
  \nabla^2 q` (Eq. 4), :math:`R = H/\gamma`, the displacement rate from
  :math:`-\mathrm{Div}(\mathbb K : \nabla \dot u + E\, \omega(\dot u)) = \mathrm{Div}(\partial_Q
  P : R)`, :math:`E = \partial_Q P : (2 J q)`, by right-preconditioned GMRES warm-started from
  the last rate (its gradient known: the start's residual needs four transforms), then
  :math:`\dot Q = R + 2 \omega J q` and :math:`\tau \dot A = -\zeta A - \chi\, \mathrm{tr}\, P
  - s A^3` (Eq. 5; ``tr S`` with ``coupling = "trS"``), returned as :math:`\hat N_q =
  \widehat{\dot q} - L_q \hat q` and :math:`\dot A`.

The time step that carries the displacement through Krogstad's stages and projects it once
per accepted step is :mod:`nematic_solids.model.accelerated.finite_step`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple, TypeAlias

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .. import constitutive as cl
from .. import reference_kernels
from .. import tensors as T
from ..parameters import Numerics, Parameters
from ..pde import ActiveNematicPDE
from .dtypes import narrow, real_dtype, wide_mean, wide_sum
from .krylov import gmres_aux, pcg
from .linear_rhs import Constant, forward, inverse, weighted_inner

Array: TypeAlias = jax.Array
#: the numpy reference's kernels, which take JAX arrays too (``tensors.namespace``); typed for
#: numpy there, hence untyped here
rk: Any = reference_kernels

#: a force-balance solve's outcome: 0 converged, else the index of its reason tag (as the
#: reference's :class:`nematic_solids.model.errors.SimulationFailure` reasons)
BALANCE_REASONS = ("", "J<=0", "newton_diverged", "ellipticity_lost")
FOLDED, DIVERGED, ELLIPTICITY = 1, 2, 3


class FiniteSymbols(NamedTuple):
    """The run's constant arrays on the half spectrum (N, N // 2 + 1): ``Lq``, ``k2``
    (:math:`|k|^2`), the derivative wave vectors ``kx``, ``ky`` (Nyquist removed), the unit
    wave vectors ``khx``, ``khy``, ``inv_k2`` (:math:`1/|k|^2` on the active modes, else 0),
    the Parseval weights ``weights`` and ``w`` = weights / N^2 (the real-space inner
    product)."""

    Lq: Constant
    k2: Constant
    kx: Constant
    ky: Constant
    khx: Constant
    khy: Constant
    inv_k2: Constant
    weights: Constant
    w: Constant


@dataclass(frozen=True)
class FiniteConstants:
    """The scalars (fixed at trace time under ``jax.jit``): the grid size, the moduli of
    the stress, the constants of Eqs. (4)-(5), the applied shear ``eps``, whether tr S
    drives Eq. (5), the reference medium's ``a`` = kappa / (kappa + 1) of the Green
    preconditioner, and the solves' tolerances and caps (those of
    :class:`nematic_solids.model.mechanics.FiniteMechanics`)."""

    n: int
    kappa: float
    B: float
    Bp: float
    alpha: float
    A0: float
    C: float
    K: float
    gamma: float
    zeta: float
    chi: float
    s: float
    tau: float
    eps: float
    trS: bool
    a: float
    tol: float
    max_newton: int
    cg_rtol: float
    max_cg: int
    spin_tol: float
    restart: int = 30
    #: the name of the seeds' axis under ``jax.vmap`` (None: one seed, unbatched)
    batch_axis: str | None = None
    #: the fields' precision (``Numerics.precision``;
    #: :mod:`nematic_solids.model.accelerated.dtypes`)
    precision: str = "float64"

    @property
    def moduli(self) -> cl.Moduli:
        return cl.Moduli(kappa=self.kappa, B=self.B, B_prime=self.Bp, alpha=self.alpha)


def setup(params: Parameters, numerics: Numerics) -> tuple[FiniteSymbols, FiniteConstants]:
    """The symbols (numpy arrays) and constants of a finite-strain run, from the numpy
    reference's PDE and :class:`nematic_solids.model.mechanics.FiniteMechanics`."""
    eq = ActiveNematicPDE(params, numerics.replace(backend="numpy", mechanics="finite"))
    p, g, mech = eq.params, eq.spectral, eq.mechanics
    m = mech.moduli
    symbols = FiniteSymbols(
        Lq=-(p.A0 + p.K * g.k2) / p.gamma,
        k2=g.k2,
        kx=g.kx,
        ky=g.ky,
        khx=g.khat[0],
        khy=g.khat[1],
        inv_k2=mech._inv_k2,
        weights=g.weights,
        w=g.weights / g.n**2,
    )
    consts = FiniteConstants(
        n=g.n,
        kappa=m.kappa,
        B=m.B,
        Bp=m.B_prime,
        alpha=m.alpha,
        A0=p.A0,
        C=p.C,
        K=p.K,
        gamma=p.gamma,
        zeta=p.zeta,
        chi=p.chi,
        s=p.s,
        tau=p.tau,
        eps=p.eps,
        trS=p.coupling == "trS",
        a=mech._a,  # type: ignore[attr-defined]
        tol=mech.tol,  # type: ignore[attr-defined]
        max_newton=mech.max_newton,  # type: ignore[attr-defined]
        cg_rtol=mech.cg_rtol,  # type: ignore[attr-defined]
        max_cg=mech.max_cg,  # type: ignore[attr-defined]
        spin_tol=mech.spin_tol,
        precision=numerics.precision,
    )
    return symbols, consts


def symbols_on(sym: FiniteSymbols, device: jax.Device, precision: str = "float64") -> FiniteSymbols:
    """The symbols as arrays of the run's ``precision`` (real) on ``device``."""
    dtype = real_dtype(precision)
    return FiniteSymbols(*(jax.device_put(np.asarray(a, dtype=dtype), device) for a in sym))


# --- the displacement's deformation and the force-balance residual -----------------------
def grad_hat(v: Array, sym: FiniteSymbols) -> Array:
    """:math:`\\widehat{\\partial_j v_i} = i k_j \\hat v_i` (the reference's kernel)."""
    return rk.grad_hat_kernel(v, sym.kx, sym.ky)


def div_hat(T_hat: Array, sym: FiniteSymbols) -> Array:
    """:math:`i k_j \\hat T_{ij}` (the reference's kernel)."""
    return rk.div_hat_kernel(T_hat, sym.kx, sym.ky)


def green(r: Array, sym: FiniteSymbols, c: FiniteConstants) -> Array:
    """The reference medium's Green operator (the reference's kernel): the preconditioner of
    both solves."""
    return rk.green_kernel(r, sym.khx, sym.khy, sym.inv_k2, c.a)


def deformation(u_hat: Array, sym: FiniteSymbols, c: FiniteConstants) -> Array:
    """:math:`F = \\bar F + \\nabla \\tilde u` from the displacement spectrum (four
    transforms)."""
    F = inverse(grad_hat(u_hat, sym), c.n)
    return F.at[0, 0].add(1.0 + c.eps).at[1, 1].add(1.0 - c.eps)


def residual(P: Array, P_hat: Array, sym: FiniteSymbols, n: int) -> Array:
    """The force-balance residual :math:`\\lVert \\hat k_J \\hat P_{iJ} \\rVert /
    \\max(1, \\mathrm{RMS}\\, P)` (:meth:`nematic_solids.model.mechanics.Mechanics.residual`),
    accumulated in float64 (a float64 scalar, compared with ``newton_tol``)."""
    r = sym.khx * P_hat[:, 0] + sym.khy * P_hat[:, 1]
    norm = jnp.sqrt(wide_sum(sym.weights * jnp.abs(r) ** 2)) / n**2
    return norm / jnp.maximum(1.0, jnp.sqrt(wide_mean(jnp.sum(P**2, axis=(0, 1)))))


# --- force balance (Eq. 3) -------------------------------------------------------------
class Balance(NamedTuple):
    """A force-balance solve: the displacement spectrum, its deformation gradient and
    stress, the residual, the Newton iterations and CG iterations, the transforms, and the
    outcome (0, or an index of :data:`BALANCE_REASONS`)."""

    u_hat: Array
    F: Array
    P: Array
    residual: Array
    iterations: Array
    cg_iterations: Array
    transforms: Array
    status: Array


def force_balance(
    q: Array, u_hat: Array, F: Array, sym: FiniteSymbols, c: FiniteConstants
) -> Balance:
    """Newton-Krylov for :math:`\\mathrm{Div}\\, P = 0` at the order ``q`` (2, N, N) from the
    displacement spectrum ``u_hat`` (2, N, N // 2 + 1) whose deformation gradient is ``F``
    (module docstring)."""
    n = c.n
    Q = T.nematic(q[0], q[1])
    m = c.moduli
    inner = weighted_inner(sym.w)

    def evaluate(F: Array) -> tuple[Array, Array, Array]:
        """``(P, P hat, residual)``: an infinite residual where J <= 0 somewhere."""
        P = cl.first_piola(F, Q, m)
        P_hat = forward(P)
        folded = ~jnp.all(T.det(F) > 0.0)
        return P, P_hat, jnp.where(folded, jnp.inf, residual(P, P_hat, sym, n))

    P, P_hat, res = evaluate(F)
    # an unusable start (J <= 0): the homogeneous state instead
    bad = ~jnp.isfinite(res)
    u_hat = jnp.where(bad, 0.0, u_hat)
    F = jnp.where(bad, deformation(jnp.zeros_like(u_hat), sym, c), F)
    P, P_hat, res = lax.cond(bad, lambda: evaluate(F), lambda: (P, P_hat, res))
    zero = jnp.int32(0)
    status = jnp.where(jnp.isfinite(res), zero, FOLDED)
    nfft = 4 + jnp.where(bad, 8, 0)

    def going(s):
        return (s[8] == 0) & (s[4] > c.tol)

    def newton(s):
        u_hat, F, P, P_hat, res, it, ncg, nfft, status = s
        K = cl.tangent(F, Q, m)
        b = div_hat(P_hat, sym)
        rtol = jnp.clip(0.5 * c.tol / res, 1e-8, c.cg_rtol)

        def op(v: Array) -> Array:
            dF = inverse(grad_hat(v, sym), n)
            return -div_hat(forward(cl.apply_tangent(K, dF)), sym)

        cg = pcg(op, b, lambda r: green(r, sym, c), inner, rtol=rtol, maxiter=c.max_cg)
        lost = (cg.status != 0) & (cg.iterations < c.max_cg)

        def search(t):
            k, step, *_ = t
            trial = u_hat + narrow(step, cg.x) * cg.x
            F_t = deformation(trial, sym, c)
            P_t, P_hat_t, res_t = evaluate(F_t)
            good = jnp.isfinite(res_t) & (res_t < res)
            return k + 1, jnp.where(good, step, 0.5 * step), trial, F_t, P_t, P_hat_t, res_t, good

        def searching(t):
            return (t[0] < 12) & ~t[7]

        start = (zero, jnp.float64(1.0), u_hat, F, P, P_hat, res, jnp.bool_(False))
        k, _, trial, F_t, P_t, P_hat_t, res_t, good = lax.while_loop(searching, search, start)
        fail = jnp.where(jnp.isfinite(res_t), DIVERGED, FOLDED)
        new_status = jnp.where(
            it >= c.max_newton, DIVERGED, jnp.where(lost, ELLIPTICITY, jnp.where(good, 0, fail))
        )
        move = new_status == 0
        return (
            jnp.where(move, trial, u_hat),
            jnp.where(move, F_t, F),
            jnp.where(move, P_t, P),
            jnp.where(move, P_hat_t, P_hat),
            jnp.where(move, res_t, res),
            it + 1,
            ncg + cg.iterations,
            nfft + 8 * cg.iterations + 8 * k,
            new_status.astype(jnp.int32),
        )

    s = (u_hat, F, P, P_hat, res, zero, zero, jnp.int32(nfft), status.astype(jnp.int32))
    u_hat, F, P, _, res, it, ncg, nfft, status = lax.while_loop(going, newton, s)
    return Balance(u_hat, F, P, res, it, ncg, nfft, status)


# --- a stage's right-hand side -----------------------------------------------------------
class FiniteRate(NamedTuple):
    """One stage's evaluation: ``Nq`` (the spectra of N_q), ``Adot``, the displacement rate
    ``udot_hat`` and its real-space gradient ``udot_grad``, the tangent ``K`` and the spin
    coupling ``E`` (the well-posedness margin's), the rate solve's ``iterations`` and whether
    it ``converged``, ``folded`` (J <= 0 somewhere: the stage fails), and the ``transforms``."""

    Nq: Array
    Adot: Array
    udot_hat: Array
    udot_grad: Array
    K: Array
    E: Array
    iterations: Array
    converged: Array
    folded: Array
    transforms: Array


def finite_split(
    q: Array,
    A: Array,
    q_hat: Array,
    F: Array,
    udot0: Array,
    grad0: Array,
    sym: FiniteSymbols,
    c: FiniteConstants,
    P: Array | None = None,
) -> FiniteRate:
    """The split right-hand side of one seed at the deformation gradient ``F`` (module
    docstring): ``q`` (2, N, N), ``A`` (N, N), ``q_hat`` (2, N, N // 2 + 1), the rate solve
    warm-started from ``udot0`` with gradient ``grad0``; ``P`` the stress at F if known."""
    n = c.n
    q1, q2 = q[0], q[1]
    Q = T.nematic(q1, q2)
    m = c.moduli
    if P is None:
        P = cl.first_piola(F, Q, m)
    Ebar_dev, Jm1, trP = rk.strain_measures_kernel(F, P)
    folded = ~jnp.all(Jm1 > -1.0)
    lap = inverse(-sym.k2 * q_hat, n)
    H = rk.molecular_field_kernel(q1, q2, A, Jm1, Ebar_dev, lap, c.A0, c.C, 2.0 * c.Bp, c.B, c.K)
    R = H / c.gamma
    K = cl.tangent(F, Q, m)
    E = cl.first_piola_q_increment(F, Q, T.nematic(-2.0 * q2, 2.0 * q1), m)
    dP = cl.first_piola_q_increment(F, Q, T.nematic(R[0], R[1]), m)
    b = div_hat(forward(dP), sym)

    def of_gradient(G: Array) -> Array:
        """The rate operator from the real-space gradient of its argument."""
        stress = cl.apply_tangent(K, G) + E * (0.5 * (G[1, 0] - G[0, 1]))
        return -div_hat(forward(stress), sym)

    def op(v: Array) -> tuple[Array, Array]:
        G = inverse(grad_hat(v, sym), n)
        return of_gradient(G), G

    sol = gmres_aux(
        op,
        b,
        (2, 2, n, n),
        weighted_inner(sym.w),
        rtol=c.spin_tol,
        maxiter=c.max_cg,
        restart=c.restart,
        batch_axis=c.batch_axis,
        precondition=lambda r: green(r, sym, c),
        start=(udot0, grad0, b - of_gradient(grad0)),
        aux_dtype=real_dtype(c.precision),
    )
    qdot, _ = rk.corotational_rate(R, sol.Lx, q1, q2)
    tr = cl.second_piola_trace(F, P) if c.trS else trP
    Adot = rk.activity_rate(A, tr, c.zeta, c.chi, c.s, c.tau)
    Nq = forward(qdot) - sym.Lq * q_hat
    # transforms: the Laplacian 2, dP 4, a warm start's residual 4 (none from zero), 8 per
    # operator application, the rate's spectra 2
    warm = jnp.any(udot0 != 0.0)
    nfft = 2 + 4 + jnp.where(warm, 4, 0) + 8 * sol.applications + 2
    return FiniteRate(Nq, Adot, sol.x, sol.Lx, K, E, sol.iterations, sol.converged, folded, nfft)
