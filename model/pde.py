r"""The py-pde PDE class: paper Eqs. (3)-(5) with a readable numpy ``evolution_rate``.

State: a :class:`pde.FieldCollection` of three scalar fields ``q1, q2, A`` on the periodic
unit square. The displacement is slaved to Q by quasi-static force balance (Eq. 3), solved on
every evaluation of :meth:`ActiveNematicPDE.evolution_rate` by :mod:`nematic_solids.model.mechanics`
(the time stepper may instead integrate it with the state: :meth:`ActiveNematicPDE.rates` with a
given displacement; docs/model/numerics.md).

Equations (tensor conventions: docs/model/index.md):

.. math::
    H &= -\big(A + A_0 + C\, Q:Q - 2 B' (J - 1)\big) Q + B\, \mathrm{dev}\,\bar E
         + K \nabla^2 Q
         \qquad (= -\delta \Psi / \delta Q \text{ of Eq. 1, projected on sym. traceless}) \\
    \gamma \big(\dot Q - W Q + Q W\big) &= H \qquad\qquad (\text{Eq. 4}) \\
    \tau \dot A &= -\zeta A - \chi\, \mathrm{tr}\, P - s A^3 \qquad (\text{Eq. 5})

In components, with :math:`W = \omega\,[[0, -1], [1, 0]]`:
:math:`\dot q_1 = H_{11}/\gamma - 2 \omega q_2`, :math:`\dot q_2 = H_{12}/\gamma + 2 \omega q_1`,
where :math:`\omega = \tfrac12 \operatorname{curl} \dot u` depends linearly on :math:`\dot Q`
(the displacement rate solves the rate form of Eq. 3), so :math:`\omega` and :math:`\dot Q`
are found together by one linear solve (GMRES, :mod:`nematic_solids.model.mechanics`).
"""

from __future__ import annotations

import numpy as np
from pde import CartesianGrid, FieldCollection, ScalarField
from pde.pdes.base import PDEBase

from .errors import SimulationFailure
from .fourier import SpectralGrid
from .mechanics import MechanicalState, make_mechanics
from .parameters import Numerics, Parameters

Array = np.ndarray
LABELS = ("q1", "q2", "A")


def make_grid(resolution: int) -> CartesianGrid:
    """The periodic unit square with ``resolution`` cells per side."""
    return CartesianGrid([(0.0, 1.0), (0.0, 1.0)], [resolution, resolution], periodic=True)


def make_state(q1: Array, q2: Array, A: Array) -> FieldCollection:
    grid = make_grid(q1.shape[0])
    return FieldCollection(
        [ScalarField(grid, np.array(d, dtype=float)) for d in (q1, q2, A)], labels=list(LABELS)
    )


