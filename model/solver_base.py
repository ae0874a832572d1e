r"""The machinery that both exponential integrators of :mod:`nematic_solids.model.solver` share:
:class:`ETDSolver`.

It holds what does not depend on the scheme: the split right-hand side
(:mod:`nematic_solids.model.split`), the phi functions of :math:`L_q = -(A_0 + K k^2)/\gamma` cached
per step size, the spectra reused between steps, the well-posedness monitor
(:mod:`nematic_solids.model.wellposedness`), the integrated displacement's projection onto force
balance (Eq. (3)) once per accepted step, and py-pde's stepper with the step control below. The
schemes (:class:`nematic_solids.model.solver.ETDRK2Solver`,
:class:`nematic_solids.model.solver.ETDRK4Solver`) define the step and the order of its error
estimate.

**Step control** (both): the error is the largest pointwise error (``error_norm = "max"``,
default; ``"rms"``: the RMS over the grid), maximum over the three fields; a step is accepted
if it is below ``numerics.tolerance`` and the next step is scaled by
:math:`0.9\,(\mathrm{tol}/\mathrm{err})^{1/p}` (p = 3 for ETDRK4, 2 for ETDRK2), clipped to
[0.2, 2] and ``dt_max``, and rounded down onto the ladder ``dt_max 2^(-j/8)`` so that the phi
functions of :math:`L_q` are reused. A step whose stage cannot be evaluated (non-finite, a spin
or Newton solve that fails: a too-large step can throw a stage out of the well-posed range) is
retried with h/4; if it still fails at ``h <= 1e-3 dt_max`` the failure is the run's.
``adaptive = False`` gives the fixed-step schemes (orders tested).

**Protocols** (:mod:`nematic_solids.model.protocol`): a step never crosses a switch time of the
parameters' functions of time; one that would is shortened to end on it, and the next starts exactly
there. Inside a sine no step is longer than 1/16 of its period, inside a ramp piece than 1/8 of its
duration (:meth:`nematic_solids.model.protocol.Protocol.max_step`; adaptive: rounded down onto
the ladder), whatever the error estimate allows, fixed steps included. Every stage of a step
sets the constants at its time on the pieces that hold the step's start; the projection and the
saves at the step's end use the values after it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pde.solvers.base import SolverBase

from .backend import kernels
from .errors import IllPosed, SimulationFailure
from .mechanics import MechanicalState, Mechanics
from .pde import ActiveNematicPDE
from .reference_kernels import phi_functions
from .split import make_split

#: the solvers' logger (nematic_solids.model.solver: the name under which they have always logged)
log = logging.getLogger("nematic_solids.model.solver")
Array = np.ndarray


@dataclass
class SolverState:
    """The solver's part of a continued run's state (:mod:`nematic_solids.model.checkpoint`): the
    step size the next step tries, the spectra of q1, q2 as the last step produced them (a forward
    transform of the fields differs from them by rounding; None before the first step), the counters
    and the smallest well-posedness margin so far."""

    h: float
    q_hat: Array | None
    stats: dict[str, int]
    margin_min: float


#: step sizes whose symbols a solver keeps (:func:`_cached`)
CACHE_SIZE = 64


def _cached(cache: dict, key, make: Callable):  # type: ignore[type-arg]
    """``cache[key]``, made by ``make()`` if absent; the cache keeps the :data:`CACHE_SIZE` most
    recently used entries (a dict in order of use). The step sizes of the ladder recur all run
    long; a step shortened to land on a save time is used once: it pushes out the entry
    unused the longest, not the whole cache."""
    value = cache.pop(key, None)
    if value is None:
        value = make()
        if len(cache) >= CACHE_SIZE:
            del cache[next(iter(cache))]
    cache[key] = value  # the most recently used last
    return value


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
        #: the pointwise kernels of the backend (nematic_solids.model.backend)
        self.k = kernels(num.backend)
        self._known: list[tuple[Array, Array]] = []
        self._phi_cache: dict[tuple[float, int], tuple[Array, ...]] = {}
        self.on_step: Callable[[float, float], None] | None = None
        #: the split right-hand side (nematic_solids.model.split: spectral for linear mechanics,
        #: compiled where the mechanics is)
        self._split = make_split(pde.mechanics, pde, self.Lq)
        #: whether the mechanics' warm start was checkpointed in the current step (after its
        #: first right-hand side)
        self._checkpointed = False
        #: the integrated displacement spectrum at the end of the last step and its
        #: deformation gradient (projected onto force balance when the step is accepted)
        self._pending_disp: tuple[Array, Array | None] | None = None
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
        #: smallest well-posedness margin over the accepted states
        #: (nematic_solids.model.wellposedness)
        self.margin_min = float("inf")
        self._checked_at = float("nan")
        #: the step size the next step tries (the step control's state between segments)
        self._dt = float(num.dt)
        #: the step size a continued run starts with (:meth:`resume`)
        self._resume_h: float | None = None
        #: the start of the step being taken: its stages use the protocol's pieces that
        #: hold it (nematic_solids.model.protocol; None outside a step: right-continuous)
        self._after: float | None = None
        #: the integrated displacement carries its deformation gradient through the stages
        #: (in real space) unless a protocol moves the applied shear F bar: then each stage
        #: transforms its displacement (F = F bar(t) + grad u at the stage's time)
        self.carry_deformation = not pde.protocol.varies("eps")

    # --- the split right-hand side -----------------------------------------------------
    def split(
        self, u: Array, q_hat: Array, t: float, disp: Array | None = None, F: Array | None = None
    ) -> tuple[Array, Array]:
        """Return ``(N_q hat, Adot)`` for the state ``u = [q1, q2, A]`` with ``q_hat`` the
        spectra of q1, q2 (:mod:`nematic_solids.model.split`). Where the mechanics integrates the
        displacement: at the displacement spectrum ``disp`` with deformation gradient ``F`` (its
        rate is then the mechanics' ``udot_hat``, with gradient ``udot_grad``)."""
        self.stats["rhs"] += 1
        self.pde.at_time(t, self._after)
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
        """exp(L_q h), phi_1..phi_kmax(L_q h), cached per step size (q1, q2 share them;
        :func:`_cached`)."""
        return _cached(self._phi_cache, (h, kmax), lambda: phi_functions(self.Lq * h, kmax))

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
        :class:`nematic_solids.model.errors.IllPosed` when it is <= 0, naming the value and the
        place."""
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
        err_q: Array | None,
        err_A: Array | None,
        new_disp: tuple[Array, Array | None] | None = None,
        err_grad: Array | None = None,
        new: Array | None = None,
        err: float | None = None,
    ) -> tuple[Array, float]:
        """The new state, its spectra remembered for the next step, and the error estimate
        of ``err_q`` (spectra) and ``err_A`` (real space): the largest pointwise error
        (``error_norm = "max"``, two inverse transforms) or the RMS over the grid, maximum
        over the three fields. With the integrated displacement, ``new_disp`` (spectrum and
        deformation gradient) is kept for the projection of an accepted step, and the
        displacement's error counts by its strain ``err_grad`` (real space), each component of
        :math:`\\nabla e_u` like a field. ``new``: the new state if the caller has it (then
        ``new_A`` is its last field). ``err``: the error estimate of ``err_q`` and ``err_A``
        if the caller has formed it (then they are None)."""
        g = self.pde.spectral
        if new is None:
            new = np.concatenate([g.inverse(new_q_hat), new_A[None]])
        self._known = [(u[:2].copy(), q_hat), (new[:2], new_q_hat)]
        if err is None:
            if err_q is None or err_A is None:
                raise ValueError("the error estimate or its parts (err_q, err_A) must be given")
            if self.error_norm == "max":
                err = max(float(np.abs(g.inverse(err_q)).max()), float(np.abs(err_A).max()))
            else:
                err = max(
                    g.rms_hat(err_q[0]), g.rms_hat(err_q[1]), float(np.sqrt(np.mean(err_A**2)))
                )
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
        self.pde.at_time(
            t
        )  # the step's end belongs to the next piece (nematic_solids.model.protocol)
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
        j = math.ceil(-8.0 * math.log2(h / self.dt_max) - 1e-9)
        return float(self.dt_max * 2.0 ** (-max(j, 0) / 8.0))

    # --- continuation (nematic_solids.model.checkpoint)
    # ---------------------------------------------
    def saved_state(self, u: Array) -> SolverState:
        """What a run continued from the accepted state ``u`` needs of the solver."""
        q_hat = next((hat.copy() for real, hat in self._known if np.array_equal(real, u[:2])), None)
        return SolverState(self._dt, q_hat, dict(self.stats), self.margin_min)

    def resume(self, saved: SolverState, u: Array) -> None:
        """Take back :meth:`saved_state` for the state ``u``: the next :meth:`make_stepper`
        starts with the saved step size instead of its ``dt``."""
        self._known = [] if saved.q_hat is None else [(u[:2].copy(), saved.q_hat)]
        self.stats.update(saved.stats)
        self.margin_min = saved.margin_min
        self._resume_h = saved.h

    # --- py-pde interface --------------------------------------------------------------
    def make_stepper(self, state, dt: float | None = None):  # type: ignore[override]
        self.info["dt"] = dt = float(dt or self.pde.numerics.dt)
        self.info["steps"] = 0
        self.info["stochastic"] = False
        self.info["dt_adaptive"] = self.adaptive
        # a continued run steps on with the step size it had (py-pde's dt, which sets the
        # trackers' time tolerance, stays the run's initial one)
        self._dt = dt if self._resume_h is None else self._resume_h
        self._resume_h = None

        protocol = self.pde.protocol

        def stepper(state, t_start: float, t_end: float) -> float:
            u = state.data
            # the steps work on a C-contiguous copy: py-pde's data is a view of an array with
            # ghost cells (rows strided), on which the compiled kernels take their slower
            # strided variants; the last accepted state is copied into the view when the
            # stepper returns (nothing reads it in between; a failure ends the run)
            cur = np.ascontiguousarray(u)
            t = t_start
            h = self._dt
            while t < t_end - 1e-12 * max(1.0, abs(t_end)):
                # land exactly on t_end (the next save time) and on the protocol's switch
                # times (no step crosses one: nematic_solids.model.protocol)
                switch = protocol.next_break(t)
                target = min(t_end, switch)
                # no step over a sine's period or a ramp's piece (its fraction, on the ladder)
                cap = protocol.max_step(t) if protocol else math.inf
                if self.adaptive:
                    if cap < self.dt_max:
                        cap = self._quantize(cap)
                    h_try = min(h, self.dt_max, cap, target - t)
                else:
                    h_try = min(h, cap, target - t)
                if t + h_try == t and h_try != switch - t:  # a step that would not move on
                    raise SimulationFailure(
                        "time_unresolved", f"a step of {h_try:g} does not change t", t
                    )
                try:
                    self._after = t
                    new, err = self.step(cur, t, h_try)
                    if not np.all(np.isfinite(new)):
                        raise SimulationFailure("nan", "non-finite state after a step", t)
                except SimulationFailure as exc:
                    self._after = None
                    h = self._retry(exc, h_try, t)
                    continue
                self._after = None
                if self.adaptive:
                    fac = (
                        2.0
                        if err == 0
                        else min(
                            max(0.9 * (self.tolerance / err) ** (1.0 / self.error_order), 0.2),
                            2.0,
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
                cur = new
                t = switch if h_try == switch - t else t + h_try
                self.stats["steps"] += 1
                self.info["steps"] += 1
                if self.on_step is not None:
                    self.on_step(t, h_try)
            if cur is not u:
                u[...] = cur
            self._dt = h
            self.info["dt_last"] = h
            return t

        return stepper
