r"""Krogstad's ETDRK4 step of finite strain in JAX, for one seed (``jax.vmap`` batches it), with
the displacement integrated with the state and projected onto force balance once per accepted
step: the scheme of :meth:`nematic_solids.model.solver.ETDRK4Solver.step` and
:meth:`nematic_solids.model.solver_base.ETDSolver._project` (docs/model/numerics.md), on the
stage right-hand side and the Newton solve of :mod:`nematic_solids.model.accelerated.finite`.

With the fields' stages of :mod:`nematic_solids.model.accelerated.etdrk4`, the displacement
:math:`d` (L = 0: the weights become the classical RK4's) and its deformation gradient
:math:`F = \bar F + \nabla d` are carried through the stages from the rates :math:`V_s` and
their real-space gradients :math:`G_s` that the stages' rate solves return (each warm-started
from the last):

.. math::
    d_a = d + \tfrac h2 V_u, \quad d_b = d + \tfrac h2 V_a, \quad d_c = d + h V_b, \qquad
    d_{n+1} = d + \tfrac h6 (V_u + 2 V_a + 2 V_b + V_c),

F alike with the G; the step's error counts the strain's, :math:`\tfrac h3 (G_b - G_a)`, each
component like a field. The start's well-posedness margin is the sampled minimum over the grid
and 48 directions of :math:`\det M / (\kappa + 1)`, :math:`M_{ik} = \mathbb K_{iJkL} \hat k_J
\hat k_L + \tfrac12 (E \hat k)_i \hat t_k`, refined by a parabola through the smallest sample
and its neighbours (:func:`nematic_solids.model.wellposedness.finite_margin`). An accepted
step's displacement is put back onto force balance by Newton from it
(:func:`nematic_solids.model.accelerated.finite.force_balance`); if that fails the step is
retried with h/4 (the step control of :func:`nematic_solids.model.accelerated.etdrk4.advance`).
A rejected or failed step keeps the rate of its start's stage as the next warm start, as the
reference's checkpoint does.
"""

from __future__ import annotations

from typing import NamedTuple, TypeAlias

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .. import constitutive as cl
from .. import tensors as T
from ..wellposedness import N_ANGLES
from . import finite as balance
from .dtypes import complex_dtype, narrow, real_dtype, wide_mean, wide_sum
from .etdrk4 import (
    ELLIPTICITY,
    FOLDED,
    NAN,
    NEWTON,
    SPIN,
    SeedState,
    Step,
    initial_state,
    krogstad_stages,
    krogstad_weights,
)
from .finite import FiniteConstants, FiniteSymbols, deformation, finite_split, force_balance
from .linear_rhs import inverse

Array: TypeAlias = jax.Array


#: what a finite-strain state saves of the mechanics (the keys of
#: :meth:`nematic_solids.model.mechanics.FiniteMechanics.saved_state`, fields of
#: :class:`Mechanics`)
SAVED = ("u_hat", "udot_hat", "udot_grad")


class Mechanics(NamedTuple):
    """What a finite-strain seed carries between steps: the displacement spectrum in force
    balance, its deformation gradient and stress, the displacement rate and its real-space
    gradient (the next rate solve's warm start), and the Newton and CG iterations so far."""

    u_hat: Array
    F: Array
    P: Array
    udot_hat: Array
    udot_grad: Array
    newton: Array
    cg_iterations: Array


