r"""Small-strain force balance (paper Eq. 3 linearised about the reference state): one exact
Fourier solve with the Green operator of the isotropic medium (shear modulus 1, 2-D bulk
modulus kappa, or incompressible by projection); the Jaumann spin of Eq. (4) from its Fourier
symbol, with the feedback of the spin on :math:`\dot Q` solved by GMRES.
"""

from __future__ import annotations

import numpy as np

from .. import krylov
from .. import tensors as T
from ..errors import SimulationFailure
from ..fourier import SpectralGrid
from ..parameters import Parameters
from .base import MechanicalState, Mechanics

Array = np.ndarray


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

    def __init__(
        self,
        params: Parameters,
        grid: SpectralGrid,
        *,
        incompressible: bool = False,
        spin_tol: float = 1e-8,
        backend: str = "compiled",
    ):
        super().__init__(params, grid, spin_tol=spin_tol, backend=backend)
        self.incompressible = incompressible
        k = params.kappa
        self._a = 1.0 if incompressible else k / (k + 1.0)
        self.ebar = np.array([[params.eps, 0.0], [0.0, -params.eps]])
        kx, ky = self._khat
        #: the spin symbols per unit alpha - B: the spin of a rate of alpha - B at fixed Q
        self.unit_spin_symbols = (-0.5 * (-2.0 * kx * ky), -0.5 * (kx**2 - ky**2))
        self.spin_symbols = self._spin_symbols()
        #: a zero half spectrum (the spin solve's start; read, never written)
        self.zero_hat = np.zeros(grid.k2.shape, dtype=complex)
        self.spin_maxiter = 100  # GMRES iterations of the spin solve before spin_diverged

    def _spin_symbols(self) -> tuple[Array, Array]:
        """The spin symbols (m1, m2) of :meth:`spin_multiplier` at the current alpha - B."""
        kx, ky = self._khat
        c = -0.5 * (self.moduli.alpha - self.moduli.B)
        return c * (-2.0 * kx * ky), c * (kx**2 - ky**2)

    def set_parameters(self, params: Parameters, rates: dict[str, float]) -> None:
        super().set_parameters(params, rates)
        self.ebar = np.array([[params.eps, 0.0], [0.0, -params.eps]])
        self.spin_symbols = self._spin_symbols()

    def spin_source(self, q_hat: Array) -> Array | None:
        r"""The spin that a rate of alpha - B drives at fixed Q,
        :math:`\dot\alpha\, (\hat m_1 \hat q_1 + \hat m_2 \hat q_2)` with the spin symbols
        per unit alpha - B (the eigenstress :math:`(\alpha - B) Q` changes at that rate):
        None without one."""
        if self.alpha_rate == 0.0:
            return None
        mu1, mu2 = self.unit_spin_symbols
        return self.alpha_rate * (mu1 * q_hat[0] + mu2 * q_hat[1])

    def _eigenstress(self, q1: Array, q2: Array) -> Array:
        m = self.moduli
        Q = T.nematic(q1, q2)
        tau = (m.alpha - m.B) * Q
        if m.B_prime:
            tau = tau - m.B_prime * T.ddot(Q, Q) * T.identity(q1.shape)
        return tau

    def solve(
        self,
        q1: Array,
        q2: Array,
        *,
        u_guess: Array | None = None,
        t: float | None = None,
        F_guess: Array | None = None,
    ) -> MechanicalState:
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
        return MechanicalState(
            F=T.identity(tr_e.shape) + grad_u,
            P=sigma,
            Ebar_dev=Ebar_dev,
            Jm1=tr_e,
            trP=T.trace(sigma),
            u_hat=u_hat,
        )

    def spectral_response(self, q_hat: Array, QQ_hat: Array | None) -> tuple[Array, Array, Array]:
        """Fast path of :meth:`solve` for the time stepper, all from the spectra of q1, q2
        (and of Q:Q when B' != 0): returns ``(dev e hat (2 comps), tr e hat, tr sigma hat)``.

        The backend's ``linear_response`` (:mod:`nematic_solids.model.compiled.spectral`, or its
        numpy twin in :mod:`nematic_solids.model.reference_kernels`; tested to agree, and with
        :meth:`solve`).
        """
        g, m = self.grid, self.moduli
        iso = -m.B_prime * QQ_hat if QQ_hat is not None else self.zero_hat
        return self.k.linear_response(
            q_hat[0],
            q_hat[1],
            iso,
            g.kx,
            g.ky,
            self._khat[0],
            self._khat[1],
            self._inv_k2,
            m.alpha - m.B,
            self._a,
            self.params.kappa,
            self.incompressible,
            self.params.eps * g.n**2,
        )

    def response_symbols(self) -> Array:
        """The real symbols ``S[r, c]`` of :meth:`spectral_response` (outputs r: dev e (2
        components), tr e, tr sigma; inputs c: q1 hat, q2 hat, -B' Q:Q hat), for
        :func:`nematic_solids.model.compiled.linear_rhs.linear_split`: the responses to unit
        spectra; the response is linear and every factor i of a derivative meets another one, so
        they are real."""
        g, m = self.grid, self.moduli
        one, zero = np.ones(g.k2.shape, dtype=complex), self.zero_hat
        cols = []
        for q1h, q2h, iso in ((one, zero, zero), (zero, one, zero), (zero, zero, one)):
            dev, tr_e, tr_s = self.k.linear_response(
                q1h,
                q2h,
                iso,
                g.kx,
                g.ky,
                self._khat[0],
                self._khat[1],
                self._inv_k2,
                m.alpha - m.B,
                self._a,
                self.params.kappa,
                self.incompressible,
                0.0,
            )
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

    def corotational_hat(
        self,
        q1: Array,
        q2: Array,
        R_hat: Array,
        t: float | None = None,
        q_hat: Array | None = None,
    ) -> Array:
        r"""Solve :math:`\omega = \Omega[R + 2 \omega J q] + \omega_s` (Jq = (-q2, q1),
        :math:`\omega_s` the :meth:`spin_source` of the spectra ``q_hat``) by GMRES on
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
        if self.alpha_rate != 0.0:
            source = self.spin_source(g.forward(np.stack([q1, q2])) if q_hat is None else q_hat)
            b = b + source
        # from zero: its residual is b, no operator application; a warm start from the last
        # spin costs one application for its residual and saves fewer iterations (the spin
        # follows the stage-specific part of Qdot): 4534 iterations + 1256 residuals against
        # 4940 iterations for a linear 128^2 run to t = 300 (-11 % transforms, measured)
        omega_hat, it, status, j_hat = krylov.gmres_aux(
            operator,
            b,
            self.zero_hat,
            lambda r: r,
            g.inner,
            rtol=self.spin_tol,
            maxiter=self.spin_maxiter,
        )
        self.accept_spin(omega_hat, it, status == "ok", t)
        return R_hat + j_hat

    def rate_margin(
        self, q1: Array, q2: Array, mech: MechanicalState | None = None
    ) -> tuple[float, int, float]:
        r"""Well-posedness margin of the rate problem (:mod:`nematic_solids.model.wellposedness`):
        :math:`1 - (\alpha - B) \max S`, its flat grid index, and the wave-vector angle of
        the minimum (perpendicular to the director there)."""
        m, idx = self.k.linear_margin_kernel(q1, q2, self.params.alpha_minus_B)
        theta = 0.5 * float(np.arctan2(q2.flat[idx], q1.flat[idx]))
        return m, idx, (theta + 0.5 * np.pi) % np.pi

    def accept_spin(
        self, omega_hat: Array, iterations: int, converged: bool, t: float | None
    ) -> None:
        """Book a spin solve (here or in
        :func:`nematic_solids.model.compiled.linear_rhs.linear_split`): count its iterations, fail
        the run if it did not converge, keep the spin (``omega_hat``, which :meth:`corotational`
        returns)."""
        self.spin_iterations += iterations
        if not converged:
            raise SimulationFailure(
                "spin_diverged",
                "the Jaumann spin solve did not converge in "
                f"{iterations} iterations ((alpha - B) S too large: loss of well-posedness)",
                t,
            )
        self.omega_hat = omega_hat

    def corotational(
        self, mech: MechanicalState, q1: Array, q2: Array, R: Array, t: float | None = None
    ) -> tuple[Array, Array]:
        qdot_hat = self.corotational_hat(q1, q2, self.grid.forward(R), t)
        assert self.omega_hat is not None
        return self.grid.inverse(qdot_hat), self.grid.inverse(self.omega_hat)
