r"""The fast py-pde solver: adaptive second-order exponential time differencing (ETDRK2).

Scheme (Cox & Matthews 2002, J. Comput. Phys. 176, 430, Eq. 22 "ETD2RK"): split each field's
rate into a stiff linear part and the rest N,

.. math::
    \dot{\hat q} = L_q \hat q + \hat N_q, \quad L_q = -(A_0 + K k^2)/\gamma, \qquad
    \dot A = L_A A + N_A, \quad L_A(x) = -(\zeta + 3 s A_n(x)^2)/\tau ,

so the Frank term and the linear decay of Q are integrated exactly in Fourier space, and the
local cubic of Eq. (5) (stiff once a pattern has formed: :math:`3 s A^2 \sim 25`) with its
pointwise Jacobian frozen at the start of the step (an exponential Rosenbrock-type splitting,
in real space: the split is exact for any frozen L, so the order stays two). One step of size h:

.. math::
    a = e^{L h} u_n + h\, \varphi_1(L h)\, N(u_n), \qquad
    u_{n+1} = a + h\, \varphi_2(L h)\, \big(N(a) - N(u_n)\big),

with :math:`\varphi_1(z) = (e^z - 1)/z`, :math:`\varphi_2(z) = (e^z - 1 - z)/z^2`. The
difference between the first-order ETD1 predictor ``a`` and ``u_{n+1}`` is the local error
estimate (RMS over the grid, maximum over the three fields); the step is accepted if it is
below ``numerics.tolerance`` and the next step is scaled by
:math:`0.9\,(\mathrm{tol}/\mathrm{err})^{1/2}` (clipped to [0.2, 2] and ``dt_max``).
``adaptive = False`` gives the plain fixed-step ETDRK2 (second order, tested).

In linear mechanics the Jaumann spin is computed with the spectral symbol of
:meth:`model.mechanics.LinearMechanics.spin_multiplier`, reusing the transforms the step needs
anyway, and the pointwise algebra runs in the numba kernels of :mod:`model.kernels`; finite
mechanics uses the generic :meth:`ActiveNematicPDE.rates` path with the displacement-rate solve,
and warm-starts Newton with :math:`\tilde u_n + h \dot{\tilde u}_n`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
from pde.solvers.base import SolverBase

from . import kernels as kern
from .errors import SimulationFailure
from .mechanics import FiniteMechanics, LinearMechanics
from .pde import ActiveNematicPDE

log = logging.getLogger(__name__)
Array = np.ndarray


def phi_functions(z: Array) -> tuple[Array, Array, Array]:
    """:math:`e^z, \\varphi_1(z), \\varphi_2(z)`, with Taylor series for small ``|z|``."""
    z = np.asarray(z, dtype=float)
    ez = np.exp(z)
    small = np.abs(z) < 1e-3
    zs = np.where(small, 1.0, z)
    phi1 = np.where(small, 1 + z / 2 + z**2 / 6 + z**3 / 24, np.expm1(zs) / zs)
    phi2 = np.where(small, 0.5 + z / 6 + z**2 / 24 + z**3 / 120, (np.expm1(zs) - zs) / zs**2)
    return ez, phi1, phi2


class ETDRK2Solver(SolverBase):
    """Adaptive ETDRK2 for :class:`ActiveNematicPDE` (see module docstring)."""

    name = "etdrk2"
    dt_min = 1e-7

    def __init__(self, pde: ActiveNematicPDE, *, backend: str = "numpy",
                 adaptive: bool | None = None, tolerance: float | None = None,
                 dt_max: float | None = None):
        super().__init__(pde, backend=backend)
        self.pde: ActiveNematicPDE = pde
        num = pde.numerics
        self.adaptive = num.adaptive if adaptive is None else adaptive
        self.tolerance = num.tolerance if tolerance is None else tolerance
        self.dt_max = num.dt_max if dt_max is None else dt_max
        p, g = pde.params, pde.spectral
        self.Lq = -(p.A0 + p.K * g.k2) / p.gamma  # the q1, q2 symbol (Fourier space)
        self._zeros = np.zeros((g.n, g.n))
        self._known: list[tuple[Array, Array]] = []
        self._phi_cache: dict[float, tuple[Array, Array, Array]] = {}
        self.on_step: Callable[[float, float], None] | None = None
        self.stats = {"steps": 0, "rejected": 0, "rhs": 0, "newton": 0}

    # --- the split right-hand side -----------------------------------------------------
    def split(self, u: Array, q_hat: Array, t: float) -> tuple[Array, Array]:
        """Return ``(N_q hat, Adot)`` for the state ``u = [q1, q2, A]`` with ``q_hat`` the
        spectra of q1, q2: :math:`\\hat N_q = \\widehat{\\dot q} - L_q \\hat q` in Fourier space,
        and the full activity rate (Eq. 5) in real space."""
        self.stats["rhs"] += 1
        eq = self.pde
        g = eq.spectral
        if isinstance(eq.mechanics, LinearMechanics):
            return self._split_linear(u, q_hat, t)
        rate, mech, _ = eq.rates(u[0], u[1], u[2], t)
        self.stats["newton"] += mech.iterations
        if not np.all(np.isfinite(rate)):
            raise SimulationFailure("nan", "non-finite rate", t)
        return g.forward(rate[:2]) - self.Lq * q_hat, rate[2]

    def _split_linear(self, u: Array, q_hat: Array, t: float) -> tuple[Array, Array]:
        """Linear-mechanics fast path: every linear map of q stays in Fourier space."""
        eq = self.pde
        p, g, mech = eq.params, eq.spectral, eq.mechanics
        assert isinstance(mech, LinearMechanics)
        q1, q2, A = u
        QQ_hat = g.forward(2.0 * (q1**2 + q2**2)) if p.B_prime else None
        dev_hat, tr_e_hat, tr_sigma_hat = mech.spectral_response(q_hat, QQ_hat)
        if p.B_prime:
            tr_e, tr_sigma = g.inverse(np.stack([tr_e_hat, tr_sigma_hat]))
        else:
            tr_e, tr_sigma = self._zeros, g.inverse(tr_sigma_hat)
        H_hat = g.forward(kern.bulk_terms(q1, q2, A, tr_e, p.C, 2.0 * p.B_prime)) + p.B * dev_hat
        Lq_hat = self.Lq * q_hat
        R_hat = H_hat
        R_hat /= p.gamma
        R_hat += Lq_hat  # H / gamma, full
        qdot_hat = mech.corotational_hat(q1, q2, R_hat, t)  # R + 2 omega J q
        qdot_hat -= Lq_hat
        Adot = kern.activity_rate(A, tr_sigma, p.zeta, p.chi, p.s, p.tau)
        return qdot_hat, Adot

    def full_rate(self, u: Array, t: float = 0.0) -> Array:
        """:math:`\\dot u` assembled from the split (equals ``pde.evolution_rate``; tested)."""
        g = self.pde.spectral
        q_hat = g.forward(u[:2])
        Nq, Adot = self.split(u, q_hat, t)
        return np.concatenate([g.inverse(self.Lq * q_hat + Nq), Adot[None]])

    # --- one step ----------------------------------------------------------------------
    def _phis(self, h: float) -> tuple[Array, Array, Array]:
        """exp(L_q h), phi1(L_q h), phi2(L_q h), cached per step size (q1 and q2 share them)."""
        cached = self._phi_cache.get(h)
        if cached is None:
            cached = phi_functions(self.Lq * h)
            if len(self._phi_cache) > 32:
                self._phi_cache.clear()
            self._phi_cache[h] = cached
        return cached

    def _spectrum(self, q: Array) -> Array:
        """The spectra of q1, q2, reused when ``q`` is the state the last step started from
        (a rejected step) or produced (the next step): saves two transforms per step."""
        for real, hat in self._known:
            if np.array_equal(real, q):
                return hat
        return self.pde.spectral.forward(q)

    def step(self, u: Array, t: float, h: float) -> tuple[Array, float]:
        """One ETDRK2 step; returns (new state, error estimate)."""
        g = self.pde.spectral
        mech = self.pde.mechanics
        q_hat = self._spectrum(u[:2])
        A = u[2]
        finite = mech if isinstance(mech, FiniteMechanics) else None
        Nq0, Adot0 = self.split(u, q_hat, t)
        if finite is not None:
            u0, udot0 = finite.u_hat.copy(), finite.udot_hat.copy()
        E, phi1, phi2 = self._phis(h)
        p = self.pde.params
        LA, phi1A, phi2A = kern.activity_exponential(A, h, p.zeta, p.s, p.tau)
        aq_hat = E * q_hat + h * phi1 * Nq0
        aA = A + h * phi1A * Adot0  # = e^{L h} A + h phi1 (Adot - L A)
        a = np.concatenate([g.inverse(aq_hat), aA[None]])
        if finite is not None:
            finite.u_hat = u0 + h * udot0  # first-order predictor of the displacement
        try:
            Nqa, Adota = self.split(a, aq_hat, t + h)
        except SimulationFailure:
            if finite is not None:
                finite.u_hat, finite.udot_hat = u0, udot0
            raise
        corr_q = h * phi2 * (Nqa - Nq0)
        corr_A = h * phi2A * (Adota - Adot0 - LA * (aA - A))
        new_q_hat = aq_hat + corr_q
        new = np.concatenate([g.inverse(new_q_hat), (aA + corr_A)[None]])
        self._known = [(u[:2].copy(), q_hat), (new[:2], new_q_hat)]
        err = max(g.rms_hat(corr_q[0]), g.rms_hat(corr_q[1]),
                  float(np.sqrt(np.mean(corr_A**2))))
        if finite is not None:
            self._finite_restore = (u0, udot0)
        return new, err

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
                new, err = self.step(u, t, h_try)
                if not np.all(np.isfinite(new)):
                    raise SimulationFailure("nan", "non-finite state after a step", t)
                if self.adaptive:
                    fac = 2.0 if err == 0 else float(np.clip(0.9 * np.sqrt(self.tolerance / err),
                                                             0.2, 2.0))
                    if err > self.tolerance:
                        self.stats["rejected"] += 1
                        mech = self.pde.mechanics
                        if isinstance(mech, FiniteMechanics):
                            mech.u_hat, mech.udot_hat = self._finite_restore
                        h = self._quantize(h_try * fac)
                        if h < self.dt_min:
                            raise SimulationFailure(
                                "step_size_collapsed",
                                f"adaptive time step fell below {self.dt_min:g}", t)
                        continue
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