class ActiveNematicPDE(PDEBase):
    """Active nematic solid, paper Eqs. (1)-(5); see the module docstring."""

    explicit_time_dependence = False
    check_implementation = False  # evolution_rate is numpy-only (spectral mechanics)

    def __init__(self, params: Parameters | None = None, numerics: Numerics | None = None):
        super().__init__()
        #: the run's parameters, with their protocol (nematic_solids.model.protocol)
        self.base_params = params or Parameters()
        self.protocol = self.base_params.protocol
        #: the constants at the current time (:meth:`at_time`; all of them without a protocol)
        self.params = self.base_params.at(0.0)
        self._protocol_key: tuple | None = None  # the values (and rates) last set
        #: without explicit numerics the grid follows the state (:meth:`use_grid_of`)
        self.grid_from_state = numerics is None
        self.numerics = numerics or Numerics()
        self._build(self.numerics)

    def _build(self, numerics: Numerics) -> None:
        self.numerics = numerics
        self.spectral = SpectralGrid(
            numerics.resolution, fft_backend="scipy" if numerics.backend == "numpy" else "auto"
        )
        self.mechanics = make_mechanics(self.params, numerics, self.spectral)
        self._protocol_key = None  # the new mechanics holds the constants at t = 0

    def at_time(self, t: float, after: float | None = None) -> None:
        """Set the constants (and the mechanics') to the protocol's values at ``t`` on the
        pieces that hold ``after`` (:meth:`nematic_solids.model.protocol.Protocol.values`; default:
        ``t``, right-continuous), with their rates; nothing without a protocol."""
        if not self.protocol:
            return
        values = self.protocol.values(t, after)
        rates = self.protocol.rates(t, after)
        key = (tuple(values.values()), tuple(rates.values()))
        if key == self._protocol_key:
            return
        self._protocol_key = key
        self.params = self.base_params.at(t, after)
        self.mechanics.set_parameters(self.params, rates)

    def use_grid_of(self, state: FieldCollection) -> None:
        """Match the grid of ``state`` (an N x N periodic unit square, e.g. from
        :func:`make_state`). Without explicit ``numerics`` the resolution is taken from the
        state; with them a different resolution is an error (a ``ValueError`` naming both)."""
        shape = tuple(state.grid.shape)
        n = shape[0]
        if len(shape) != 2 or shape[0] != shape[1]:
            raise ValueError(f"ActiveNematicPDE needs a square 2D grid, got shape {shape}")
        if n == self.numerics.resolution:
            return
        if not self.grid_from_state:
            raise ValueError(
                f"the state is on a {n}x{n} grid but the PDE's numerics have resolution "
                f"{self.numerics.resolution}: pass Numerics(resolution={n}) or a state of "
                f"that size"
            )
        self._build(self.numerics.replace(resolution=n))

    def solve(self, state, *args, **kwargs):  # type: ignore[override]
        """py-pde's :meth:`~pde.pdes.base.PDEBase.solve`, on the grid of ``state``."""
        self.use_grid_of(state)
        return super().solve(state, *args, **kwargs)

    # --- pieces of the right-hand side (readable reference) ----------------------------
    def molecular_field(
        self, q1: Array, q2: Array, A: Array, mech: MechanicalState, q_hat: Array | None = None
    ) -> Array:
        """:math:`H` (components H11, H12), the negative variational derivative of Eq. (1)
        (the backend's ``molecular_field_kernel``); ``q_hat``, the spectra of q1, q2 if known,
        saves two transforms."""
        p = self.params
        g = self.spectral
        lap = g.inverse(-g.k2 * (g.forward(np.stack([q1, q2])) if q_hat is None else q_hat))
        return self.mechanics.k.molecular_field_kernel(
            q1, q2, A, mech.Jm1, mech.Ebar_dev, lap, p.A0, p.C, 2.0 * p.B_prime, p.B, p.K
        )

    def corotational_rates(
        self, q1: Array, q2: Array, H: Array, mech: MechanicalState, t: float | None = None
    ) -> tuple[Array, Array]:
        r"""``(Qdot components, omega)``: :math:`\dot Q = H/\gamma + W Q - Q W` with the spin
        slaved to :math:`\dot Q` through the displacement rate (see
        :mod:`nematic_solids.model.mechanics`)."""
        return self.mechanics.corotational(mech, q1, q2, H / self.params.gamma, t)

    def activity_rate(self, A: Array, mech: MechanicalState) -> Array:
        r"""Paper Eq. (5): :math:`(-\zeta A - \chi\, \mathrm{tr} P - s A^3)/\tau` (the
        backend's ``activity_rate``); with ``coupling = "trS"`` the trace of the second Piola
        stress instead (finite strain; at small strain they are one)."""
        p = self.params
        tr = mech.trS if p.coupling == "trS" and mech.trS is not None else mech.trP
        return self.mechanics.k.activity_rate(A, tr, p.zeta, p.chi, p.s, p.tau)

    def rates(
        self,
        q1: Array,
        q2: Array,
        A: Array,
        t: float | None = None,
        u_hat: Array | None = None,
        q_hat: Array | None = None,
        F: Array | None = None,
    ) -> tuple[Array, MechanicalState, Array]:
        """Return ``(d/dt [q1, q2, A], mechanical state, omega)``: with the displacement in
        force balance (Eq. 3, solved), or at the given displacement spectrum ``u_hat``
        (finite mechanics only; the integrated-displacement stages of the solver) with its
        deformation gradient ``F`` if known. ``q_hat``: the spectra of q1, q2 if known (saves
        transforms)."""
        mechanics = self.mechanics
        if u_hat is None:
            mech = mechanics.solve(q1, q2, t=t)
        else:
            mech = mechanics.state_at(u_hat, q1, q2, t, F)
        H = self.molecular_field(q1, q2, A, mech, q_hat)
        rate = np.empty((3,) + A.shape)
        rate[:2], omega = self.corotational_rates(q1, q2, H, mech, t)
        rate[2] = self.activity_rate(A, mech)
        return rate, mech, omega

    def evolution_rate(self, state: FieldCollection, t: float = 0) -> FieldCollection:  # type: ignore[override]
        self.use_grid_of(state)
        self.at_time(t)
        q1, q2, A = state.data
        rate, _, _ = self.rates(q1, q2, A, t)
        if not np.all(np.isfinite(rate)):
            raise SimulationFailure("nan", "non-finite rate", t)
        out = state.copy()
        out.data[:] = rate
        return out
