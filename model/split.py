r"""The split right-hand side of the exponential integrators (:mod:`nematic_solids.model.solver`).

For the state ``u = [q1, q2, A]`` with ``q_hat`` the spectra of q1, q2, a split returns
:math:`\hat N_q = \widehat{\dot q} - L_q \hat q` (Fourier space, :math:`L_q = -(A_0 + K k^2)/
\gamma`) and the full activity rate :math:`\dot A` (Eq. 5, real space), with the mechanical
state it used (or None):

* :class:`ForceBalanceSplit`, for any mechanics: the PDE's readable
  :meth:`nematic_solids.model.pde.ActiveNematicPDE.rates` (force balance solved, or, where the
  mechanics integrates the displacement, the state at the given displacement), transformed.
* :class:`SpectralSplit`, for :class:`nematic_solids.model.mechanics.LinearMechanics`: every linear
  map of q stays in Fourier space (the small-strain response as Fourier symbols); one compiled
  function, :func:`nematic_solids.model.compiled.linear_rhs.linear_split`, where the mechanics is
  compiled, and its numpy reference otherwise (tested to agree with each other and with
  ``evolution_rate``).

:func:`make_split` chooses by the mechanics' type (``functools.singledispatch``).
"""

from __future__ import annotations

import functools

import numpy as np

from .compiled import linear_rhs
from .errors import SimulationFailure
from .mechanics import LinearMechanics, MechanicalState, Mechanics
from .pde import ActiveNematicPDE

Array = np.ndarray


class ForceBalanceSplit:
    """The split from :meth:`nematic_solids.model.pde.ActiveNematicPDE.rates` (any mechanics)."""

    def __init__(self, pde: ActiveNematicPDE, Lq: Array):
        self.pde = pde
        self.Lq = Lq

    def __call__(
        self, u: Array, q_hat: Array, t: float, disp: Array | None = None, F: Array | None = None
    ) -> tuple[Array, Array, MechanicalState | None]:
        """``(N_q hat, Adot, mechanical state)`` at the displacement spectrum ``disp`` if
        given (the integrated scheme; ``F`` its deformation gradient if known), else in
        force balance."""
        rate, mech, _ = self.pde.rates(u[0], u[1], u[2], t, u_hat=disp, q_hat=q_hat, F=F)
        if not np.all(np.isfinite(rate)):
            raise SimulationFailure("nan", "non-finite rate", t)
        return self.pde.spectral.forward(rate[:2]) - self.Lq * q_hat, rate[2], mech


class SpectralSplit:
    """The linear-mechanics split with every linear map of q in Fourier space."""

    def __init__(self, pde: ActiveNematicPDE, mech: LinearMechanics, Lq: Array):
        self.pde = pde
        self.mech = mech
        self.Lq = Lq
        g = pde.spectral
        self._zeros = np.zeros((g.n, g.n))
        self._weights = g.weights / g.n**2  # Parseval weights of the half spectrum
        #: the compiled right-hand side's fixed data (None: the numpy reference)
        self._rhs_data: linear_rhs.LinearRHS | None = None
        if mech.compiled:
            p = pde.params
            assert g.fft.plans is not None
            self._rhs_data = linear_rhs.LinearRHS(
                Lq,
                *mech.spin_symbols,
                mech.response_symbols(),
                self._weights,
                *g.fft.plans,
                p.eps * g.n**2,
                p.B,
                p.B_prime,
                p.C,
                p.gamma,
                p.zeta,
                p.chi,
                p.s,
                p.tau,
                mech.spin_tol,
                mech.spin_maxiter,
                *linear_rhs.workspace(g.n),
                *mech.unit_spin_symbols,
                mech.alpha_rate,
            )
        #: the mechanics' parameter version the compiled data holds (a protocol changes it)
        self._version = mech.parameter_version

    @property
    def compiled_data(self) -> linear_rhs.LinearRHS | None:
        """The compiled right-hand side's fixed data (None where the mechanics runs the numpy
        reference): what :mod:`nematic_solids.model.compiled.linear_step` takes."""
        return self._rhs_data

    def _update(self) -> None:
        """Put a protocol's current constants into the compiled data."""
        mech, p = self.mech, self.pde.params
        self._version = mech.parameter_version
        if self._rhs_data is None:
            return
        self._rhs_data = self._rhs_data._replace(
            m1=mech.spin_symbols[0],
            m2=mech.spin_symbols[1],
            S=mech.response_symbols(),
            mean_dev=p.eps * self.pde.spectral.n**2,
            chi=p.chi,
            spin_rate=mech.alpha_rate,
        )

    def __call__(
        self, u: Array, q_hat: Array, t: float, disp: Array | None = None, F: Array | None = None
    ) -> tuple[Array, Array, MechanicalState | None]:
        """``(N_q hat, Adot, None)``; by
        :func:`nematic_solids.model.compiled.linear_rhs.linear_split` where the mechanics is
        compiled, else by :meth:`reference`."""
        if disp is not None:
            raise ValueError("a given displacement needs finite mechanics")
        if self._version != self.mech.parameter_version:
            self._update()
        if self._rhs_data is None:
            return (*self.reference(u, q_hat, t), None)
        mech, g = self.mech, self.pde.spectral
        Nq, Adot, omega_hat, its, ok, nfft = linear_rhs.linear_split(
            u[0], u[1], u[2], np.ascontiguousarray(q_hat), mech.zero_hat, self._rhs_data
        )
        g.fft.count += nfft
        mech.accept_spin(omega_hat, its, ok, t)
        return Nq, Adot, None

    def reference(self, u: Array, q_hat: Array, t: float) -> tuple[Array, Array]:
        """numpy reference of :func:`nematic_solids.model.compiled.linear_rhs.linear_split`."""
        eq, mech = self.pde, self.mech
        p, g = eq.params, eq.spectral
        q1, q2, A = u
        QQ_hat = g.forward(2.0 * (q1**2 + q2**2)) if p.B_prime else None
        dev_hat, tr_e_hat, tr_sigma_hat = mech.spectral_response(q_hat, QQ_hat)
        if p.B_prime:
            tr_e, tr_sigma = g.inverse(np.stack([tr_e_hat, tr_sigma_hat]))
        else:
            tr_e, tr_sigma = self._zeros, g.inverse(tr_sigma_hat)
        H_hat = g.forward(mech.k.bulk_terms(q1, q2, A, tr_e, p.C, 2.0 * p.B_prime)) + p.B * dev_hat
        Lq_hat = self.Lq * q_hat
        R_hat = H_hat
        R_hat /= p.gamma
        R_hat += Lq_hat  # H / gamma, full
        qdot_hat = mech.corotational_hat(q1, q2, R_hat, t, q_hat)  # R + 2 omega J q
        qdot_hat -= Lq_hat
        Adot = mech.k.activity_rate(A, tr_sigma, p.zeta, p.chi, p.s, p.tau)
        return qdot_hat, Adot


Split = ForceBalanceSplit | SpectralSplit


@functools.singledispatch
def make_split(mech: Mechanics, pde: ActiveNematicPDE, Lq: Array) -> Split:
    """The split for the PDE's mechanics ``mech``: :class:`ForceBalanceSplit` in general."""
    return ForceBalanceSplit(pde, Lq)


@make_split.register
def _(mech: LinearMechanics, pde: ActiveNematicPDE, Lq: Array) -> Split:
    return SpectralSplit(pde, mech, Lq)
