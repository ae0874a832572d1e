r"""Finite-strain force balance (paper Eq. 3): neo-Hookean + nemato-elastic (the exact
derivative of Eq. 1), Newton-Krylov on :math:`\tilde u` in Fourier space.

Each Newton step solves :math:`-\mathrm{Div}(\mathbb K : \nabla \delta u) = \mathrm{Div}\, P` by
conjugate gradients, preconditioned by the exact Green operator of the homogeneous isotropic
reference medium (so a small-strain step converges in one iteration), warm-started, with a
backtracking line search that keeps :math:`J > 0` and decreases the residual. The spin of
Eq. (4) comes with the displacement rate :math:`\dot u` of the linearised balance, by GMRES
(:meth:`FiniteMechanics.corotational`).
"""

from __future__ import annotations

import numpy as np

from .. import constitutive as cl
from .. import krylov
from .. import tensors as T
from .. import wellposedness as wp
from ..compiled import finite_krylov
from ..errors import SimulationFailure
from ..fourier import SpectralGrid
from ..parameters import Parameters
from .base import MechanicalState, Mechanics

Array = np.ndarray


class FiniteMechanics(Mechanics):
    """Finite-strain force balance by Newton-Krylov (see the module docstring)."""

    def __init__(
        self,
        params: Parameters,
        grid: SpectralGrid,
        *,
        tol: float = 1e-8,
        max_newton: int = 30,
        cg_rtol: float = 0.1,
        max_cg: int = 200,
        spin_tol: float = 1e-8,
        backend: str = "compiled",
        integrated: bool = True,
    ):
        super().__init__(params, grid, spin_tol=spin_tol, backend=backend)
        self.integrated = integrated
        self.tol = tol
        self.max_newton = max_newton
        self.cg_rtol = cg_rtol
        self.max_cg = max_cg
        k = params.kappa
        self._a = k / (k + 1.0)  # reference medium: mu0 = 1, kappa0 = kappa
        n = grid.n
        self.u_hat = np.zeros((2, n, n // 2 + 1), dtype=complex)  # warm start
        self.udot_hat = np.zeros_like(self.u_hat)
        self.udot_grad = np.zeros((2, 2, n, n))
        self._checkpoint: tuple[Array, Array, Array] | None = None
        self._weights = grid.weights / n**2  # Parseval weights of the half spectrum
        self._workspace: tuple[Array, Array, Array] | None = None
        self.fft_parts.update(rate_solve=0, newton_cg=0, force_balance=0)
        #: (u_hat, q1, q2, F, P) of the last converged solve, which :meth:`state_at` reuses
        #: when asked for the same displacement and order (the first stage after a projection)
        self._solution: tuple[Array, Array, Array, Array, Array] | None = None

    def set_parameters(self, params: Parameters, rates: dict[str, float]) -> None:
        super().set_parameters(params, rates)
        self._solution = None  # its stress is of the constants before

    def checkpoint(self) -> None:
        # the rate's gradient is replaced, never written in place: kept as it is
        self._checkpoint = (self.u_hat.copy(), self.udot_hat.copy(), self.udot_grad)

    def restore(self) -> None:
        if self._checkpoint is not None:
            self.u_hat, self.udot_hat, self.udot_grad = self._checkpoint

    def predict(self, dt: float) -> None:
        self.u_hat = self.u_hat + dt * self.udot_hat

    def saved_state(self) -> dict[str, Array]:
        """The displacement (warm start or integrated), its rate and the rate's gradient."""
        return {
            "u_hat": self.u_hat.copy(),
            "udot_hat": self.udot_hat.copy(),
            "udot_grad": self.udot_grad.copy(),
        }

    def resume(self, arrays: dict[str, Array], q1: Array, q2: Array) -> None:
        """Take back :meth:`saved_state`, taken right after the save's solve: its solution
        (F and P of ``u_hat`` at this order, which :meth:`state_at` reuses in the next step)
        is evaluated again, a pure function of them (F from ``u_hat``: the save's solve had
        no F guess), so the next step starts from bitwise the same data."""
        self.u_hat = np.array(arrays["u_hat"], dtype=complex)
        self.udot_hat = np.array(arrays["udot_hat"], dtype=complex)
        self.udot_grad = np.array(arrays["udot_grad"], dtype=float)
        F, P, _, _ = self._evaluate(self.u_hat, q1, q2)
        self._solution = (self.u_hat, q1.copy(), q2.copy(), F, P)

    def _tangent(self, F: Array, q1: Array, q2: Array) -> Array:
        """The tangent dP/dF (the backend's ``tangent_kernel``)."""
        m = self.moduli
        return self.k.tangent_kernel(
            np.ascontiguousarray(F),
            np.ascontiguousarray(q1),
            np.ascontiguousarray(q2),
            m.kappa,
            m.B,
            m.B_prime,
            m.alpha,
        )

    def deformation(self, u_hat: Array) -> Array:
        """:math:`F = \\bar F + \\nabla u` from the spectrum ``u_hat`` (four transforms)."""
        g = self.grid
        F = g.inverse(self.k.grad_hat_kernel(u_hat, g.kx, g.ky))
        F[0, 0] += self.Fbar[0, 0]  # F-bar is diagonal
        F[1, 1] += self.Fbar[1, 1]
        return F

    def _operator(self, K: Array):
        g = self.grid

        def A(v_hat: Array) -> Array:
            k = self.k
            dF = g.inverse(k.grad_hat_kernel(v_hat, g.kx, g.ky))
            return k.neg_div_hat_kernel(g.forward(k.apply_tangent_kernel(K, dF)), g.kx, g.ky)

        return A

    def _pcg(self, K: Array, b_hat: Array, rtol: float) -> tuple[Array, int, bool]:
        """Newton's correction from zero: compiled (:func:`nematic_solids.model.finite_krylov.pcg`)
        or the numpy reference (:func:`nematic_solids.model.krylov.pcg` on :meth:`_operator`)."""
        g = self.grid
        x0 = np.zeros_like(b_hat)
        if self.compiled:
            assert g.fft.plans is not None
            x, it, code, nop = finite_krylov.pcg(
                K,
                b_hat,
                x0,
                g.kx,
                g.ky,
                self._khat[0],
                self._khat[1],
                self._inv_k2,
                self._a,
                self._weights,
                *g.fft.plans,
                rtol,
                self.max_cg,
            )
            g.fft.count += 8 * nop
            return x, it, code == 0
        x, it, status = krylov.pcg(
            self._operator(K),
            b_hat,
            x0,
            lambda r: self._green(r, self._a),
            g.inner,
            rtol=rtol,
            maxiter=self.max_cg,
        )
        return x, it, status == "ok"

    def _udot_gmres(self, K: Array, E: Array, b: Array) -> tuple[Array, Array, int, bool]:
        """The displacement-rate solve, warm-started from the last rate :attr:`udot_hat`:
        ``(udot_hat, its real-space gradient, iterations, converged)``, compiled
        (:func:`nematic_solids.model.compiled.finite_krylov.gmres`) or the numpy reference
        (:func:`nematic_solids.model.krylov.gmres_aux`); the gradient comes with the operator
        applications (no transform of its own), and the start's residual uses the start's gradient
        :attr:`udot_grad` (four transforms instead of eight)."""
        g = self.grid
        if self.compiled:
            assert g.fft.plans is not None
            if self._workspace is None:
                self._workspace = finite_krylov.workspace(g.n)
            x, grad, it, ok, nop, naux = finite_krylov.gmres(
                K,
                E,
                b,
                self.udot_hat,
                self.udot_grad,
                g.kx,
                g.ky,
                self._khat[0],
                self._khat[1],
                self._inv_k2,
                self._a,
                self._weights,
                *g.fft.plans,
                self.spin_tol,
                self.max_cg,
                *self._workspace,
            )
            g.fft.count += 8 * nop + 4 * naux
            return x, grad, it, ok

        def of_gradient(G: Array) -> Array:
            k = self.k
            return k.neg_div_hat_kernel(g.forward(k.apply_tangent_spin_kernel(K, G, E)), g.kx, g.ky)

        def A(v_hat: Array) -> tuple[Array, Array]:
            G = g.inverse(self.k.grad_hat_kernel(v_hat, g.kx, g.ky))
            return of_gradient(G), G

        x, it, status, grad = krylov.gmres_aux(
            A,
            b,
            self.udot_hat,
            lambda r: self._green(r, self._a),
            g.inner,
            rtol=self.spin_tol,
            maxiter=self.max_cg,
            Lx0=self.udot_grad,
            op_given_aux=lambda v, G: of_gradient(G),
        )
        return x, grad, it, status == "ok"

    def _evaluate(
        self, u_hat: Array, q1: Array, q2: Array, F: Array | None = None
    ) -> tuple[Array, Array, Array, float]:
        """``(F, P, P_hat, residual)`` at ``u_hat`` (deformation ``F`` if known); an infinite
        residual where J <= 0."""
        count = self.grid.fft.count
        if F is None:
            F = self.deformation(u_hat)
        J = T.det(F)
        if not np.all(J > 0):
            self.fft_parts["force_balance"] += self.grid.fft.count - count
            return F, F, F, np.inf
        m = self.moduli
        P = self.k.first_piola_kernel(F, q1, q2, m.kappa, m.B, m.B_prime, m.alpha)
        P_hat = self.grid.forward(P)
        self.fft_parts["force_balance"] += self.grid.fft.count - count
        return F, P, P_hat, self.residual(P, P_hat)

    def solve(
        self,
        q1: Array,
        q2: Array,
        *,
        u_guess: Array | None = None,
        t: float | None = None,
        F_guess: Array | None = None,
    ) -> MechanicalState:
        u_hat = self.u_hat if u_guess is None else u_guess
        F, P, P_hat, res = self._evaluate(u_hat, q1, q2, F_guess)
        if not np.isfinite(res):  # the guess is unusable: restart from the homogeneous state
            u_hat = np.zeros_like(u_hat)
            F, P, P_hat, res = self._evaluate(u_hat, q1, q2)
            if not np.isfinite(res):
                raise SimulationFailure("J<=0", "the applied deformation has J <= 0", t)
        it = 0
        K = None
        while res > self.tol:
            if it >= self.max_newton:
                raise SimulationFailure(
                    "newton_diverged",
                    f"force balance not converged after {it} Newton iterations "
                    f"(residual {res:.3g} > {self.tol:g})",
                    t,
                )
            it += 1
            K = self._tangent(F, q1, q2)
            b = self.grid.div_hat(P_hat)
            # inexact Newton: ask CG for just the reduction this step needs (one step from
            # a residual near tol, as in the projection of an integrated displacement, needs
            # little: a cap of cg_rtol = 0.1 instead of 1e-3 halves its CG work, measured)
            rtol = float(np.clip(0.5 * self.tol / res, 1e-8, self.cg_rtol))
            count = self.grid.fft.count
            du, ncg, ok = self._pcg(K, b, rtol)
            self.fft_parts["newton_cg"] += self.grid.fft.count - count
            self.cg_iterations += ncg
            if not ok and ncg < self.max_cg:
                raise SimulationFailure(
                    "ellipticity_lost",
                    "the tangent stiffness is not positive definite (loss of ellipticity)",
                    t,
                )
            step = 1.0
            for _ in range(12):
                trial = u_hat + step * du
                F_t, P_t, P_hat_t, res_t = self._evaluate(trial, q1, q2)
                if np.isfinite(res_t) and res_t < res:
                    break
                step *= 0.5
            else:
                reason = "J<=0" if not np.isfinite(res_t) else "newton_diverged"
                raise SimulationFailure(
                    reason, f"line search failed at Newton iteration {it} (residual {res:.3g})", t
                )
            u_hat, F, P, P_hat, res = trial, F_t, P_t, P_hat_t, res_t
        self.u_hat = u_hat
        self._solution = (u_hat, q1.copy(), q2.copy(), F, P)
        return self._state(F, P, u_hat, iterations=it, residual=res, K=K)

    def _state(
        self,
        F: Array,
        P: Array,
        u_hat: Array,
        *,
        iterations: int = 0,
        residual: float = float("nan"),
        K: Array | None = None,
    ) -> MechanicalState:
        """The :class:`MechanicalState` of the deformation ``F`` with stress ``P`` (its
        strain measures by the backend's ``strain_measures_kernel``)."""
        Ebar_dev, Jm1, trP = self.k.strain_measures_kernel(
            np.ascontiguousarray(F), np.ascontiguousarray(P)
        )
        trS = None
        if self.params.coupling == "trS":
            trS = cl.second_piola_trace(F, P)
        return MechanicalState(
            F=F,
            P=P,
            Ebar_dev=Ebar_dev,
            Jm1=Jm1,
            trP=trP,
            trS=trS,
            u_hat=u_hat,
            iterations=iterations,
            residual=residual,
            tangent=K,
        )

    def state_at(
        self, u_hat: Array, q1: Array, q2: Array, t: float | None = None, F: Array | None = None
    ) -> MechanicalState:
        """The mechanical state at the displacement ``u_hat`` as given, without solving the
        force balance (the stages of the integrated-displacement scheme, where u is part of
        the integrated state: docs/model/numerics.md), with the deformation gradient ``F``
        if given (else from ``u_hat``). Its ``residual`` is not computed (NaN). Raises
        ``J<=0`` where the deformation folds. The deformation and stress of the last solve
        are reused when ``u_hat`` is its solution for the same q."""
        sol = self._solution
        if (
            sol is not None
            and u_hat is sol[0]
            and np.array_equal(q1, sol[1])
            and np.array_equal(q2, sol[2])
        ):
            return self._state(sol[3], sol[4], u_hat)
        if F is None:
            F = self.deformation(u_hat)
        m = self.moduli
        P = self.k.first_piola_kernel(F, q1, q2, m.kappa, m.B, m.B_prime, m.alpha)
        state = self._state(F, P, u_hat)
        if not state.Jm1.min() > -1.0:  # J <= 0 somewhere (or not finite): P is meaningless
            raise SimulationFailure("J<=0", "the integrated displacement has J <= 0", t)
        return state

    def deformation_of(self, u_hat: Array) -> Array:
        """F of ``u_hat``: the last solve's when ``u_hat`` is its solution, else transformed."""
        sol = self._solution
        return sol[3] if sol is not None and u_hat is sol[0] else self.deformation(u_hat)

    def corotational(
        self, mech: MechanicalState, q1: Array, q2: Array, R: Array, t: float | None = None
    ) -> tuple[Array, Array]:
        r"""Solve for :math:`\dot u` and :math:`\dot Q = R + 2\omega J q` together:

        .. math::
            -\mathrm{Div}\big(\mathbb K : \nabla \dot u + E\, \omega(\dot u)\big)
            = \mathrm{Div}(\partial_Q P : R + \dot\alpha F Q + \mathbb K : \dot{\bar F}),
            \qquad E = \partial_Q P : (2 J q),
            \quad \omega(\dot u) = \tfrac12 (\partial_1 \dot u_2 - \partial_2 \dot u_1),

        by GMRES (Green-preconditioned, warm-started), with the rates of alpha and of the
        applied shear under a protocol (:mod:`nematic_solids.model.protocol`; zero otherwise).
        Returns ``(Qdot components, omega)``.
        """
        g, m = self.grid, self.moduli
        K = mech.tangent
        if K is None:
            K = self._tangent(mech.F, q1, q2)
            mech.tangent = K
        F = np.ascontiguousarray(mech.F)
        E = self.k.q_increment_kernel(F, q1, q2, -2.0 * q2, 2.0 * q1, m.B, m.B_prime, m.alpha)
        mech.spin_coupling = E
        dP = self.k.q_increment_kernel(
            F,
            q1,
            q2,
            np.ascontiguousarray(R[0]),
            np.ascontiguousarray(R[1]),
            m.B,
            m.B_prime,
            m.alpha,
        )
        if self.alpha_rate != 0.0:  # dP/dalpha = F Q (the active term of Eq. 2)
            dP = dP + self.alpha_rate * self.k.q_increment_kernel(F, q1, q2, q1, q2, 0.0, 0.0, 1.0)
        if self.eps_rate != 0.0:  # the applied shear's rate, K : d(F bar)/dt
            dFbar = np.zeros((2, 2) + q1.shape)
            dFbar[0, 0], dFbar[1, 1] = self.eps_rate, -self.eps_rate
            dP = dP + self.k.apply_tangent_kernel(K, dFbar)
        b = self.k.div_hat_kernel(g.forward(dP), g.kx, g.ky)

        count = g.fft.count
        udot, grad, it, ok = self._udot_gmres(K, E, b)
        self.fft_parts["rate_solve"] += g.fft.count - count
        self.spin_iterations += it
        if not ok:
            raise SimulationFailure(
                "spin_diverged",
                "the displacement-rate (Jaumann spin) solve did not converge "
                f"in {it} iterations: loss of ellipticity",
                t,
            )
        self.udot_hat = udot
        self.udot_grad = grad
        return self.k.corotational_rate(R, grad, q1, q2)

    def rate_margin(
        self, q1: Array, q2: Array, mech: MechanicalState | None = None
    ) -> tuple[float, int, float]:
        """Well-posedness margin of the rate problem at the deformation of ``mech`` (solved
        here if not given), its flat grid index and the wave-vector angle of the minimum
        (:func:`nematic_solids.model.wellposedness.finite_margin`; reuses the tangent and E of
        :meth:`corotational` when ``mech`` has them)."""
        m = self.moduli
        if mech is None:
            mech = self.solve(q1, q2)
        K = mech.tangent
        if K is None:
            K = self._tangent(mech.F, q1, q2)
        E = mech.spin_coupling
        if E is None:
            E = self.k.q_increment_kernel(
                np.ascontiguousarray(mech.F), q1, q2, -2.0 * q2, 2.0 * q1, m.B, m.B_prime, m.alpha
            )
        return wp.finite_margin(K, E, m.kappa, samples=self.k.finite_margin_kernel)
