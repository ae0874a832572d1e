r"""Quasi-static force balance :math:`\mathrm{Div}\, P = 0` (paper Eq. 3) on the periodic square.

The deformation is :math:`F = \bar F + \nabla \tilde u` with a periodic fluctuation
:math:`\tilde u` and the applied pure shear :math:`\bar F = \mathrm{diag}(1+\epsilon, 1-\epsilon)`
(the paper's :math:`\epsilon_{11} = \epsilon = -\epsilon_{22}`; at small strain the mean
displacement gradient is exactly that).

Two solvers share one interface, :class:`Mechanics` (what the time stepper and the PDE call:
:meth:`~Mechanics.solve`, :meth:`~Mechanics.state_at`, :meth:`~Mechanics.corotational`,
:meth:`~Mechanics.rate_margin`, and the warm start's :meth:`~Mechanics.checkpoint`,
:meth:`~Mechanics.restore`, :meth:`~Mechanics.predict`):

* :class:`LinearMechanics`: small strain, one exact Fourier solve with the Green operator of
  the isotropic medium (shear modulus 1, 2-D bulk modulus kappa, or incompressible by
  projection).
* :class:`FiniteMechanics`: neo-Hookean + nemato-elastic (exact derivative of Eq. 1),
  Newton-Krylov on :math:`\tilde u` in Fourier space. Each Newton step solves
  :math:`-\mathrm{Div}(\mathbb K : \nabla \delta u) = \mathrm{Div}\, P` by conjugate gradients,
  preconditioned by the exact Green operator of the homogeneous isotropic reference medium
  (so a small-strain step converges in one iteration), warm-started, with a backtracking line
  search that keeps :math:`J > 0` and decreases the residual.

**Residual.** :math:`r = \lVert \hat k_J \hat P_{iJ} \rVert / \max(1, \lVert P \rVert)`: the RMS
of :math:`\mathrm{Div}\,P` in the :math:`H^{-1}` norm (so high wavenumbers are not amplified),
relative to the RMS stress with the shear modulus G = 1 as a floor.

**Spin.** The Jaumann derivative of Eq. (4) needs :math:`W = \operatorname{skew} \nabla \dot u`.
Since u is slaved to Q, :math:`\dot u` solves the linearised balance
:math:`\mathrm{Div}(\mathbb K : \nabla \dot u + \partial_Q P : \dot Q) = 0` (an extra linear
solve: exact, no lagged difference). :meth:`spin` returns
:math:`\omega = \tfrac12 (\partial_1 \dot u_2 - \partial_2 \dot u_1)` for a given
:math:`\dot Q`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from . import constitutive as cl
from . import krylov
from . import tensors as T
from . import wellposedness as wp
from .backend import kernels
from .compiled import finite_krylov
from .errors import SimulationFailure
from .fourier import SpectralGrid

log = logging.getLogger(__name__)
Array = np.ndarray


@dataclass
class MechanicalState:
    """Everything the Q and A equations and the observables need from the mechanics.

    ``Ebar_dev`` holds the two independent components ((E11 - E22)/2, E12) of the deviatoric
    part of :math:`\\bar E = \\tfrac12 (J^{-1} C - I)` (small strain: of e), ``Jm1`` is
    :math:`J - 1` as it enters :math:`B'` (small strain: tr e), ``trP`` is
    :math:`P_{11} + P_{22}` (Eq. 5).
    """

    F: Array
    P: Array
    Ebar_dev: Array
    Jm1: Array
    trP: Array
    u_hat: Array
    iterations: int = 0
    residual: float = 0.0
    extras: dict = field(default_factory=dict)


def applied_deformation(eps: float) -> Array:
    """The mean deformation gradient :math:`\\bar F = \\mathrm{diag}(1+\\epsilon, 1-\\epsilon)`."""
    return np.array([[1.0 + eps, 0.0], [0.0, 1.0 - eps]])


class Mechanics:
    """The interface the solver and the PDE call; the base of both mechanics.

    ``backend`` ("compiled" or "numpy", from ``Numerics.backend``) chooses the compiled
    Krylov solves where native FFTW is available (:attr:`compiled`); the numpy path is their
    reference. ``integrated`` is True when the displacement is part of the integrated state
    (finite strain with ``Numerics.displacement = "integrated"``): the solver then carries
    :attr:`u_hat` through the stages with its rate :attr:`udot_hat` and projects it with
    :meth:`solve` once per step; it carries the deformation gradient along (in real space,
    from :meth:`deformation_of` and the rate's gradient :attr:`udot_grad`), so a stage needs
    no transform for it.
    """

    #: the displacement is integrated with the state (only finite mechanics can)
    integrated = False
    #: where :attr:`integrated`: the displacement spectrum (Newton's warm start, or the
    #: integrated displacement) and its rate, the solution of the last rate solve
    u_hat: Array
    udot_hat: Array
    #: the real-space gradient (2, 2, N, N) of :attr:`udot_hat`
    udot_grad: Array

    def __init__(self, params, grid: SpectralGrid, *, spin_tol: float = 1e-8,
                 backend: str = "compiled"):
        self.params = params
        self.grid = grid
        self.spin_tol = spin_tol
        #: the pointwise and spectral kernels of the backend (model.backend)
        self.k = kernels(backend)
        #: compiled code runs the Krylov solves (native FFTW available and backend "compiled")
        self.compiled = backend == "compiled" and grid.fft.plans is not None
        self.spin_iterations = 0
        self.cg_iterations = 0  # Newton's CG iterations (finite mechanics only)
        self.omega_hat: Array | None = None
        #: transforms by part of the work (stored with each run as fft_<part>): "saves" the
        #: observables at saved times; finite strain also "rate_solve" (the displacement-rate
        #: GMRES), "newton_cg" (Newton's corrections), "force_balance" (Newton's residuals)
        self.fft_parts: dict[str, int] = {"saves": 0}
        self.moduli = cl.Moduli.from_params(params)
        self.Fbar = applied_deformation(params.eps)
        g = grid
        kh = g.khat
        # Green operator of the isotropic medium (mu = 1, lambda + mu = kappa):
        # [mu k^2 I + (lambda + mu) k k] u = b  ->  u = (I - a khat khat) b / k^2
        self._inv_k2 = np.where(g.active, 1.0 / np.where(g.active, g.kd2, 1.0), 0.0)
        self._khat = kh

    # --- the interface (the defaults: a mechanics without a warm start) ----------------
    def solve(self, q1: Array, q2: Array, *, u_guess: Array | None = None,
              t: float | None = None, F_guess: Array | None = None) -> MechanicalState:
        """The mechanical state in force balance (Eq. 3) for the order q1, q2 (``u_guess``: a
        start for an iterative solve, ``F_guess`` its deformation gradient if known)."""
        raise NotImplementedError

    def state_at(self, u_hat: Array, q1: Array, q2: Array, t: float | None = None,
                 F: Array | None = None) -> MechanicalState:
        """The mechanical state at a given displacement, whose deformation gradient is ``F``
        if given (only where :attr:`integrated`)."""
        raise ValueError(f"{type(self).__name__} does not integrate the displacement")

    def deformation_of(self, u_hat: Array) -> Array:
        """The deformation gradient of the displacement spectrum ``u_hat`` (only where
        :attr:`integrated`)."""
        raise ValueError(f"{type(self).__name__} does not integrate the displacement")

    def corotational(self, mech: MechanicalState, q1: Array, q2: Array, R: Array,
                     t: float | None = None) -> tuple[Array, Array]:
        """``(Qdot components, omega)``: :math:`\\dot Q = R + 2 \\omega J q` with the spin
        slaved to :math:`\\dot Q` (Eq. 4)."""
        raise NotImplementedError

    def rate_margin(self, q1: Array, q2: Array, mech: MechanicalState | None = None
                    ) -> tuple[float, int, float]:
        """The well-posedness margin of the rate problem, its flat grid index and the
        wave-vector angle of the minimum (:mod:`model.wellposedness`)."""
        raise NotImplementedError

    def checkpoint(self) -> None:
        """Remember the warm start (displacement and its rate) at the start of a step."""

    def restore(self) -> None:
        """Put the warm start of the last :meth:`checkpoint` back (a rejected step)."""

    def predict(self, dt: float) -> None:
        """Move Newton's warm start ``dt`` ahead along the displacement rate."""

    # --- shared helpers ----------------------------------------------------------------
    def _green(self, b_hat: Array, a: float) -> Array:
        """:math:`(I - a \\hat k \\hat k) \\hat b / k^2` (the backend's ``green_kernel``)."""
        return self.k.green_kernel(b_hat, self._khat[0], self._khat[1], self._inv_k2, a)

    def residual(self, P: Array, P_hat: Array | None = None) -> float:
        """:math:`\\lVert \\hat k_J \\hat P_{iJ} \\rVert / \\max(1, \\mathrm{RMS}\\, P)`."""
        if P_hat is None:
            P_hat = self.grid.forward(P)
        return float(self.k.balance_residual_kernel(P, P_hat, self._khat[0], self._khat[1],
                                                    self.grid.weights))


class LinearMechanics(Mechanics):
    """Small-strain force balance, solved exactly in Fourier space.

    .. math::
        \\mathrm{Div}\\big(2\\,\\mathrm{dev}\\, e + \\kappa\\, \\mathrm{tr}\\, e\\, I
        + \\tau\\big) = 0, \\quad \\tau = (\\alpha - B) Q - B' (Q:Q) I,
        \\quad \\hat{\\tilde u} = \\frac{1}{k^2}\\Big(I - \\frac{\\kappa}{\\kappa + 1}
        \\hat k \\hat k\\Big) \\, i \\hat\\tau k

    (incompressible: the factor is 1 and
    :math:`\\hat p = \\hat k \\cdot \\hat \\tau \\cdot \\hat k`, mean pressure 0 so that
    :math:`\\overline{\\mathrm{tr}\\,\\sigma} = \\overline{\\mathrm{tr}\\,\\tau}` in both
    variants).
    """

    def __init__(self, params, grid: SpectralGrid, *, incompressible: bool = False,
                 spin_tol: float = 1e-8, backend: str = "compiled"):
        super().__init__(params, grid, spin_tol=spin_tol, backend=backend)
        self.incompressible = incompressible
        k = params.kappa
        self._a = 1.0 if incompressible else k / (k + 1.0)
        self.ebar = np.array([[params.eps, 0.0], [0.0, -params.eps]])
        kx, ky = self._khat
        c = -0.5 * (self.moduli.alpha - self.moduli.B)
        #: the spin symbols (m1, m2) of :meth:`spin_multiplier`
        self.spin_symbols = (c * (-2.0 * kx * ky), c * (kx**2 - ky**2))
        #: a zero half spectrum (the spin solve's start; read, never written)
        self.zero_hat = np.zeros(grid.k2.shape, dtype=complex)
        self.spin_maxiter = 100  # GMRES iterations of the spin solve before spin_diverged

    def _eigenstress(self, q1: Array, q2: Array) -> Array:
        m = self.moduli
        Q = T.nematic(q1, q2)
        tau = (m.alpha - m.B) * Q
        if m.B_prime:
            tau = tau - m.B_prime * T.ddot(Q, Q) * T.identity(q1.shape)
        return tau

    def solve(self, q1: Array, q2: Array, *, u_guess: Array | None = None,
              t: float | None = None, F_guess: Array | None = None) -> MechanicalState:
        """The small-strain state: one exact Fourier solve (no guess is needed)."""
        g = self.grid
        tau = self._eigenstress(q1, q2)
        tau_hat = g.forward(tau)
        b_hat = self.grid.div_hat(tau_hat)  # i tau_hat k
        u_hat = self._green(b_hat, self._a)
        grad_u = g.inverse(self.grid.grad_hat(u_hat)) + self.ebar[:, :, None, None]
        e = 0.5 * (grad_u + T.transpose(grad_u))
        tr_e = T.trace(e)
        eye = T.identity(tr_e.shape)
        if self.incompressible:
            kh = self._khat
            p_hat = np.einsum("i...,ij...,j...->...", kh, tau_hat, kh)
            p = g.inverse(p_hat)
            sigma = -p * eye + 2.0 * e + tau
        else:
            sigma = 2.0 * (e - 0.5 * tr_e * eye) + self.params.kappa * tr_e * eye + tau
        Ebar_dev = np.stack([0.5 * (e[0, 0] - e[1, 1]), e[0, 1]])
        return MechanicalState(F=T.identity(tr_e.shape) + grad_u, P=sigma, Ebar_dev=Ebar_dev,
                               Jm1=tr_e, trP=T.trace(sigma), u_hat=u_hat)

    def spectral_response(self, q_hat: Array, QQ_hat: Array | None
                          ) -> tuple[Array, Array, Array]:
        """Fast path of :meth:`solve` for the time stepper, all from the spectra of q1, q2
        (and of Q:Q when B' != 0): returns ``(dev e hat (2 comps), tr e hat, tr sigma hat)``.

        The backend's ``linear_response`` (:mod:`model.compiled.spectral`, or its numpy twin
        in :mod:`model.reference_kernels`; tested to agree, and with :meth:`solve`).
        """
        g, m = self.grid, self.moduli
        iso = -m.B_prime * QQ_hat if QQ_hat is not None else self.zero_hat
        return self.k.linear_response(q_hat[0], q_hat[1], iso, g.kx, g.ky, self._khat[0],
                               self._khat[1], self._inv_k2, m.alpha - m.B, self._a,
                               self.params.kappa, self.incompressible,
                               self.params.eps * g.n**2)

    def response_symbols(self) -> Array:
        """The real symbols ``S[r, c]`` of :meth:`spectral_response` (outputs r: dev e (2
        components), tr e, tr sigma; inputs c: q1 hat, q2 hat, -B' Q:Q hat), for
        :func:`model.compiled.linear_rhs.linear_split`: the responses to unit spectra; the
        response is linear and every factor i of a derivative meets another one, so they are
        real."""
        g, m = self.grid, self.moduli
        one, zero = np.ones(g.k2.shape, dtype=complex), self.zero_hat
        cols = []
        for q1h, q2h, iso in ((one, zero, zero), (zero, one, zero), (zero, zero, one)):
            dev, tr_e, tr_s = self.k.linear_response(q1h, q2h, iso, g.kx, g.ky, self._khat[0],
                                              self._khat[1], self._inv_k2, m.alpha - m.B,
                                              self._a, self.params.kappa, self.incompressible,
                                              0.0)
            cols.append(np.stack([dev[0], dev[1], tr_e, tr_s]))
        S = np.stack(cols, axis=1)
        assert np.all(S.imag == 0.0)
        return np.ascontiguousarray(S.real)

    def spin_multiplier(self, qdot1_hat: Array, qdot2_hat: Array) -> Array:
        """Fourier symbol of the spin: :math:`\\hat\\omega = -\\tfrac12 (\\alpha - B)\\,
        \\hat t \\cdot \\hat{\\dot Q} \\cdot \\hat k`, :math:`\\hat t = (-\\hat k_2, \\hat k_1)`
        (the isotropic B' part of the eigenstress is curl free)."""
        m1, m2 = self.spin_symbols
        return m1 * qdot1_hat + m2 * qdot2_hat

    def corotational_hat(self, q1: Array, q2: Array, R_hat: Array, t: float | None = None
                         ) -> Array:
        r"""Solve :math:`\omega = \Omega[R + 2 \omega J q]` (Jq = (-q2, q1)) by GMRES on
        :math:`\hat\omega`, started from zero; return the spectra of the Qdot components (the
        spin's spectrum is kept in ``omega_hat``).

        Without the Jaumann feedback this is one multiplication; the feedback operator has
        norm <= (alpha - B) max S, and :math:`I - M` becomes singular at (alpha - B) S = 1 for
        a uniform state (loss of well-posedness, reported as ``spin_diverged``).
        """
        g = self.grid

        def operator(omega_hat: Array) -> tuple[Array, Array]:
            """``(I - M) omega_hat`` and the Jaumann rate ``2 omega J q`` (hat) it used."""
            j = g.forward(self.k.jaumann_products(g.inverse(omega_hat), q1, q2))
            return self.k.symbol_combination(omega_hat, m1, m2, j[0], j[1]), j

        m1, m2 = self.spin_symbols
        b = self.k.symbol_combination(self.zero_hat, -m1, -m2, R_hat[0], R_hat[1])
        # from zero: its residual is b, no operator application; a warm start from the last
        # spin costs one application for its residual and saves fewer iterations (the spin
        # follows the stage-specific part of Qdot): 4534 iterations + 1256 residuals against
        # 4940 iterations for a linear 128^2 run to t = 300 (-11 % transforms, measured)
        omega_hat, it, status, j_hat = krylov.gmres_aux(
            operator, b, self.zero_hat, lambda r: r, g.inner, rtol=self.spin_tol,
            maxiter=self.spin_maxiter)
        self.accept_spin(omega_hat, it, status == "ok", t)
        return R_hat + j_hat

    def rate_margin(self, q1: Array, q2: Array, mech: MechanicalState | None = None
                    ) -> tuple[float, int, float]:
        r"""Well-posedness margin of the rate problem (:mod:`model.wellposedness`):
        :math:`1 - (\alpha - B) \max S`, its flat grid index, and the wave-vector angle of
        the minimum (perpendicular to the director there)."""
        m, idx = wp.linear_margin(q1, q2, self.params.alpha_minus_B)
        theta = 0.5 * float(np.arctan2(q2.flat[idx], q1.flat[idx]))
        return m, idx, (theta + 0.5 * np.pi) % np.pi

    def accept_spin(self, omega_hat: Array, iterations: int, converged: bool,
                    t: float | None) -> None:
        """Book a spin solve (here or in :func:`model.compiled.linear_rhs.linear_split`): count its
        iterations, fail the run if it did not converge, keep the spin (``omega_hat``, which
        :meth:`corotational` returns)."""
        self.spin_iterations += iterations
        if not converged:
            raise SimulationFailure(
                "spin_diverged", "the Jaumann spin solve did not converge in "
                f"{iterations} iterations ((alpha - B) S too large: loss of well-posedness)", t)
        self.omega_hat = omega_hat

    def corotational(self, mech: MechanicalState, q1: Array, q2: Array, R: Array,
                     t: float | None = None) -> tuple[Array, Array]:
        qdot_hat = self.corotational_hat(q1, q2, self.grid.forward(R), t)
        assert self.omega_hat is not None
        return self.grid.inverse(qdot_hat), self.grid.inverse(self.omega_hat)


class FiniteMechanics(Mechanics):
    """Finite-strain force balance by Newton-Krylov (see the module docstring)."""

    def __init__(self, params, grid: SpectralGrid, *, tol: float = 1e-8, max_newton: int = 30,
                 cg_rtol: float = 0.1, max_cg: int = 200, spin_tol: float = 1e-8,
                 backend: str = "compiled", integrated: bool = True):
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
        self._checkpoint: tuple[Array, Array] | None = None
        self._weights = grid.weights / n**2  # Parseval weights of the half spectrum
        self._workspace: tuple[Array, Array, Array] | None = None
        self.fft_parts.update(rate_solve=0, newton_cg=0, force_balance=0)
        #: (u_hat, q1, q2, F, P) of the last converged solve, which :meth:`state_at` reuses
        #: when asked for the same displacement and order (the first stage after a projection)
        self._solution: tuple[Array, Array, Array, Array, Array] | None = None

    def checkpoint(self) -> None:
        self._checkpoint = (self.u_hat.copy(), self.udot_hat.copy())

    def restore(self) -> None:
        if self._checkpoint is not None:
            self.u_hat, self.udot_hat = self._checkpoint

    def predict(self, dt: float) -> None:
        self.u_hat = self.u_hat + dt * self.udot_hat

    def _tangent(self, F: Array, q1: Array, q2: Array) -> Array:
        """The tangent dP/dF (the backend's ``tangent_kernel``)."""
        m = self.moduli
        return self.k.tangent_kernel(np.ascontiguousarray(F), np.ascontiguousarray(q1),
                              np.ascontiguousarray(q2), m.kappa, m.B, m.B_prime, m.alpha)

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
        """Newton's correction from zero: compiled (:func:`model.finite_krylov.pcg`) or the
        numpy reference (:func:`model.krylov.pcg` on :meth:`_operator`)."""
        g = self.grid
        x0 = np.zeros_like(b_hat)
        if self.compiled:
            assert g.fft.plans is not None
            x, it, code, nop = finite_krylov.pcg(
                K, b_hat, x0, g.kx, g.ky, self._khat[0], self._khat[1], self._inv_k2, self._a,
                self._weights, *g.fft.plans, rtol, self.max_cg)
            g.fft.count += 8 * nop
            return x, it, code == 0
        x, it, status = krylov.pcg(self._operator(K), b_hat, x0,
                                   lambda r: self._green(r, self._a), g.inner, rtol=rtol,
                                   maxiter=self.max_cg)
        return x, it, status == "ok"

    def _udot_gmres(self, K: Array, E: Array, b: Array) -> tuple[Array, Array, int, bool]:
        """The displacement-rate solve, warm-started: ``(udot_hat, its real-space gradient,
        iterations, converged)``, compiled (:func:`model.compiled.finite_krylov.gmres`) or the
        numpy reference (:func:`model.krylov.gmres_aux`); the gradient comes with the
        operator applications (no transform of its own)."""
        g = self.grid
        if self.compiled:
            assert g.fft.plans is not None
            if self._workspace is None:
                self._workspace = finite_krylov.workspace(g.n)
            x, grad, it, ok, nop = finite_krylov.gmres(
                K, E, b, self.udot_hat, g.kx, g.ky, self._khat[0], self._khat[1],
                self._inv_k2, self._a, self._weights, *g.fft.plans, self.spin_tol,
                self.max_cg, *self._workspace)
            g.fft.count += 8 * nop
            return x, grad, it, ok

        def A(v_hat: Array) -> tuple[Array, Array]:
            k = self.k
            G = g.inverse(k.grad_hat_kernel(v_hat, g.kx, g.ky))
            return k.neg_div_hat_kernel(g.forward(k.apply_tangent_spin_kernel(K, G, E)), g.kx,
                                        g.ky), G

        x, it, status, grad = krylov.gmres_aux(A, b, self.udot_hat,
                                               lambda r: self._green(r, self._a), g.inner,
                                               rtol=self.spin_tol, maxiter=self.max_cg)
        return x, grad, it, status == "ok"

    def _evaluate(self, u_hat: Array, q1: Array, q2: Array, F: Array | None = None
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

    def solve(self, q1: Array, q2: Array, *, u_guess: Array | None = None,
              t: float | None = None, F_guess: Array | None = None) -> MechanicalState:
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
                    f"(residual {res:.3g} > {self.tol:g})", t)
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
                    "the tangent stiffness is not positive definite (loss of ellipticity)", t)
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
                    reason, f"line search failed at Newton iteration {it} "
                    f"(residual {res:.3g})", t)
            u_hat, F, P, P_hat, res = trial, F_t, P_t, P_hat_t, res_t
        self.u_hat = u_hat
        self._solution = (u_hat, q1.copy(), q2.copy(), F, P)
        return self._state(F, P, u_hat, iterations=it, residual=res, K=K)

    def _state(self, F: Array, P: Array, u_hat: Array, *, iterations: int = 0,
               residual: float = float("nan"), K: Array | None = None) -> MechanicalState:
        """The :class:`MechanicalState` of the deformation ``F`` with stress ``P`` (its
        strain measures by the backend's ``strain_measures_kernel``)."""
        Ebar_dev, Jm1, trP = self.k.strain_measures_kernel(np.ascontiguousarray(F),
                                                    np.ascontiguousarray(P))
        return MechanicalState(F=F, P=P, Ebar_dev=Ebar_dev, Jm1=Jm1, trP=trP, u_hat=u_hat,
                               iterations=iterations, residual=residual, extras={"K": K})

    def state_at(self, u_hat: Array, q1: Array, q2: Array, t: float | None = None,
                 F: Array | None = None) -> MechanicalState:
        """The mechanical state at the displacement ``u_hat`` as given, without solving the
        force balance (the stages of the integrated-displacement scheme, where u is part of
        the integrated state: docs/model.md, section 4), with the deformation gradient ``F``
        if given (else from ``u_hat``). Its ``residual`` is not computed (NaN). Raises
        ``J<=0`` where the deformation folds. The deformation and stress of the last solve
        are reused when ``u_hat`` is its solution for the same q."""
        sol = self._solution
        if (sol is not None and u_hat is sol[0] and np.array_equal(q1, sol[1])
                and np.array_equal(q2, sol[2])):
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

    def corotational(self, mech: MechanicalState, q1: Array, q2: Array, R: Array,
                     t: float | None = None) -> tuple[Array, Array]:
        r"""Solve for :math:`\dot u` and :math:`\dot Q = R + 2\omega J q` together:

        .. math::
            -\mathrm{Div}\big(\mathbb K : \nabla \dot u + E\, \omega(\dot u)\big)
            = \mathrm{Div}(\partial_Q P : R), \qquad E = \partial_Q P : (2 J q),
            \quad \omega(\dot u) = \tfrac12 (\partial_1 \dot u_2 - \partial_2 \dot u_1),

        by GMRES (Green-preconditioned, warm-started). Returns ``(Qdot components, omega)``.
        """
        g, m = self.grid, self.moduli
        K = mech.extras.get("K")
        if K is None:
            K = self._tangent(mech.F, q1, q2)
            mech.extras["K"] = K
        F = np.ascontiguousarray(mech.F)
        E = self.k.q_increment_kernel(F, q1, q2, -2.0 * q2, 2.0 * q1, m.B, m.B_prime, m.alpha)
        mech.extras["E"] = E
        dP = self.k.q_increment_kernel(F, q1, q2, np.ascontiguousarray(R[0]),
                                       np.ascontiguousarray(R[1]), m.B, m.B_prime, m.alpha)
        b = self.k.div_hat_kernel(g.forward(dP), g.kx, g.ky)

        count = g.fft.count
        udot, grad, it, ok = self._udot_gmres(K, E, b)
        self.fft_parts["rate_solve"] += g.fft.count - count
        self.spin_iterations += it
        if not ok:
            raise SimulationFailure(
                "spin_diverged", "the displacement-rate (Jaumann spin) solve did not converge "
                f"in {it} iterations: loss of ellipticity", t)
        self.udot_hat = udot
        self.udot_grad = grad
        return self.k.corotational_rate(R, grad, q1, q2)

    def rate_margin(self, q1: Array, q2: Array, mech: MechanicalState | None = None
                    ) -> tuple[float, int, float]:
        """Well-posedness margin of the rate problem at the deformation of ``mech`` (solved
        here if not given), its flat grid index and the wave-vector angle of the minimum
        (:func:`model.wellposedness.finite_margin`; reuses the tangent and E of
        :meth:`corotational` when ``mech`` has them)."""
        m = self.moduli
        if mech is None:
            mech = self.solve(q1, q2)
        K = mech.extras.get("K")
        if K is None:
            K = self._tangent(mech.F, q1, q2)
        E = mech.extras.get("E")
        if E is None:
            E = self.k.q_increment_kernel(np.ascontiguousarray(mech.F), q1, q2, -2.0 * q2, 2.0 * q1,
                                   m.B, m.B_prime, m.alpha)
        return wp.finite_margin(K, E, m.kappa, samples=self.k.finite_margin_kernel)


def make_mechanics(params, numerics, grid: SpectralGrid) -> Mechanics:
    """The mechanics ``numerics.mechanics`` names, with its tolerances and backend."""
    if numerics.mechanics == "linear":
        return LinearMechanics(params, grid, incompressible=numerics.incompressible,
                               spin_tol=numerics.spin_tol, backend=numerics.backend)
    return FiniteMechanics(params, grid, tol=numerics.newton_tol, max_newton=numerics.max_newton,
                           spin_tol=numerics.spin_tol, backend=numerics.backend,
                           integrated=numerics.displacement == "integrated")
