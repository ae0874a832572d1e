r"""The fast py-pde solver: adaptive second-order exponential time differencing (ETDRK2).

Scheme (Cox & Matthews 2002, J. Comput. Phys. 176, 430, Eq. 22 "ETD2RK"): split each field's
rate into a stiff linear part, diagonal in Fourier space, and the rest N,

.. math::
    \dot{\hat q} = L_q \hat q + \hat N_q, \quad L_q = -(A_0 + K k^2)/\gamma, \qquad
    \dot{\hat A} = L_A \hat A + \hat N_A, \quad L_A = -\zeta / \tau ,

so the Frank term and the linear decays are integrated exactly. One step of size h:

.. math::
    \hat a = e^{L h} \hat u_n + h\, \varphi_1(L h)\, \hat N(u_n), \qquad
    \hat u_{n+1} = \hat a + h\, \varphi_2(L h)\, \big(\hat N(a) - \hat N(u_n)\big),

with :math:`\varphi_1(z) = (e^z - 1)/z`, :math:`\varphi_2(z) = (e^z - 1 - z)/z^2`. The
difference between the first-order ETD1 predictor ``a`` and ``u_{n+1}`` is the local error
estimate (RMS over the grid, maximum over the three fields); the step is accepted if it is
below ``numerics.tolerance`` and the next step is scaled by
:math:`0.9\,(\mathrm{tol}/\mathrm{err})^{1/2}` (clipped to [0.2, 2] and ``dt_max``).
``adaptive = False`` gives the plain fixed-step ETDRK2 (second order, tested).

In linear mechanics the Jaumann spin is computed with the spectral symbol of
:meth:`model.mechanics.LinearMechanics.spin_multiplier`, reusing the transforms the step needs
anyway; finite mechanics uses the generic :meth:`ActiveNematicPDE.rates` path with the
displacement-rate solve, and warm-starts Newton with :math:`\tilde u_n + h \dot{\tilde u}_n`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
from pde.solvers.base import SolverBase

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
        self.L = np.stack([-(p.A0 + p.K * g.k2) / p.gamma, -(p.A0 + p.K * g.k2) / p.gamma,
                           np.full(g.k2.shape, -p.zeta / p.tau)])
        self._phi_cache: dict[float, tuple[Array, Array, Array]] = {}
        self.on_step: Callable[[float, float], None] | None = None
        self.stats = {"steps": 0, "rejected": 0, "rhs": 0, "newton": 0}

    # --- the split right-hand side -----------------------------------------------------
    def nonlinear_hat(self, u: Array, u_hat: Array, t: float) -> Array:
        """:math:`\\hat N(u) = \\widehat{\\dot u} - L \\hat u` for the state ``u = [q1, q2, A]``."""
        self.stats["rhs"] += 1
        eq = self.pde
        g = eq.spectral
        mech_model = eq.mechanics
        if isinstance(mech_model, LinearMechanics):
            return self._nonlinear_hat_linear(u, u_hat, t)
        rate, mech, _ = eq.rates(u[0], u[1], u[2], t)
        self.stats["newton"] += mech.iterations
        if not np.all(np.isfinite(rate)):
            raise SimulationFailure("nan", "non-finite rate", t)
        return g.forward(rate) - self.L * u_hat

    def _nonlinear_hat_linear(self, u: Array, u_hat: Array, t: float) -> Array:
        """Linear-mechanics fast path: every linear map of q stays in Fourier space."""
        eq = self.pde
        p, g, mech = eq.params, eq.spectral, eq.mechanics
        assert isinstance(mech, LinearMechanics)
        q1, q2, A = u
        QQ = 2.0 * (q1**2 + q2**2)
        QQ_hat = g.forward(QQ) if p.B_prime else None
        dev_hat, tr_e_hat, tr_sigma_hat = mech.spectral_response(u_hat[:2], QQ_hat)
        if p.B_prime:
            tr_e, tr_sigma = g.inverse(np.stack([tr_e_hat, tr_sigma_hat]))
            bulk_nl = A + p.C * QQ - 2.0 * p.B_prime * tr_e
        else:
            tr_sigma = g.inverse(tr_sigma_hat)
            bulk_nl = A + p.C * QQ
        H_hat = g.forward(np.stack([-bulk_nl * q1, -bulk_nl * q2])) + p.B * dev_hat
        R_hat = H_hat / p.gamma + self.L[:2] * u_hat[:2]  # H / gamma, full
        qdot_hat, _ = mech.corotational_hat(q1, q2, R_hat, t)
        N_hat = np.empty_like(u_hat)
        N_hat[:2] = qdot_hat - self.L[:2] * u_hat[:2]
        N_hat[2] = g.forward((-p.chi * tr_sigma - p.s * A**3) / p.tau)
        return N_hat

    # --- one step ----------------------------------------------------------------------
    def _phis(self, h: float) -> tuple[Array, Array, Array]:
        """exp(Lh), phi1(Lh), phi2(Lh), cached per step size (q1 and q2 share one array;
        the activity's L is a constant)."""
        cached = self._phi_cache.get(h)
        if cached is None:
            Eq, p1q, p2q = phi_functions(self.L[0] * h)
            Ea, p1a, p2a = phi_functions(self.L[2, 0, 0] * h)
            cached = (np.stack([Eq, Eq, np.full_like(Eq, Ea)]),
                      np.stack([p1q, p1q, np.full_like(p1q, p1a)]),
                      np.stack([p2q, p2q, np.full_like(p2q, p2a)]))
            if len(self._phi_cache) > 32:
                self._phi_cache.clear()
            self._phi_cache[h] = cached
        return cached

    def step(self, u: Array, t: float, h: float) -> tuple[Array, Array, float]:
        """One ETDRK2 step; returns (new state, N(u) hat, error estimate)."""
        g = self.pde.spectral
        mech = self.pde.mechanics
        u_hat = g.forward(u)
        finite = mech if isinstance(mech, FiniteMechanics) else None
        N0_hat = self.nonlinear_hat(u, u_hat, t)
        if finite is not None:
            u0, udot0 = finite.u_hat.copy(), finite.udot_hat.copy()
        E, phi1, phi2 = self._phis(h)
        a_hat = E * u_hat + h * phi1 * N0_hat
        a = g.inverse(a_hat)
        if finite is not None:
            finite.u_hat = u0 + h * udot0  # first-order predictor of the displacement
        try:
            Na_hat = self.nonlinear_hat(a, a_hat, t + h)
        except SimulationFailure:
            if finite is not None:
                finite.u_hat, finite.udot_hat = u0, udot0
            raise
        corr = h * phi2 * (Na_hat - N0_hat)
        new = g.inverse(a_hat + corr)
        err = max(g.rms_hat(corr[i]) for i in range(3))
        if finite is not None:
            self._finite_restore = (u0, udot0)
        return new, N0_hat, err

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
                new, _, err = self.step(u, t, h_try)
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
