r"""The interface of the quasi-static force balance :math:`\mathrm{Div}\, P = 0` (paper Eq. 3)
on the periodic square, and what both mechanics share.

The deformation is :math:`F = \bar F + \nabla \tilde u` with a periodic fluctuation
:math:`\tilde u` and the applied pure shear :math:`\bar F = \mathrm{diag}(1+\epsilon, 1-\epsilon)`
(the paper's :math:`\epsilon_{11} = \epsilon = -\epsilon_{22}`; at small strain the mean
displacement gradient is exactly that).

:class:`Mechanics` is what the time stepper and the PDE call (:meth:`~Mechanics.solve`,
:meth:`~Mechanics.state_at`, :meth:`~Mechanics.corotational`, :meth:`~Mechanics.rate_margin`,
and the warm start's :meth:`~Mechanics.checkpoint`, :meth:`~Mechanics.restore`,
:meth:`~Mechanics.predict`, and for a continued run :meth:`~Mechanics.saved_state` and
:meth:`~Mechanics.resume`); :class:`MechanicalState` is what a solve returns. The two
mechanics are :class:`nematic_solids.model.mechanics.linear.LinearMechanics` and
:class:`nematic_solids.model.mechanics.finite.FiniteMechanics`.

**Residual.** :math:`r = \lVert \hat k_J \hat P_{iJ} \rVert / \max(1, \lVert P \rVert)`: the RMS
of :math:`\mathrm{Div}\,P` in the :math:`H^{-1}` norm (so high wavenumbers are not amplified),
relative to the RMS stress with the shear modulus G = 1 as a floor.

**Spin.** The Jaumann derivative of Eq. (4) needs :math:`W = \operatorname{skew} \nabla \dot u`.
Since u is slaved to Q, :math:`\dot u` solves the linearised balance
:math:`\mathrm{Div}(\mathbb K : \nabla \dot u + \partial_Q P : \dot Q) = 0` (an extra linear
solve: exact, no lagged difference). :meth:`~Mechanics.corotational` returns :math:`\dot Q`
with :math:`\omega = \tfrac12 (\partial_1 \dot u_2 - \partial_2 \dot u_1)` of that
:math:`\dot Q`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from .. import constitutive as cl
from ..backend import kernels
from ..fourier import SpectralGrid
from ..parameters import Parameters

Array = np.ndarray


@dataclass
class MechanicalState:
    """Everything the Q and A equations and the observables need from the mechanics.

    ``Ebar_dev`` holds the two independent components ((E11 - E22)/2, E12) of the deviatoric
    part of :math:`\\bar E = \\tfrac12 (J^{-1} C - I)` (small strain: of e), ``Jm1`` is
    :math:`J - 1` as it enters :math:`B'` (small strain: tr e), ``trP`` is
    :math:`P_{11} + P_{22}` (Eq. 5). Finite strain also carries what the rate problem reuses:
    ``tangent``, the packed (:func:`nematic_solids.model.tensors.pack_symmetric`) tangent
    :math:`\\mathbb K = \\partial P / \\partial F` of Newton's last step (at the iterate before
    the solution; None where the guess needed no step, and in the states of
    :meth:`~Mechanics.state_at`), and ``spin_coupling``, :math:`E = \\partial_Q P : (2 J q)`, once
    :meth:`~Mechanics.corotational` computed it.
    """

    F: Array
    P: Array
    Ebar_dev: Array
    Jm1: Array
    trP: Array
    u_hat: Array
    iterations: int = 0
    residual: float = 0.0
    tangent: Array | None = None
    spin_coupling: Array | None = None
    #: tr S, S = F^-1 P the second Piola stress (finite strain with ``coupling = "trS"``)
    trS: Array | None = None


def applied_deformation(eps: float) -> Array:
    """The mean deformation gradient :math:`\\bar F = \\mathrm{diag}(1+\\epsilon, 1-\\epsilon)`."""
    return np.array([[1.0 + eps, 0.0], [0.0, 1.0 - eps]])


class Mechanics(ABC):
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

    def __init__(
        self,
        params: Parameters,
        grid: SpectralGrid,
        *,
        spin_tol: float = 1e-8,
        backend: str = "compiled",
    ):
        self.params = params
        self.grid = grid
        self.spin_tol = spin_tol
        #: the pointwise and spectral kernels of the backend (nematic_solids.model.backend)
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
        #: the time derivatives of alpha and eps under a protocol (:meth:`set_parameters`)
        self.alpha_rate = 0.0
        self.eps_rate = 0.0
        #: counts the changes of :meth:`set_parameters` (what caches the constants checks)
        self.parameter_version = 0
        g = grid
        kh = g.khat
        # Green operator of the isotropic medium (mu = 1, lambda + mu = kappa):
        # [mu k^2 I + (lambda + mu) k k] u = b  ->  u = (I - a khat khat) b / k^2
        self._inv_k2 = np.where(g.active, 1.0 / np.where(g.active, g.kd2, 1.0), 0.0)
        self._khat = kh

    def set_parameters(self, params: Parameters, rates: dict[str, float]) -> None:
        """The constants at the current time of a protocol (:mod:`nematic_solids.model.protocol`)
        and the time derivatives ``rates`` of alpha - B and eps there (they drive the displacement
        rate: :meth:`corotational`)."""
        self.params = params
        self.moduli = cl.Moduli.from_params(params)
        self.Fbar = applied_deformation(params.eps)
        self.alpha_rate = float(rates.get("alpha_minus_B", 0.0))
        self.eps_rate = float(rates.get("eps", 0.0))
        self.parameter_version += 1

    # --- the interface (abstract, or the defaults of a mechanics without a warm start) -
    @abstractmethod
    def solve(
        self,
        q1: Array,
        q2: Array,
        *,
        u_guess: Array | None = None,
        t: float | None = None,
        F_guess: Array | None = None,
    ) -> MechanicalState:
        """The mechanical state in force balance (Eq. 3) for the order q1, q2 (``u_guess``: a
        start for an iterative solve, ``F_guess`` its deformation gradient if known)."""

    def state_at(
        self, u_hat: Array, q1: Array, q2: Array, t: float | None = None, F: Array | None = None
    ) -> MechanicalState:
        """The mechanical state at a given displacement, whose deformation gradient is ``F``
        if given (only where :attr:`integrated`)."""
        raise ValueError(f"{type(self).__name__} does not integrate the displacement")

    def deformation_of(self, u_hat: Array) -> Array:
        """The deformation gradient of the displacement spectrum ``u_hat`` (only where
        :attr:`integrated`)."""
        raise ValueError(f"{type(self).__name__} does not integrate the displacement")

    @abstractmethod
    def corotational(
        self, mech: MechanicalState, q1: Array, q2: Array, R: Array, t: float | None = None
    ) -> tuple[Array, Array]:
        """``(Qdot components, omega)``: :math:`\\dot Q = R + 2 \\omega J q` with the spin
        slaved to :math:`\\dot Q` (Eq. 4)."""

    @abstractmethod
    def rate_margin(
        self, q1: Array, q2: Array, mech: MechanicalState | None = None
    ) -> tuple[float, int, float]:
        """The well-posedness margin of the rate problem, its flat grid index and the
        wave-vector angle of the minimum (:mod:`nematic_solids.model.wellposedness`)."""

    def checkpoint(self) -> None:  # noqa: B027 (no warm start: nothing to do)
        """Remember the warm start (displacement and its rate) at the start of a step."""

    def restore(self) -> None:  # noqa: B027 (no warm start: nothing to do)
        """Put the warm start of the last :meth:`checkpoint` back (a rejected step)."""

    def predict(self, dt: float) -> None:  # noqa: B027 (no warm start: nothing to do)
        """Move Newton's warm start ``dt`` ahead along the displacement rate."""

    def saved_state(self) -> dict[str, Array]:
        """What a run continued from this moment needs of the mechanics besides the fields
        (:mod:`nematic_solids.model.checkpoint`): nothing here (every solve starts from zero)."""
        return {}

    def resume(self, arrays: dict[str, Array], q1: Array, q2: Array) -> None:  # noqa: B027
        """Take back :meth:`saved_state` (taken after the save at the order ``q1``, ``q2``)."""

    # --- shared helpers ----------------------------------------------------------------
    def _green(self, b_hat: Array, a: float) -> Array:
        """:math:`(I - a \\hat k \\hat k) \\hat b / k^2` (the backend's ``green_kernel``)."""
        return self.k.green_kernel(b_hat, self._khat[0], self._khat[1], self._inv_k2, a)

    def residual(self, P: Array, P_hat: Array | None = None) -> float:
        """:math:`\\lVert \\hat k_J \\hat P_{iJ} \\rVert / \\max(1, \\mathrm{RMS}\\, P)`."""
        if P_hat is None:
            P_hat = self.grid.forward(P)
        return float(
            self.k.balance_residual_kernel(
                P, P_hat, self._khat[0], self._khat[1], self.grid.weights
            )
        )