def initial_mechanics(
    q: Array, sym: FiniteSymbols, c: FiniteConstants
) -> tuple[Mechanics, Array, Array]:
    """The force balance at the order ``q`` from the homogeneous state, as the reference's
    first save solves it: ``(mechanics, outcome, transforms)`` (outcome 0, or an index of
    :data:`nematic_solids.model.accelerated.etdrk4.REASONS`)."""
    zero = jnp.zeros((2, c.n, c.n // 2 + 1), complex_dtype(c.precision))
    bal = force_balance(q, zero, deformation(zero, sym, c), sym, c)
    mech = Mechanics(
        bal.u_hat,
        bal.F,
        bal.P,
        zero,
        jnp.zeros((2, 2, c.n, c.n), real_dtype(c.precision)),
        jnp.int32(0),  # (the steps' Newton iterations, as the reference's solver counts)
        bal.cg_iterations,
    )
    return mech, _balance_reason(bal.status), bal.transforms + 4


def _balance_reason(status: Array) -> Array:
    """A force-balance outcome as a seed's reason code."""
    return jnp.select(
        [
            status == balance.FOLDED,
            status == balance.DIVERGED,
            status == balance.ELLIPTICITY,
        ],
        [FOLDED, NEWTON, ELLIPTICITY],
        0,
    ).astype(jnp.int32)


def finite_margin(K: Array, E: Array, kappa: float) -> Array:
    r"""The well-posedness margin of the rate problem (module docstring;
    :func:`nematic_solids.model.wellposedness.finite_margin`). With :math:`\hat k = (\cos
    \phi, \sin \phi)` the symbol is :math:`M = K_{i0k0} c^2 + (K_{i0k1} + K_{i1k0}) c s +
    K_{i1k1} s^2 + \tfrac12 (E_{i0} c + E_{i1} s) \hat t_k`: three 2 x 2 fields and two
    vectors per point, evaluated at every sampled angle."""
    angles = np.arange(N_ANGLES) * (np.pi / N_ANGLES)
    K0, K1, K2 = K[:, 0, :, 0], K[:, 0, :, 1] + K[:, 1, :, 0], K[:, 1, :, 1]
    E0, E1 = E[:, 0], E[:, 1]

    def det_at(phi: Array, K0: Array, K1: Array, K2: Array, E0: Array, E1: Array) -> Array:
        """det M / (kappa + 1) at the angles ``phi`` (a leading axis) and every point."""
        c = jnp.cos(phi).reshape(phi.shape + (1,) * (K0.ndim - 2))
        s = jnp.sin(phi).reshape(c.shape)
        t = (-s, c)
        Ek = [0.5 * (E0[i] * c + E1[i] * s) for i in range(2)]

        def M(i: int, k: int) -> Array:
            return K0[i, k] * (c * c) + K1[i, k] * (c * s) + K2[i, k] * (s * s) + Ek[i] * t[k]

        return (M(0, 0) * M(1, 1) - M(0, 1) * M(1, 0)) / (kappa + 1.0)

    D = det_at(jnp.asarray(angles, K.dtype), K0, K1, K2, E0, E1)  # (angle, x, y)
    flat = jnp.argmin(D)
    ia, x, y = jnp.unravel_index(flat, D.shape)
    m = D[ia, x, y]
    dphi = np.pi / N_ANGLES
    phis = jnp.asarray(angles, K.dtype)[ia] + dphi * jnp.array([-1.0, 0.0, 1.0], K.dtype)
    d = det_at(phis, *(a[..., x, y] for a in (K0, K1, K2, E0, E1)))
    curv = d[0] - 2.0 * d[1] + d[2]
    refined = d[1] - 0.125 * (d[2] - d[0]) ** 2 / jnp.where(curv > 0, curv, 1.0)
    return jnp.where(curv > 0, jnp.minimum(m, refined), m)


def finite_step(
    s: SeedState, h: Array, sym: FiniteSymbols, c: FiniteConstants, error_norm: str
) -> Step:
    """One Krogstad ETDRK4 step of size ``h`` of finite strain from the seed's state, with
    its displacement carried through the stages and projected (module docstring). ``h`` and
    the error are float64, the rest in the fields' precision."""
    n = c.n
    q, q_hat, A, m = s.q, s.q_hat, s.A, s.mech
    h = narrow(h, q)  # the step in the fields' precision
    dtype = q.dtype
    Lq = jnp.asarray(sym.Lq)
    wq = krogstad_weights(Lq * h)
    Eq, nq_u, nq_ab, nq_c = wq[0], wq[7], wq[8], wq[9]
    LA = -(c.zeta + 3.0 * c.s * A * A) / c.tau
    wA = krogstad_weights(LA * h)
    EA, nA_u, nA_ab, nA_c = wA[0], wA[7], wA[8], wA[9]
    offsets = jnp.stack([0.0 * h, 0.5 * h, 0.5 * h, h])
    rk4 = jnp.array([1.0, 2.0, 2.0, 1.0], dtype)  # the classical RK4 weights of the displacement
    errw = jnp.array([0.0, -1.0, 1.0, 0.0], dtype)  # G_b - G_a
    stages = krogstad_stages(q, q_hat, A, h, wq, wA, n)

    def evaluate(i, carry):
        Nq, NA, V, G, accV, accG, errG, V0, G0, K0, E0, codes, its, nfft = carry
        q_s, qh_s, A_s = lax.switch(i, stages, Nq, NA)
        F_s = m.F + offsets[i] * G  # F at the stage (at the start: the solution's)
        r = finite_split(q_s, A_s, qh_s, F_s, V, G, sym, c)
        finite = jnp.all(jnp.isfinite(r.Nq)) & jnp.all(jnp.isfinite(r.Adot))
        code = jnp.where(r.folded, FOLDED, jnp.where(~r.converged, SPIN, jnp.where(finite, 0, NAN)))
        first = i == 0
        return (
            Nq.at[i].set(r.Nq),
            NA.at[i].set(r.Adot - LA * A_s),
            r.udot_hat,
            r.udot_grad,
            accV + rk4[i] * r.udot_hat,
            accG + rk4[i] * r.udot_grad,
            errG + errw[i] * r.udot_grad,
            jnp.where(first, r.udot_hat, V0),
            jnp.where(first, r.udot_grad, G0),
            jnp.where(first, r.K, K0),
            jnp.where(first, r.E, E0),
            codes.at[i].set(code.astype(jnp.int32)),
            its + r.iterations,
            nfft + r.transforms + jnp.where(first, 0, 2),  # a stage's q: 2 inverse transforms
        )

    zero = jnp.int32(0)
    shape_g = (2, 2, n, n)
    start = (
        jnp.zeros((4,) + q_hat.shape, q_hat.dtype),
        jnp.zeros((4,) + A.shape, A.dtype),
        m.udot_hat,
        m.udot_grad,
        jnp.zeros_like(m.udot_hat),
        jnp.zeros(shape_g, dtype),
        jnp.zeros(shape_g, dtype),
        m.udot_hat,
        m.udot_grad,
        jnp.zeros((2, 2, 2, 2, n, n), dtype),
        jnp.zeros(shape_g, dtype),
        jnp.zeros(4, jnp.int32),
        zero,
        zero,
    )
    Nq, NA, V3, G3, accV, accG, errG, V0, G0, K0, E0, codes, its, nfft = lax.fori_loop(
        0, 4, evaluate, start
    )
    # the displacement stages use the rate of the stage before: d_s = d + offset_s V_(s-1),
    # which the loop's F_s follows; the displacement itself is only needed at the end
    new_q_hat = Eq * q_hat + h * (nq_u * Nq[0] + nq_ab * Nq[1] + nq_ab * Nq[2] + nq_c * Nq[3])
    new_A = EA * A + h * (nA_u * NA[0] + nA_ab * NA[1] + nA_ab * NA[2] + nA_c * NA[3])
    new_q = inverse(new_q_hat, n)
    new_d = m.u_hat + (h / 6.0) * accV
    new_F = m.F + (h / 6.0) * accG
    err_q = h * nq_ab * (Nq[2] - Nq[1])
    err_A = h * nA_ab * (NA[2] - NA[1])
    err_G = (h / 3.0) * errG
    nfft = nfft + 2
    if error_norm == "max":
        error = jnp.maximum(jnp.max(jnp.abs(inverse(err_q, n))), jnp.max(jnp.abs(err_A)))
        error = jnp.maximum(error, jnp.max(jnp.abs(err_G)))
        nfft = nfft + 2
    else:  # RMS over the grid, the spectra's by Parseval (model.fourier.rms_hat)
        rms = [jnp.sqrt(wide_sum(sym.weights * jnp.abs(e) ** 2)) / n**2 for e in err_q]
        error = jnp.maximum(jnp.maximum(rms[0], rms[1]), jnp.sqrt(wide_mean(err_A**2)))
        error = jnp.maximum(error, jnp.max(jnp.sqrt(wide_mean(err_G**2, axis=(2, 3)))))
    error = error.astype(jnp.float64)
    first_ok = codes[0] == 0
    finite_new = jnp.all(jnp.isfinite(new_q)) & jnp.all(jnp.isfinite(new_A))
    later = jnp.where(codes[1] != 0, codes[1], jnp.where(codes[2] != 0, codes[2], codes[3]))
    stages_ok = (later == 0) & finite_new
    reason = jnp.where(~first_ok, codes[0], jnp.where(later != 0, later, NAN))
    margin = finite_margin(K0, E0, c.kappa)
    # the projection of the new displacement onto force balance (Newton from it)
    bal = force_balance(new_q, new_d, new_F, sym, c)
    accepted = Mechanics(
        bal.u_hat,
        bal.F,
        bal.P,
        V3,
        G3,
        m.newton + bal.iterations,
        m.cg_iterations + bal.cg_iterations,
    )
    # not accepted: the start's displacement, with its stage's rate as the next warm start
    # (where that stage succeeded: the reference's checkpoint)
    kept = m._replace(
        udot_hat=jnp.where(first_ok, V0, m.udot_hat), udot_grad=jnp.where(first_ok, G0, m.udot_grad)
    )
    return Step(
        new_q,
        new_q_hat,
        new_A,
        error,
        first_ok,
        stages_ok,
        (codes[1] != SPIN) & (codes[2] != SPIN) & (codes[3] != SPIN),
        margin,
        its,
        nfft + bal.transforms,
        reason=reason.astype(jnp.int32),
        mech=accepted,
        kept=kept,
        projected=bal.status == 0,
        projection_reason=_balance_reason(bal.status),
    )


def initial_finite_state(
    q: Array, A: Array, sym: FiniteSymbols, c: FiniteConstants, *, dt: float
) -> SeedState:
    """The state at t = 0 of fields ``q`` (2, N, N), ``A`` with first step ``dt`` and the
    force balance at ``q`` (:func:`initial_mechanics`): a seed whose balance fails there has
    failed at t = 0."""
    mech, code, nfft = initial_mechanics(q, sym, c)
    s = initial_state(q, A, dt=dt)
    return s._replace(
        status=code,
        # (float64 arrays, not Python scalars: a weakly typed leaf would make the second
        # advance compile again)
        t_failed=jnp.where(code != 0, jnp.float64(0.0), jnp.float64(jnp.nan)),
        transforms=s.transforms + nfft,
        mech=mech,
    )


def resumed_mechanics(
    u_hat: Array,
    udot_hat: Array,
    udot_grad: Array,
    q: Array,
    sym: FiniteSymbols,
    c: FiniteConstants,
) -> Mechanics:
    """The mechanics of a continued seed from what its state saved (the displacement in
    force balance, its rate and the rate's gradient: as
    :meth:`nematic_solids.model.mechanics.FiniteMechanics.resume`, F and P evaluated anew)."""
    F = deformation(u_hat, sym, c)
    P = cl.first_piola(F, T.nematic(q[0], q[1]), c.moduli)
    zero = jnp.int32(0)
    return Mechanics(u_hat, F, P, udot_hat, udot_grad, zero, zero)


def save_margin(q: Array, mech: Mechanics, c: FiniteConstants) -> Array:
    """The well-posedness margin at a save, at the state's force balance (the reference's
    :meth:`nematic_solids.model.mechanics.FiniteMechanics.rate_margin` after the save's
    solve: the tangent and E at its deformation)."""
    Q = T.nematic(q[0], q[1])
    K = cl.tangent(mech.F, Q, c.moduli)
    E = cl.first_piola_q_increment(mech.F, Q, T.nematic(-2.0 * q[1], 2.0 * q[0]), c.moduli)
    return finite_margin(K, E, c.kappa)
