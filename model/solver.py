r"""The fast py-pde solvers: adaptive exponential time differencing (ETD) Runge-Kutta.

Both schemes split each field's rate into a stiff linear part and the rest N,

.. math::
    \dot{\hat q} = L_q \hat q + \hat N_q, \quad L_q = -(A_0 + K k^2)/\gamma, \qquad
    \dot A = L_A A + N_A, \quad L_A(x) = -(\zeta + 3 s A_n(x)^2)/\tau ,

so the Frank term and the linear decay of Q are integrated exactly in Fourier space, and the
local cubic of Eq. (5) (stiff once a pattern has formed: :math:`3 s A^2 \sim 25`) with its
pointwise Jacobian frozen at the start of the step (an exponential Rosenbrock-type splitting,
in real space: the split is exact for any frozen L, so the orders are unchanged). Both L are
diagonal (in Fourier space for q, point by point for A), so every :math:`\varphi_k(hL)` is a
pointwise function, :math:`\varphi_k(z) = \sum_j z^j/(j+k)!`.

**ETDRK4** (default, ``numerics.scheme = "etdrk4"``; Krogstad 2005, J. Comput. Phys. 203, 72),
four right-hand sides per step, with :math:`\varphi_k = \varphi_k(hL)`,
:math:`\tilde\varphi_k = \varphi_k(hL/2)`:

.. math::
    a &= e^{Lh/2} u_n + \tfrac h2 \tilde\varphi_1 N_u, \qquad
    b = a + h \tilde\varphi_2 (N_a - N_u), \qquad
    c = e^{Lh} u_n + h \varphi_1 N_u + 2 h \varphi_2 (N_b - N_u), \\
    u_{n+1} &= e^{Lh} u_n + h\big[(\varphi_1 - 3\varphi_2 + 4\varphi_3) N_u
      + (2\varphi_2 - 4\varphi_3)(N_a + N_b) + (4\varphi_3 - \varphi_2) N_c\big].

Error estimate: the same weights with :math:`2 N_a` in place of :math:`N_a + N_b` (Cox &
Matthews' third-order weights on the first-order midpoint stage a), i.e.
:math:`e = h (2\varphi_2 - 4\varphi_3)(N_b - N_a) = O(h^3)`; the step advances with the
fourth-order value (local extrapolation). Measured orders 3.8-4.1 (tests).

**ETDRK2** (``scheme = "etdrk2"``; Cox & Matthews 2002, J. Comput. Phys. 176, 430, Eq. 22):

.. math::
    a = e^{L h} u_n + h\, \varphi_1(L h)\, N(u_n), \qquad
    u_{n+1} = a + h\, \varphi_2(L h)\, \big(N(a) - N(u_n)\big),

with the difference ``u_{n+1} - a`` (O(h^2)) as the error estimate.

**Step control** (both): the error is the largest pointwise error (``error_norm = "max"``,
default; ``"rms"``: the RMS over the grid), maximum over the three fields; a step is accepted
if it is below ``numerics.tolerance`` and the next step is scaled by
:math:`0.9\,(\mathrm{tol}/\mathrm{err})^{1/p}` (p = 3 for ETDRK4, 2 for ETDRK2), clipped to
[0.2, 2] and ``dt_max``, and rounded down onto the ladder ``dt_max 2^(-j/8)`` so that the phi
functions of :math:`L_q` are reused. A step whose stage cannot be evaluated (non-finite, a spin
or Newton solve that fails: a too-large step can throw a stage out of the well-posed range) is
retried with h/4; if it still fails at ``h <= 1e-3 dt_max`` the failure is the run's.
``adaptive = False`` gives the fixed-step schemes (orders tested).

In linear mechanics the Jaumann spin is computed with the spectral symbol of
:meth:`model.mechanics.LinearMechanics.spin_multiplier`, reusing the transforms the step needs
anyway, and the whole right-hand side runs as one compiled function
(:mod:`model.compiled.linear_rhs`) where native FFTW is available and ``Numerics.backend`` is
"compiled" (its numpy reference otherwise: :mod:`model.split`); the stage algebra is one pass per
stage (the backend's ``etd_combination``); finite mechanics uses the generic
:meth:`ActiveNematicPDE.rates` path with the displacement-rate solve (its Krylov solves compiled,
:mod:`model.compiled.finite_krylov`), with the displacement integrated with the state or Newton
warm-started from the last stage's displacement plus its rate times the time offset.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
from pde.solvers.base import SolverBase

from model.backend import kernels
from model.errors import IllPosed, SimulationFailure
from model.mechanics import MechanicalState, Mechanics
from model.pde import ActiveNematicPDE
from model.reference_kernels import phi_functions
from model.split import make_split

log = logging.getLogger(__name__)
Array = np.ndarray


class ETDSolver(SolverBase):
    """Shared machinery of the exponential integrators for :class:`ActiveNematicPDE`: the
    split right-hand side, cached phi functions, spectra reuse and the adaptive step control
    (see module docstring). Subclasses define :meth:`step` and ``error_order`` (the local
    error estimate is O(h^error_order))."""

    dt_min = 1e-7
    error_order = 2
    #: a step whose stage fails (non-finite state or a spin / Newton solve that does not
    #: converge) is retried with h / 4 while h > this; below it the failure is the run's.
    retry_floor = 1e-3

    def __init__(
        self,
        pde: ActiveNematicPDE,
        *,
        backend: str = "numpy",
        adaptive: bool | None = None,
        tolerance: float | None = None,
        dt_max: float | None = None,
    ):
        super().__init__(pde, backend=backend)
        self.pde: ActiveNematicPDE = pde
        num = pde.numerics
        self.adaptive = num.adaptive if adaptive is None else adaptive
        self.tolerance = num.tolerance if tolerance is None else tolerance
        self.dt_max = num.dt_max if dt_max is None else dt_max
        self.error_norm = num.error_norm
        p, g = pde.params, pde.spectral
        self.Lq = -(p.A0 + p.K * g.k2) / p.gamma  # the q1, q2 symbol (Fourier space)
        #: the pointwise kernels of the backend (model.backend)
        self.k = kernels(num.backend)
        self._known: list[tuple[Array, Array]] = []
        self._phi_cache: dict[tuple[float, int], tuple[Array, ...]] = {}
        self.on_step: Callable[[float, float], None] | None = None
        #: the split right-hand side (model.split: spectral for linear mechanics, compiled
        #: where the mechanics is)
        self._split = make_split(pde.mechanics, pde, self.Lq)
        #: whether the mechanics' warm start was checkpointed in the current step (after its
        #: first right-hand side)
        self._checkpointed = False
        #: the integrated displacement spectrum at the end of the last step and its
        #: deformation gradient (projected onto force balance when the step is accepted)
        self._pending_disp: tuple[Array, Array] | None = None
        self.stats = {
            "steps": 0,
            "rejected": 0,
            "stage_failures": 0,
            "rhs": 0,
            "newton": 0,
            "projections": 0,
        }
        #: the mechanical state of the last force-balance right-hand side (its tangent and E
        #: serve the well-posedness check of the step's start)
        self._last_mech: MechanicalState | None = None
        #: smallest well-posedness margin over the accepted states (model.wellposedness)
        self.margin_min = float("inf")
        self._checked_at = float("nan")

    # --- the split right-hand side -----------------------------------------------------
    def split(
        self, u: Array, q_hat: Array, t: float, disp: Array | None = None, F: Array | None = None
    ) -> tuple[Array, Array]:
        """Return ``(N_q hat, Adot)`` for the state ``u = [q1, q2, A]`` with ``q_hat`` the
        spectra of q1, q2 (:mod:`model.split`). Where the mechanics integrates the
        displacement: at the displacement spectrum ``disp`` with deformation gradient ``F`` (its
        rate is then the mechanics' ``udot_hat``, with gradient ``udot_grad``)."""
        self.stats["rhs"] += 1
        Nq, Adot, mech = self._split(u, q_hat, t, disp, F)
        if mech is not None:
            self._last_mech = mech
            self.stats["newton"] += mech.iterations
        return Nq, Adot

    def full_rate(self, u: Array, t: float = 0.0) -> Array:
        """:math:`\\dot u` assembled from the split (equals ``pde.evolution_rate``; tested)."""
        g = self.pde.spectral
        q_hat = g.forward(u[:2])
        Nq, Adot = self.split(u, q_hat, t)
        return np.concatenate([g.inverse(self.Lq * q_hat + Nq), Adot[None]])

    # --- one step ----------------------------------------------------------------------
    def _phis(self, h: float, kmax: int = 2) -> tuple[Array, ...]:
        """exp(L_q h), phi_1..phi_kmax(L_q h), cached per step size (q1, q2 share them)."""
        cached = self._phi_cache.get((h, kmax))
        if cached is None:
            cached = phi_functions(self.Lq * h, kmax)
            if len(self._phi_cache) > 64:
                self._phi_cache.clear()
            self._phi_cache[(h, kmax)] = cached
        return cached

    def _spectrum(self, q: Array) -> Array:
        """The spectra of q1, q2, reused when ``q`` is the state the last step started from
        (a rejected step) or produced (the next step): saves two transforms per step."""
        for real, hat in self._known:
            if np.array_equal(real, q):
                return hat
        return self.pde.spectral.forward(q)

    def step(self, u: Array, t: float, h: float) -> tuple[Array, float]:
        """One step from ``(u, t)`` of size ``h``; returns (new state, error estimate)."""
        raise NotImplementedError

    def check_wellposed(self, u: Array, t: float) -> float:
        """The well-posedness margin of the state ``u`` (an accepted state: every step checks
        its start after the first right-hand side, reusing that evaluation's tangent); raises
        :class:`model.errors.IllPosed` when it is <= 0, naming the value and the place."""
        if t == self._checked_at:  # a rejected step retried from the same state
            return self.margin_min
        self._checked_at = t
        margin, idx, phi = self.pde.mechanics.rate_margin(u[0], u[1], self._last_mech)
        self.margin_min = min(self.margin_min, margin)
        if margin <= 0.0:
            n = self.pde.spectral.n
            ix, iy = divmod(idx, n)
            S = float(np.hypot(u[0].flat[idx], u[1].flat[idx]))
            amb = self.pde.params.alpha_minus_B
            raise IllPosed(
                f"well-posedness margin {margin:.3g} <= 0 at x = {(ix + 0.5) / n:.3f}, "
                f"y = {(iy + 0.5) / n:.3f} (S = {S:.3f}, (alpha - B) S = {amb * S:.3f}, "
                f"wave vector at {np.degrees(phi):.0f} deg)",
                t,
            )
        return margin

    def _integrated_mechanics(self) -> Mechanics | None:
        """The mechanics if it integrates the displacement with the state, else None."""
        mech = self.pde.mechanics
        return mech if mech.integrated else None

    def _checkpoint(self) -> None:
        """Remember the mechanics' warm start after the step's first right-hand side (so a
        rejected step can put it back)."""
        self.pde.mechanics.checkpoint()
        self._checkpointed = True

    def _restore(self) -> None:
        """Undo a rejected or failed step's mechanical work: the warm start back to the
        step's start (if it got that far), the integrated displacement it produced dropped."""
        self._pending_disp = None
        if self._checkpointed:
            self.pde.mechanics.restore()

    def _finish(
        self,
        u: Array,
        q_hat: Array,
        new_q_hat: Array,
        new_A: Array,
        err_q: Array,
        err_A: Array,
        new_disp: tuple[Array, Array] | None = None,
        err_grad: Array | None = None,
    ) -> tuple[Array, float]:
        """The new state, its spectra remembered for the next step, and the error estimate
        of ``err_q`` (spectra) and ``err_A`` (real space): the largest pointwise error
        (``error_norm = "max"``, two inverse transforms) or the RMS over the grid, maximum
        over the three fields. With the integrated displacement, ``new_disp`` (spectrum and
        deformation gradient) is kept for the projection of an accepted step, and the
        displacement's error counts by its strain ``err_grad`` (real space), each component of
        :math:`\\nabla e_u` like a field."""
        g = self.pde.spectral
        new = np.concatenate([g.inverse(new_q_hat), new_A[None]])
        self._known = [(u[:2].copy(), q_hat), (new[:2], new_q_hat)]
        if self.error_norm == "max":
            err = max(float(np.abs(g.inverse(err_q)).max()), float(np.abs(err_A).max()))
        else:
            err = max(g.rms_hat(err_q[0]), g.rms_hat(err_q[1]), float(np.sqrt(np.mean(err_A**2))))
        self._pending_disp = new_disp
        if err_grad is not None:
            err = max(
                err,
                float(np.abs(err_grad).max())
                if self.error_norm == "max"
                else float(np.sqrt(np.mean(err_grad**2, axis=(2, 3))).max()),
            )
        return new, err

    def _project(self, new: Array, t: float) -> None:
        """Put the integrated displacement of an accepted step back onto force balance
        (Eq. 3): Newton from it, usually no or one iteration; it becomes the mechanics'
        displacement, from which the next step starts."""
        disp, self._pending_disp = self._pending_disp, None
        if disp is None:
            return
        state = self.pde.mechanics.solve(new[0], new[1], u_guess=disp[0], t=t, F_guess=disp[1])
        self.stats["newton"] += state.iterations
        self.stats["projections"] += 1

    def _retry(self, exc: SimulationFailure, h_try: float, t: float) -> float:
        """A failed stage or projection: the step size to retry with (h / 4), or raise
        ``exc`` when the failure is the run's (fixed steps, an ill-posed accepted state, or a
        step at the retry floor)."""
        # a too-large step can throw a stage out of the well-posed range: retry smaller; a
        # failure that persists at small steps is the run's, and so is an ill-posed accepted
        # state (a shorter step cannot change it)
        self._restore()
        if (
            not self.adaptive
            or isinstance(exc, IllPosed)
            or h_try <= self.retry_floor * self.dt_max
        ):
            raise exc
        log.debug("step %g at t = %g failed (%s): retrying with h / 4", h_try, t, exc)
        self.stats["rejected"] += 1
        self.stats["stage_failures"] += 1
        return self._quantize(h_try / 4)

    def _quantize(self, h: float) -> float:
        """Round a proposed step down onto the ladder dt_max * 2^(-j/8), so that only a few
        distinct step sizes occur and their phi functions are reused."""
        j = np.ceil(-8.0 * np.log2(h / self.dt_max) - 1e-9)
        return float(self.dt_max * 2.0 ** (-max(j, 0.0) / 8.0))

    # --- py-pde interface --------------------------------------------------------------
    def make_stepper(self, state, dt: float | None = None):  # type: ignore[override]
        self.info["dt"] = dt = float(dt or self.pde.numerics.dt)
        self.info["steps"] = 0
        self.info["stochastic"] = False
        self.info["dt_adaptive"] = self.adaptive
        self._dt = dt

        def stepper(state, t_start: float, t_end: float) -> float:
            u = state.data
            t = t_start
            h = self._dt
            while t < t_end - 1e-12 * max(1.0, abs(t_end)):
                # land exactly on t_end (the next save time)
                h_try = min(h, self.dt_max, t_end - t) if self.adaptive else min(h, t_end - t)
                try:
                    new, err = self.step(u, t, h_try)
                    if not np.all(np.isfinite(new)):
                        raise SimulationFailure("nan", "non-finite state after a step", t)
                except SimulationFailure as exc:
                    h = self._retry(exc, h_try, t)
                    continue
                if self.adaptive:
                    fac = (
                        2.0
                        if err == 0
                        else float(
                            np.clip(
                                0.9 * (self.tolerance / err) ** (1.0 / self.error_order), 0.2, 2.0
                            )
                        )
                    )
                    if err > self.tolerance:
                        self.stats["rejected"] += 1
                        self._restore()
                        # a rejected step is retried at most half as long: the estimate
                        # near the stability limit does not scale as h^p (measured: repeated
                        # rejections at 0.9 (tol/err)^(1/p))
                        h = self._quantize(h_try * min(fac, 0.5))
                        if h < self.dt_min:
                            raise SimulationFailure(
                                "step_size_collapsed",
                                f"adaptive time step fell below {self.dt_min:g}",
                                t,
                            )
                        continue
                try:
                    self._project(new, t + h_try)
                except SimulationFailure as exc:
                    h = self._retry(exc, h_try, t)
                    continue
                if self.adaptive:
                    if h_try == min(h, self.dt_max):  # not shortened to hit t_end
                        h = self._quantize(min(h_try * fac, self.dt_max))
                    else:
                        h = max(h, h_try * fac) if fac > 1 else min(h, h_try * fac)
                        h = self._quantize(h)
                u[...] = new
                t += h_try
                self.stats["steps"] += 1
                self.info["steps"] += 1
                if self.on_step is not None:
                    self.on_step(t, h_try)
            self._dt = h
            self.info["dt_last"] = h
            return t

        return stepper


class ETDRK2Solver(ETDSolver):
    """Adaptive ETDRK2 (Cox & Matthews ETD2RK, embedded ETD1 error estimate)."""

    name = "etdrk2"
    error_order = 2

    def step(self, u: Array, t: float, h: float) -> tuple[Array, float]:
        """One ETDRK2 step; returns (new state, error estimate)."""
        g = self.pde.spectral
        q_hat = self._spectrum(u[:2])
        A = u[2]
        self._checkpointed = False
        fin = self._integrated_mechanics()
        d0 = fin.u_hat if fin is not None else None
        Nq0, Adot0 = self.split(u, q_hat, t, d0)
        self.check_wellposed(u, t)
        self._checkpoint()
        E, phi1, phi2 = self._phis(h)
        p = self.pde.params
        LA, phi1A, phi2A = self.k.activity_exponential(A, h, p.zeta, p.s, p.tau)
        aq_hat = E * q_hat + h * phi1 * Nq0
        aA = A + h * phi1A * Adot0  # = e^{L h} A + h phi1 (Adot - L A)
        a = np.concatenate([g.inverse(aq_hat), aA[None]])
        # the displacement: ETD with L = 0, i.e. Heun's method (its deformation gradient
        # alongside, in real space, from the rates' gradients)
        da = V0 = G0 = Fa = None
        if fin is not None and d0 is not None:
            V0, G0 = fin.udot_hat, fin.udot_grad
            d0 = np.ascontiguousarray(d0)
            da = self.k.rk_stage(d0, h, V0)
            Fa = self.k.rk_stage(np.ascontiguousarray(fin.deformation_of(d0)), h, G0)
        else:  # first-order predictor of Newton's start
            self.pde.mechanics.predict(h)
        Nqa, Adota = self.split(a, aq_hat, t + h, da, Fa)
        corr_q = h * phi2 * (Nqa - Nq0)
        corr_A = h * phi2A * (Adota - Adot0 - LA * (aA - A))
        if fin is None or da is None or V0 is None or G0 is None or Fa is None:
            return self._finish(u, q_hat, aq_hat + corr_q, aA + corr_A, corr_q, corr_A)
        corr_d = 0.5 * h * (fin.udot_hat - V0)
        corr_G = 0.5 * h * (fin.udot_grad - G0)
        return self._finish(
            u,
            q_hat,
            aq_hat + corr_q,
            aA + corr_A,
            corr_q,
            corr_A,
            (da + corr_d, Fa + corr_G),
            corr_G,
        )


class ETDRK4Solver(ETDSolver):
    """Adaptive fourth-order ETD Runge-Kutta of Krogstad (2005), with an embedded O(h^3)
    error estimate (see module docstring)."""

    name = "etdrk4"
    error_order = 3

    def __init__(self, pde: ActiveNematicPDE, **kwargs):
        super().__init__(pde, **kwargs)
        self._weight_cache: dict[float, tuple[Array, Array, dict[str, tuple[Array, ...]]]] = {}

    def step(self, u: Array, t: float, h: float) -> tuple[Array, float]:
        """One Krogstad ETDRK4 step; returns (new state, error estimate)."""
        g = self.pde.spectral
        p = self.pde.params
        self._checkpointed = False
        q_hat = self._spectrum(u[:2])
        A = u[2]
        E, E2, wq = self._krogstad_weights(h)
        LA, W = self.k.activity_krogstad(A, h, p.zeta, p.s, p.tau)  # pointwise L_A: no cache
        EA, EA2 = W[0], W[1]
        wA = {"a": (W[2],), "b": (W[3], W[4]), "c": (W[5], W[6]), "new": (W[7], W[8], W[8], W[9])}
        comb = self.k.etd_combination

        def combo_q(Eq: Array, x: Array, w: tuple[Array, ...], N: tuple[Array, ...]) -> Array:
            return comb(Eq, x, h, w, N)

        def combo_A(Ea: Array, x: Array, w: tuple[Array, ...], N: tuple[Array, ...]) -> Array:
            return comb(Ea, x[None], h, w, tuple(n[None] for n in N))[0]

        fin = self._integrated_mechanics()

        def rhs(
            q_s: Array, A_s: Array, t_s: float, d_s: Array | None, F_s: Array | None
        ) -> tuple[Array, Array]:
            """Stage (q spectra, A[, displacement spectrum and its deformation gradient]) ->
            (N_q hat, N_A) with N_A = Adot - L_A A (the displacement rate is then the
            mechanics' udot_hat, its gradient udot_grad)."""
            stage = np.empty((3,) + A_s.shape)
            g.inverse(q_s, out=stage[:2])
            stage[2] = A_s
            Nq, Adot = self.split(stage, q_s, t_s, d_s, F_s)
            return Nq, Adot - LA * A_s

        d0 = fin.u_hat if fin is not None else None
        Nq_u, Adot_u = self.split(u, q_hat, t, d0)
        self.check_wellposed(u, t)
        NA_u = Adot_u - LA * A
        self._checkpoint()
        # the integrated displacement (L = 0: the weights become the classical RK4's,
        # phi_k(0) = 1/k!): d_a = d + h/2 V_u, d_b = d + h/2 V_a, d_c = d + h V_b, and its
        # deformation gradient alongside in real space, F_a = F + h/2 grad V_u, ..., from
        # the rates' gradients that the rate solves return (no transforms)
        V: list[Array] = []  # the rates (spectra)
        G: list[Array] = []  # their gradients
        d_a = d_b = d_c = F0 = F_a = F_b = F_c = None
        rk = self.k.rk_stage  # x0 + c v in one pass
        if fin is not None and d0 is not None:
            d0 = np.ascontiguousarray(d0)
            F0 = np.ascontiguousarray(fin.deformation_of(d0))
            V.append(fin.udot_hat)
            G.append(fin.udot_grad)
            d_a = rk(d0, 0.5 * h, V[0])
            F_a = rk(F0, 0.5 * h, G[0])
        else:  # Newton's start: the displacement extrapolated with its rate
            self.pde.mechanics.predict(0.5 * h)
        # stage a (t + h/2): ETD1 half step
        Nq_a, NA_a = rhs(
            combo_q(E2, q_hat, wq["a"], (Nq_u,)),
            combo_A(EA2, A, wA["a"], (NA_u,)),
            t + 0.5 * h,
            d_a,
            F_a,
        )
        if fin is not None and d0 is not None and F0 is not None:
            V.append(fin.udot_hat)
            G.append(fin.udot_grad)
            d_b = rk(d0, 0.5 * h, V[1])
            F_b = rk(F0, 0.5 * h, G[1])
        # stage b (t + h/2): Krogstad's correction with phi_2, a + h phi_2(h/2) (N_a - N_u)
        Nq_b, NA_b = rhs(
            combo_q(E2, q_hat, wq["b"], (Nq_u, Nq_a)),
            combo_A(EA2, A, wA["b"], (NA_u, NA_a)),
            t + 0.5 * h,
            d_b,
            F_b,
        )
        if fin is not None and d0 is not None and F0 is not None:
            V.append(fin.udot_hat)
            G.append(fin.udot_grad)
            d_c = rk(d0, h, V[2])
            F_c = rk(F0, h, G[2])
        else:
            self.pde.mechanics.predict(0.5 * h)
        # stage c (t + h)
        Nq_c, NA_c = rhs(
            combo_q(E, q_hat, wq["c"], (Nq_u, Nq_b)),
            combo_A(EA, A, wA["c"], (NA_u, NA_b)),
            t + h,
            d_c,
            F_c,
        )
        # the fourth-order combination
        new_q_hat = combo_q(E, q_hat, wq["new"], (Nq_u, Nq_a, Nq_b, Nq_c))
        new_A = combo_A(EA, A, wA["new"], (NA_u, NA_a, NA_b, NA_c))
        # embedded estimate: the same weights with N_a in place of (N_a + N_b)/2, i.e. the
        # Cox-Matthews third-order weights on the first-order midpoint stage: O(h^3)
        err_q = h * wq["new"][1] * (Nq_b - Nq_a)
        err_A = h * wA["new"][1] * (NA_b - NA_a)
        if fin is None or d0 is None or F0 is None:
            return self._finish(u, q_hat, new_q_hat, new_A, err_q, err_A)
        V.append(fin.udot_hat)
        G.append(fin.udot_grad)
        new_d = self.k.rk4_update(d0, h / 6.0, *V)  # d0 + h/6 (V0 + 2 V1 + 2 V2 + V3)
        new_F = self.k.rk4_update(F0, h / 6.0, *G)
        return self._finish(
            u, q_hat, new_q_hat, new_A, err_q, err_A, (new_d, new_F), (h / 3.0) * (G[2] - G[1])
        )

    @staticmethod
    def _weights_from(
        f1: Array, f2: Array, f3: Array, g1: Array, g2: Array
    ) -> dict[str, tuple[Array, ...]]:
        """The stage and update weights of Krogstad's scheme from phi_k(hL) (f) and
        phi_k(hL/2) (g): a = e^{Lh/2} u + h [g1/2] N_u, b = e^{Lh/2} u + h [g1/2 - g2, g2]
        (N_u, N_a), c = e^{Lh} u + h [f1 - 2 f2, 2 f2] (N_u, N_b), u_{n+1} = e^{Lh} u +
        h [w_u, w_ab, w_ab, w_c] (N_u, N_a, N_b, N_c) (module docstring)."""
        w_ab = 2.0 * f2 - 4.0 * f3
        return {
            "a": (0.5 * g1,),
            "b": (0.5 * g1 - g2, g2),
            "c": (f1 - 2.0 * f2, 2.0 * f2),
            "new": (f1 - 3.0 * f2 + 4.0 * f3, w_ab, w_ab, 4.0 * f3 - f2),
        }

    def _krogstad_weights(self, h: float) -> tuple[Array, Array, dict[str, tuple[Array, ...]]]:
        """``(e^{L_q h}, e^{L_q h/2}, weights)`` for the q spectra, cached per step size."""
        cached = self._weight_cache.get(h)
        if cached is None:
            E, f1, f2, f3 = self._phis(h, 3)
            E2, g1, g2 = self._phis(0.5 * h, 2)
            cached = (E, E2, self._weights_from(f1, f2, f3, g1, g2))
            if len(self._weight_cache) > 64:
                self._weight_cache.clear()
            self._weight_cache[h] = cached
        return cached


#: the schemes ``numerics.scheme`` may name
SCHEMES: dict[str, type[ETDSolver]] = {"etdrk4": ETDRK4Solver, "etdrk2": ETDRK2Solver}
