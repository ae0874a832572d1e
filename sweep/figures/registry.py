"""The figures a campaign can ask for (``figures:`` in its YAML), by name: :data:`REGISTRY`,
with the fits each needs and the grids it applies to."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import xarray as xr

from ..analysis.phase import is_swept
from ..campaign import AMB, BRANCH
from .common import Results, invalid_options
from .fig2 import FIG2_OPTIONS, fig2
from .fig3 import FIG3_OPTIONS, fig3
from .fig3_growth import FIG3_GROWTH_OPTIONS, fig3_growth
from .fig4 import FIG4_OPTIONS, fig4
from .figA1 import FIGA1_OPTIONS, figA1
from .loop import LOOP_OPTIONS, loop
from .moduli import MODULI_FIGURE_OPTIONS, moduli_figure
from .switch import LEVEL, SWITCH_OPTIONS, switch

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FigureFunction = Callable[[Results, Mapping[str, Any]], "Figure"]


def _swept_all(*names: str) -> Callable[[xr.Dataset], bool]:
    return lambda phase: BRANCH not in phase.dims and all(is_swept(phase, n) for n in names)


def _oscillatory(phase: xr.Dataset) -> bool:
    """A campaign whose protocol has a sine of eps (an oscillatory shear)."""
    raw = str(phase.attrs.get("param_protocol", ""))
    return '"eps": {"sine"' in raw and BRANCH not in phase.dims


def _chained(phase: xr.Dataset) -> bool:
    return BRANCH in phase.dims


def _loop_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("transition", {"axis": str(phase.attrs.get("chain_axis", AMB))})]


def _fig4_applies(phase: xr.Dataset) -> bool:
    if BRANCH in phase.dims:
        return False
    n = sum(is_swept(phase, a) for a in ("chi", "K", "eps"))
    return n >= 2 and str(phase.attrs.get("num_mechanics", "finite")) == "finite"


def _figA1_applies(phase: xr.Dataset) -> bool:
    return (
        BRANCH not in phase.dims
        and is_swept(phase, "eps")
        and (is_swept(phase, "chi") or is_swept(phase, AMB))
        and str(phase.attrs.get("num_mechanics", "")) == "linear"
    )


@dataclass(frozen=True)
class FigureSpec:
    """A registered figure: how to draw it, which fits it needs, when it applies."""

    function: FigureFunction
    description: str
    fits: Callable[[xr.Dataset], list[tuple[str, dict[str, Any]]]]
    applies: Callable[[xr.Dataset], bool] = field(default=lambda phase: True)
    options: tuple[str, ...] = ()


def _fig2_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("transition", {"axis": AMB})]


def _fig3_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("scaling", {}), ("transition", {"axis": AMB})]


def _fig4_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("anisotropy", {})] if is_swept(phase, "eps") else []


def _figA1_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("stability", {})]


REGISTRY: dict[str, FigureSpec] = {
    "fig2": FigureSpec(
        fig2,
        "snapshot, sigma2_S(t) and sigma2_S(t_final) vs alpha - B",
        _fig2_fits,
        _swept_all(AMB),
        FIG2_OPTIONS,
    ),
    "fig3": FigureSpec(
        fig3,
        "pattern size vs K / (alpha - B - alpha_cr), inset alpha_cr(K)",
        _fig3_fits,
        _swept_all(AMB, "K"),
        FIG3_OPTIONS,
    ),
    "fig3_growth": FigureSpec(
        fig3_growth,
        "lambda(t) and sigma2_S(t) for several alpha - B at one K, the growth peak marked",
        lambda phase: [],
        _swept_all(AMB, "K"),
        FIG3_GROWTH_OPTIONS,
    ),
    "fig4": FigureSpec(
        fig4,
        "phase diagram over chi (alpha - B), K, eps with snapshots",
        _fig4_fits,
        _fig4_applies,
        FIG4_OPTIONS,
    ),
    "loop": FigureSpec(
        loop,
        "a chain's hysteresis loop: both branches, each jump, the settling time per point",
        _loop_fits,
        _chained,
        LOOP_OPTIONS,
    ),
    "moduli": FigureSpec(
        moduli_figure,
        "an oscillatory shear's storage and loss moduli vs the sweep, and the stress-strain loop",
        lambda phase: [("moduli", {})],
        _oscillatory,
        MODULI_FIGURE_OPTIONS,
    ),
    "switch": FigureSpec(
        switch,
        "a pattern through a switch-off of activity: sigma2_S(t), how far it fell, its memory",
        lambda phase: [("recovery", {})],
        lambda phase: LEVEL in phase.dims,
        SWITCH_OPTIONS,
    ),
    "figA1": FigureSpec(
        figA1,
        "stable/unstable runs in (chi (alpha - B), eps) and the linear-stability boundary",
        _figA1_fits,
        _figA1_applies,
        FIGA1_OPTIONS,
    ),
}


def option_problems(name: str, options: Mapping[str, Any]) -> list[str]:
    """What is wrong with the options of registered figure ``name`` (empty if nothing), for
    validating a campaign before it runs."""
    if name not in REGISTRY:
        return [f"unknown figure {name!r}; registered: {', '.join(sorted(REGISTRY))}"]
    return invalid_options(name, options, REGISTRY[name].options)
