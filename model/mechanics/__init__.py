r"""Quasi-static force balance :math:`\mathrm{Div}\, P = 0` (paper Eq. 3), one module per piece:

==========  ============================================================================
module      what it holds
==========  ============================================================================
``base``    :class:`Mechanics` (the interface the solver and the PDE call),
            :class:`MechanicalState` (what a solve returns), :func:`applied_deformation`
``linear``  :class:`LinearMechanics`: small strain, one exact Fourier solve
``finite``  :class:`FiniteMechanics`: neo-Hookean + nemato-elastic, Newton-Krylov
==========  ============================================================================

:func:`make_mechanics` builds the one ``Numerics.mechanics`` names.
"""

from __future__ import annotations

from ..fourier import SpectralGrid
from ..parameters import Numerics, Parameters
from .base import MechanicalState, Mechanics, applied_deformation
from .finite import FiniteMechanics
from .linear import LinearMechanics

__all__ = [
    "FiniteMechanics",
    "LinearMechanics",
    "MechanicalState",
    "Mechanics",
    "applied_deformation",
    "make_mechanics",
]


def make_mechanics(params: Parameters, numerics: Numerics, grid: SpectralGrid) -> Mechanics:
    """The mechanics ``numerics.mechanics`` names, with its tolerances and backend."""
    if numerics.mechanics == "linear":
        return LinearMechanics(
            params,
            grid,
            incompressible=numerics.incompressible,
            spin_tol=numerics.spin_tol,
            backend=numerics.backend,
        )
    return FiniteMechanics(
        params,
        grid,
        tol=numerics.newton_tol,
        max_newton=numerics.max_newton,
        spin_tol=numerics.spin_tol,
        backend=numerics.backend,
        integrated=numerics.displacement == "integrated",
    )
