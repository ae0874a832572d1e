r"""Krogstad's ETDRK4 with its embedded error estimate and the adaptive step control of
:mod:`nematic_solids.model.solver` / :mod:`nematic_solids.model.solver_base`, in JAX, for one seed
(``jax.vmap`` runs the seeds of a batch side by side, each with its own step size).

The stiff linear parts are :math:`L_q = -(A_0 + K k^2)/\gamma` (Fourier space) and the
activity's frozen pointwise Jacobian :math:`L_A = -(\zeta + 3 s A_n^2)/\tau` (real space);
with :math:`\varphi_k = \varphi_k(hL)`, :math:`\tilde\varphi_k = \varphi_k(hL/2)`
(Krogstad 2005, J. Comput. Phys. 203, 72):

.. math::
    a &= e^{Lh/2} u_n + \tfrac h2 \tilde\varphi_1 N_u, \qquad
    b = a + h \tilde\varphi_2 (N_a - N_u), \qquad
    c = e^{Lh} u_n + h \varphi_1 N_u + 2 h \varphi_2 (N_b - N_u), \\
    u_{n+1} &= e^{Lh} u_n + h\big[(\varphi_1 - 3\varphi_2 + 4\varphi_3) N_u
      + (2\varphi_2 - 4\varphi_3)(N_a + N_b) + (4\varphi_3 - \varphi_2) N_c\big],

error estimate :math:`e = h (2\varphi_2 - 4\varphi_3)(N_b - N_a) = O(h^3)`, the largest
pointwise error (``error_norm = "max"``) or the RMS (``"rms"``), maximum over q1, q2, A.

**Step control**, as :meth:`nematic_solids.model.solver_base.ETDSolver.make_stepper`: accept if the
error is at most ``tolerance``; the factor :math:`0.9 (\mathrm{tol}/e)^{1/3}` clipped to [0.2, 2] (2
for e = 0); a rejected step is retried with at most half its size, below ``dt_min`` = 1e-7 the seed
fails (``step_size_collapsed``); after an accepted step the next is the step times the factor, at
most ``dt_max`` (or, after a step shortened to land on the save time, the larger or smaller of the
old step and the scaled one); every proposal is rounded down onto the ladder
:math:`\mathrm{dt_{max}}\, 2^{-j/8}`. A step whose stage fails (a spin solve that does not converge,
a non-finite state) is retried with h/4, and fails the seed at ``h <= 1e-3 dt_max``; a start whose
well-posedness margin :math:`1 - \max (\alpha - B) S` is <= 0 fails it at once
(``rate_problem_ill_posed``). A failed seed stops where it failed; the others go on.

**Precision** (:mod:`nematic_solids.model.accelerated.dtypes`): the stages, the weights
(:math:`\varphi_k(hL)` evaluated in the fields' precision) and the error estimate's fields are in
the fields' precision; the time, the step size, the error norm (the RMS accumulated in float64)
and the step factor are float64.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, TypeAlias

import jax
import jax.numpy as jnp
from jax import lax

from ..reference_kernels import krogstad_from_phi
from .dtypes import narrow, wide_mean, wide_sum
from .linear_rhs import Constants, Symbols, forward, inverse, linear_split

Array: TypeAlias = jax.Array

#: a seed's status: 0 running or done, else the index of its failure's reason tag (the
#: last three: finite strain's, :mod:`nematic_solids.model.accelerated.finite_step`)
REASONS = (
    "",
    "spin_diverged",
    "nan",
    "rate_problem_ill_posed",
    "step_size_collapsed",
    "J<=0",
    "newton_diverged",
    "ellipticity_lost",
)
SPIN, NAN, ILL_POSED, COLLAPSED, FOLDED, NEWTON, ELLIPTICITY = 1, 2, 3, 4, 5, 6, 7


@dataclass(frozen=True)
class Control:
    """The step control's settings (:class:`nematic_solids.model.parameters.Numerics`, and the
    constants of :class:`nematic_solids.model.solver_base.ETDSolver`)."""

    tolerance: float
    dt_max: float
    adaptive: bool = True
    error_norm: str = "max"
    error_order: int = 3
    dt_min: float = 1e-7
    retry_floor: float = 1e-3


class SeedState(NamedTuple):
    """One seed's state between steps: the fields (q in real space and as spectra, A), the
    time, the next step size, the status
    (:data:`~nematic_solids.model.accelerated.etdrk4.REASONS`), the time of a failure, the
    smallest well-posedness margin, and the work counted."""

    q: Array
    q_hat: Array
    A: Array
    t: Array
    h: Array
    status: Array
    t_failed: Array
    margin_min: Array
    steps: Array
    rejected: Array
    stage_failures: Array
    rhs: Array
    spin_iterations: Array
    transforms: Array
    #: the mechanics carried between steps (finite strain's
    #: :class:`nematic_solids.model.accelerated.finite_step.Mechanics`; none in small strain)
    mech: Any = ()


def initial_state(q: Array, A: Array, *, dt: float) -> SeedState:
    """The state at t = 0 of fields ``q`` (2, N, N), ``A`` with first step ``dt`` (the
    spectra of q transformed once: two transforms counted)."""
    i = jnp.int32(0)
    f = jnp.float64
    return SeedState(
        q, forward(q), A, f(0.0), f(dt), i, f(jnp.nan), f(jnp.inf), i, i, i, i, i, jnp.int32(2)
    )


def phi_functions(z: Array, kmax: int) -> tuple[Array, ...]:
    """:math:`e^z, \\varphi_1(z), \\ldots, \\varphi_{k_{max}}(z)` (real ``z``),
    :math:`\\varphi_k(z) = \\sum_j z^j/(j + k)!`: the Taylor series (20 terms, by Horner's
    rule in one loop) for ``|z| < 1``, the recursion :math:`\\varphi_{k+1} = (\\varphi_k -
    1/k!)/z` otherwise (the branches of
    :func:`nematic_solids.model.reference_kernels.phi_functions`)."""
    small = jnp.abs(z) < 1.0
    zt = jnp.where(small, z, 0.0)
    zr = jnp.where(small, 1.0, z)
    terms = 20
    # coef[j, k - 1] = 1 / (j + k)!, highest power first
    coef = jnp.array(
        [[1.0 / math.factorial(j + k) for k in range(1, kmax + 1)] for j in range(terms)][::-1],
        dtype=z.dtype,
    )

    def horner(i: Array, p: Array) -> Array:
        return p * zt + coef[i].reshape((kmax,) + (1,) * z.ndim)

    start = jnp.zeros((kmax,) + z.shape, z.dtype)
    taylor = lax.fori_loop(0, terms, horner, start)
    out = [jnp.exp(z)]
    prev = jnp.expm1(zr)
    for k in range(1, kmax + 1):
        rec = prev / zr if k == 1 else (prev - 1.0 / math.factorial(k - 1)) / zr
        out.append(jnp.where(small, taylor[k - 1], rec))
        prev = rec
    return tuple(out)


def krogstad_weights(z: Array) -> tuple[Array, ...]:
    """``(E, E2, a, b_u, b_a, c_u, c_b, new_u, new_ab, new_c)`` for ``z = h L``: the
    exponentials of the step and the half step, the stages' and the update's weights
    (module docstring)."""
    return krogstad_from_phi(*phi_functions(z, 3), *phi_functions(0.5 * z, 2))


Stage = Callable[[Array, Array], tuple[Array, Array, Array]]


def krogstad_stages(
    q: Array,
    q_hat: Array,
    A: Array,
    h: Array,
    wq: tuple[Array, ...],
    wA: tuple[Array, ...],
    n: int,
) -> tuple[Stage, Stage, Stage, Stage]:
    """The four stages u, a, b, c of Krogstad's step from (q, q hat, A) with the weights
    ``wq``, ``wA`` of :func:`krogstad_weights` (q's and A's): each a function of the N terms
    so far (``Nq``, ``NA``, stacked u, a, b, c) returning the stage's (q, q hat, A) (module
    docstring)."""
    Eq, E2q, aq, bq_u, bq_a, cq_u, cq_b = wq[:7]
    EA, E2A, aA, bA_u, bA_a, cA_u, cA_b = wA[:7]

    def stage_u(Nq: Array, NA: Array) -> tuple[Array, Array, Array]:
        return q, q_hat, A

    def stage_a(Nq: Array, NA: Array) -> tuple[Array, Array, Array]:
        qa = E2q * q_hat + h * (aq * Nq[0])
        return inverse(qa, n), qa, E2A * A + h * (aA * NA[0])

    def stage_b(Nq: Array, NA: Array) -> tuple[Array, Array, Array]:
        qb = E2q * q_hat + h * (bq_u * Nq[0] + bq_a * Nq[1])
        return inverse(qb, n), qb, E2A * A + h * (bA_u * NA[0] + bA_a * NA[1])

    def stage_c(Nq: Array, NA: Array) -> tuple[Array, Array, Array]:
        qc = Eq * q_hat + h * (cq_u * Nq[0] + cq_b * Nq[2])
        return inverse(qc, n), qc, EA * A + h * (cA_u * NA[0] + cA_b * NA[2])

    return stage_u, stage_a, stage_b, stage_c


class Step(NamedTuple):
    """One step's outcome: the new fields, the error estimate, whether the first right-hand
    side and the other stages succeeded (and whether every spin solve converged), the start's
    well-posedness margin, and the work. A step that carries mechanics (finite strain) also
    gives the ``reason`` of a failed stage (else: a spin solve or a non-finite state), the
    mechanics to keep where the step is accepted (``mech``) or not (``kept``), and whether
    the accepted state's projection onto force balance succeeded (``projected``; else why:
    ``projection_reason``)."""

    q: Array
    q_hat: Array
    A: Array
    error: Array
    first_ok: Array
    stages_ok: Array
    spins_ok: Array
    margin: Array
    iterations: Array
    transforms: Array
    reason: Any = None
    mech: Any = ()
    kept: Any = ()
    projected: Any = True
    projection_reason: Any = 0


#: a step function: (state, step size, symbols, constants, error norm) -> its Step
StepFunction = Callable[[SeedState, Array, Any, Any, str], Step]


def krogstad_step(
    q: Array, q_hat: Array, A: Array, h: Array, sym: Symbols, c: Constants, error_norm: str
) -> Step:
    """One Krogstad ETDRK4 step of size ``h`` (float64) from (q, q hat, A) (module
    docstring); the error is float64."""
    n = c.n
    h = narrow(h, q)  # the step in the fields' precision
    wq = krogstad_weights(sym.Lq * h)
    Eq, nq_u, nq_ab, nq_c = wq[0], wq[7], wq[8], wq[9]
    LA = -(c.zeta + 3.0 * c.s * A * A) / c.tau
    wA = krogstad_weights(LA * h)
    EA, nA_u, nA_ab, nA_c = wA[0], wA[7], wA[8], wA[9]

    S = jnp.sqrt(q[0] ** 2 + q[1] ** 2)
    margin = 1.0 - jnp.max(c.amb * S)

    # the four right-hand sides (u, a, b, c) as one loop over the stages, so that the split
    # and its GMRES are compiled once; the stage index is not batched, so lax.switch picks
    # one branch (under jax.vmap too)
    stages = krogstad_stages(q, q_hat, A, h, wq, wA, n)

    def evaluate(i, carry):
        Nq, NA, converged, iterations, transforms = carry
        q_s, qh_s, A_s = lax.switch(i, stages, Nq, NA)
        r = linear_split(q_s, A_s, qh_s, sym, c)
        return (
            Nq.at[i].set(r.Nq),
            NA.at[i].set(r.Adot - LA * A_s),  # N_A = Adot - L_A A
            converged.at[i].set(r.converged),
            iterations + r.iterations,
            transforms + r.transforms,
        )

    zero = jnp.int32(0)
    Nq, NA, converged, iterations, transforms = lax.fori_loop(
        0,
        4,
        evaluate,
        (
            jnp.zeros((4,) + q_hat.shape, q_hat.dtype),
            jnp.zeros((4,) + A.shape, A.dtype),
            jnp.zeros(4, bool),
            zero,
            zero,
        ),
    )
    Nq_u, Nq_a, Nq_b, Nq_c = Nq[0], Nq[1], Nq[2], Nq[3]
    NA_u, NA_a, NA_b, NA_c = NA[0], NA[1], NA[2], NA[3]
    new_q_hat = Eq * q_hat + h * (nq_u * Nq_u + nq_ab * Nq_a + nq_ab * Nq_b + nq_c * Nq_c)
    new_A = EA * A + h * (nA_u * NA_u + nA_ab * NA_a + nA_ab * NA_b + nA_c * NA_c)
    new_q = inverse(new_q_hat, n)
    err_q = h * nq_ab * (Nq_b - Nq_a)
    err_A = h * nA_ab * (NA_b - NA_a)
    transforms = transforms + 6 + 2  # the stages' and the new state's inverse transforms
    if error_norm == "max":
        error = jnp.maximum(jnp.max(jnp.abs(inverse(err_q, n))), jnp.max(jnp.abs(err_A)))
        transforms = transforms + 2
    else:  # the RMS over the grid, from the spectra by Parseval (model.fourier.rms_hat)
        w = jnp.full(sym.Lq.shape, 2.0, A.dtype).at[:, 0].set(1.0).at[:, -1].set(1.0)
        rms = [jnp.sqrt(wide_sum(w * jnp.abs(e) ** 2)) / n**2 for e in err_q]
        error = jnp.maximum(jnp.maximum(rms[0], rms[1]), jnp.sqrt(wide_mean(err_A**2)))
    error = error.astype(jnp.float64)
    spins_ok = converged[1] & converged[2] & converged[3]
    finite = jnp.all(jnp.isfinite(new_q)) & jnp.all(jnp.isfinite(new_A))
    return Step(
        new_q,
        new_q_hat,
        new_A,
        error,
        converged[0],
        spins_ok & finite,
        spins_ok,
        margin,
        iterations,
        transforms,
    )


def quantize(h: Array, dt_max: float) -> Array:
    """Round a proposed step down onto the ladder dt_max 2^(-j/8)
    (:meth:`nematic_solids.model.solver_base.ETDSolver._quantize`)."""
    j = jnp.ceil(-8.0 * jnp.log2(h / dt_max) - 1e-9)
    return dt_max * 2.0 ** (-jnp.maximum(j, 0.0) / 8.0)


def linear_step(s: SeedState, h: Array, sym: Symbols, c: Constants, error_norm: str) -> Step:
    """:func:`krogstad_step` from the seed's state (small strain: no mechanics carried)."""
    return krogstad_step(s.q, s.q_hat, s.A, h, sym, c, error_norm)


