r"""Resolution from the physics: the grid a run needs, chosen from its parameters.

The finest length of the model's patterns is set by the Frank elasticity against the
Landau-de Gennes stiffness: the Frank length

.. math:: \ell_F = \sqrt{K / A_0}

(units of L; paper Eq. (1)'s :math:`K |\nabla Q|^2` against :math:`A_0\, \mathrm{tr}\, Q^2`),
the width of the walls between ordered domains. A grid resolves them when its spacing
:math:`L / N` is a fixed fraction of :math:`\ell_F`, so a rule gives

.. math:: N = \min\bigl(N_{\max},\ \min\{ N_{\min} 2^j \ge c / \ell_F : j = 0, 1, \dots\}\bigr),

the coarsest grid of the ladder :math:`N_{\min}, 2 N_{\min}, 4 N_{\min}, \dots` with at least
:math:`c` cells per Frank length, and at most the cap. The constant :math:`c`
(``cells_per_frank``) comes from the convergence study in docs/model/resolution.md: the grid at
which lambda and sigma2_S move by less than 5 % on the next doubling.

A rule is written ``"auto"`` (the defaults below) or as a mapping of its three numbers
(``{"cells_per_frank": 1.3, "floor": 128, "cap": 1024}``, each optional); :func:`read_rule`
reads either and :meth:`ResolutionRule.grid` gives a run's N. A run's identity holds the N
(the rule is how it was chosen, not what was run), so a point the rule puts on 128^2 is the
same run as one asked for at 128^2.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from .errors import ParameterError

#: The word that asks for the default rule.
AUTO = "auto"
#: The rule's numbers and what each may be.
KEYS = ("cells_per_frank", "floor", "cap")
ALLOWED = (
    "an even integer >= 16, 'auto' (the grid from K: docs/model/resolution.md) or "
    "a rule {cells_per_frank: C > 0, floor: N0, cap: N1} (even N0 <= N1, each "
    "optional)"
)


@dataclass(frozen=True)
class ResolutionRule:
    """At least ``cells_per_frank`` grid cells per Frank length sqrt(K / A0), on the ladder
    ``floor * 2**j``, at most ``cap``.

    Attributes:
        cells_per_frank: c, cells per Frank length. 1.3 from the convergence study
            (docs/model/resolution.md): 128^2 at K = 1e-5 (1.28 cells)
            moves lambda(100) by 10.6 % on doubling, every grid with 1.44 cells or more by
            less than 5 %. At K = 1e-6 it asks for 512^2 where 256^2 (0.81 cells) already
            moves lambda by less than 5 %: conservative by one doubling there.
        floor: the coarsest grid (the paper's 128^2: every published point with a Frank
            length of c cells or more keeps its grid, and its run).
        cap: the finest grid (memory and time: a 1024^2 finite-strain run to t = 100 costs
            about 4x a 512^2 one).
    """

    cells_per_frank: float = 1.3
    floor: int = 128
    cap: int = 1024

    def __post_init__(self) -> None:
        c = self.cells_per_frank
        if not (isinstance(c, (int, float)) and not isinstance(c, bool) and 0 < c < math.inf):
            raise ParameterError("resolution", self.to_dict(), ALLOWED)
        for n in (self.floor, self.cap):
            if not (isinstance(n, int) and not isinstance(n, bool) and n >= 16 and n % 2 == 0):
                raise ParameterError("resolution", self.to_dict(), ALLOWED)
        if self.cap < self.floor:
            raise ParameterError("resolution", self.to_dict(), ALLOWED)

    def wanted(self, K: float, A0: float) -> float:
        """Cells per side the rule asks for: c / l_F (inf when K = 0, 0 when A0 = 0)."""
        if A0 <= 0:
            return 0.0
        if K <= 0:
            return math.inf
        return self.cells_per_frank / math.sqrt(K / A0)

    def grid(self, K: float, A0: float) -> int:
        """N for the constants K and A0: the coarsest of the ladder with c cells per Frank
        length, at most the cap."""
        want, n = self.wanted(K, A0), self.floor
        while n < want and 2 * n <= self.cap:
            n *= 2
        return n

    def capped(self, K: float, A0: float) -> bool:
        """Whether the cap holds this point below the rule's c cells per Frank length."""
        return self.grid(K, A0) < self.wanted(K, A0)

    def describe(self) -> str:
        """``auto (1.3 cells per Frank length, 128 to 1024)``."""
        return f"auto ({self.cells_per_frank:g} cells per Frank length, {self.floor} to {self.cap})"

    def to_dict(self) -> dict[str, Any]:
        return {"cells_per_frank": self.cells_per_frank, "floor": self.floor, "cap": self.cap}


def is_rule(value: Any) -> bool:
    """Whether a resolution setting is a rule (``"auto"`` or a mapping), not a number."""
    return value == AUTO or isinstance(value, Mapping)


def read_rule(value: Any) -> ResolutionRule:
    """The rule of a resolution setting ``"auto"`` or ``{cells_per_frank, floor, cap}``;
    :class:`~nematic_solids.model.errors.ParameterError` for anything else."""
    if value == AUTO:
        return ResolutionRule()
    if not isinstance(value, Mapping) or not value or set(value) - set(KEYS):
        raise ParameterError("resolution", value, ALLOWED)
    try:
        return ResolutionRule(**{str(k): v for k, v in value.items()})
    except ParameterError:
        raise ParameterError("resolution", dict(value), ALLOWED) from None


def resolve(value: Any, K: float, A0: float) -> int | Any:
    """The grid of a resolution setting at the constants K, A0: the rule's N for a rule,
    the setting itself otherwise (checked where the numerics are built; a word other than
    ``auto`` is refused here, with the rule among what is allowed)."""
    if isinstance(value, str) and not is_rule(value):
        raise ParameterError("resolution", value, ALLOWED)
    return read_rule(value).grid(K, A0) if is_rule(value) else value