def advance(
    s: SeedState,
    t_end: Array,
    sym: Any,
    c: Any,
    ctl: Control,
    step: StepFunction = linear_step,
) -> SeedState:
    """Step one seed from its time to ``t_end`` (landing on it exactly), with the step
    control of the module docstring; a failed seed stays where it failed. ``step`` takes
    one step (:func:`linear_step`, or finite strain's with its mechanics: then a projection
    that fails after an accepted step is retried with h/4 like a failed stage)."""
    dt_max = ctl.dt_max
    slack = 1e-12 * jnp.maximum(1.0, jnp.abs(t_end))

    def running(s: SeedState) -> Array:
        return (s.status == 0) & (s.t < t_end - slack)

    def attempt(s: SeedState) -> SeedState:
        h = s.h
        h_try = (
            jnp.minimum(jnp.minimum(h, dt_max), t_end - s.t)
            if ctl.adaptive
            else (jnp.minimum(h, t_end - s.t))
        )
        r = step(s, h_try, sym, c, ctl.error_norm)
        ill = r.first_ok & (r.margin <= 0.0)
        failed = ~r.first_ok | (r.first_ok & ~ill & ~r.stages_ok)
        if r.reason is None:
            fail_reason = jnp.where(~r.first_ok | ~r.spins_ok, SPIN, NAN)
        else:
            fail_reason = r.reason
        ok = ~failed & ~ill
        err = r.error
        safe_err = jnp.where(err > 0.0, err, 1.0)
        fac = jnp.where(
            err == 0.0,
            2.0,
            jnp.clip(0.9 * (ctl.tolerance / safe_err) ** (1.0 / ctl.error_order), 0.2, 2.0),
        )
        reject = ok & ctl.adaptive & (err > ctl.tolerance)
        h_reject = quantize(h_try * jnp.minimum(fac, 0.5), dt_max)
        collapsed = reject & (h_reject < ctl.dt_min)
        # an accepted state whose projection onto force balance fails: a failed step
        unprojected = ok & ~reject & ~jnp.asarray(r.projected)
        failed = failed | unprojected
        fail_reason = jnp.where(unprojected, r.projection_reason, fail_reason)
        final_fail = failed & ((not ctl.adaptive) | (h_try <= ctl.retry_floor * dt_max))
        accept = ok & ~reject & ~unprojected
        if ctl.adaptive:
            scaled = jnp.where(fac > 1.0, jnp.maximum(h, h_try * fac), jnp.minimum(h, h_try * fac))
            h_accept = jnp.where(
                h_try == jnp.minimum(h, dt_max),  # not shortened to land on t_end
                quantize(jnp.minimum(h_try * fac, dt_max), dt_max),
                quantize(scaled, dt_max),
            )
        else:
            h_accept = h
        h_new = jnp.where(
            failed, quantize(h_try / 4.0, dt_max), jnp.where(reject, h_reject, h_accept)
        )
        status = jnp.where(
            ill,
            ILL_POSED,
            jnp.where(final_fail, fail_reason, jnp.where(collapsed, COLLAPSED, 0)),
        ).astype(jnp.int32)
        retried = failed & ~final_fail
        return SeedState(
            jnp.where(accept, r.q, s.q),
            jnp.where(accept, r.q_hat, s.q_hat),
            jnp.where(accept, r.A, s.A),
            jnp.where(accept, s.t + h_try, s.t),
            h_new,
            status,
            jnp.where(status != 0, s.t, s.t_failed),
            jnp.where(r.first_ok, jnp.minimum(s.margin_min, r.margin), s.margin_min),
            s.steps + accept.astype(jnp.int32),
            s.rejected + (retried | reject).astype(jnp.int32),
            s.stage_failures + retried.astype(jnp.int32),
            s.rhs + 4,
            s.spin_iterations + r.iterations,
            s.transforms + r.transforms,
            jax.tree.map(lambda new, old: jnp.where(accept, new, old), r.mech, r.kept),
        )

    return lax.while_loop(running, attempt, s)
