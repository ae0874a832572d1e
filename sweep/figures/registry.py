"""The figures a campaign can ask for (``figures:`` in its YAML), by name: :data:`REGISTRY`,
with the fits each needs, the grids it is drawn for unasked, and the campaigns it cannot be
drawn for (:func:`shape_problems`, which the validator reports at the figure's file:line)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..analysis.shape import Shape
from ..campaign import AMB, DEFAULT_MODEL
from .common import Results, invalid_options
from .fig2 import FIG2_OPTIONS, fig2
from .fig3 import FIG3_OPTIONS, fig3
from .fig3_growth import FIG3_GROWTH_OPTIONS, fig3_growth
from .fig4 import FIG4_OPTIONS, fig4
from .figA1 import FIGA1_OPTIONS, figA1
from .loop import LOOP_OPTIONS, loop
from .moduli import MODULI_FIGURE_OPTIONS, moduli_figure
from .swift_hohenberg import SH_OPTIONS, sh_phase
from .switch import DURATION, LEVEL, SWITCH_OPTIONS, switch

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FigureFunction = Callable[[Results, Mapping[str, Any]], "Figure"]
Fits = list[tuple[str, dict[str, Any]]]

#: a switch-off campaign's swept numbers of the pulse of alpha - B
LEVELS = (LEVEL, DURATION)


def _activity_line(figure: str) -> Callable[[Shape, Mapping[str, Any]], str | None]:
    """A figure along alpha - B from a fresh texture (figs. 2, 3)."""

    def needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
        if shape.chained:
            return f"{figure} draws runs that each start from a fresh texture; a chain draws loop"
        if not shape.swept(AMB):
            return f"{figure} needs alpha_minus_B (or alpha, or B) as a sweep axis"
        return None

    return needs


def _fig3_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    if shape.chained:
        return "fig3 draws runs that each start from a fresh texture; a chain draws loop"
    return None


def _fig4_axes(shape: Shape, options: Mapping[str, Any]) -> list[str]:
    chosen = set((options.get("select") or {}).keys())
    act = "chi" if shape.swept("chi") else AMB
    return [a for a in (act, "K", "eps") if shape.swept(a) and a not in chosen]


def _fig4_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    if len(_fig4_axes(shape, options)) < 2:
        return "fig4 needs at least two of chi (or alpha - B), K and eps swept (and not selected)"
    return None


def _fig4_applies(shape: Shape) -> bool:
    n = sum(shape.swept(a) for a in ("chi", "K", "eps"))  # unasked: not over alpha - B and K
    return not shape.chained and n >= 2 and shape.mechanics == "finite"


def _loop_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    return None if shape.chained else "loop draws a chain: the campaign has no chain: section"


def _switch_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    if not all(shape.swept(n) for n in LEVELS):
        return (
            "switch needs a switch-off of activity: a pulse of alpha_minus_B in protocol: "
            f"with {' and '.join(LEVELS)} swept"
        )
    return None


def _figA1_applies(shape: Shape) -> bool:
    return (
        not shape.chained
        and shape.swept("eps")
        and (shape.swept("chi") or shape.swept(AMB))
        and shape.mechanics == "linear"
    )


def _swept_all(*names: str) -> Callable[[Shape], bool]:
    return lambda shape: not shape.chained and all(shape.swept(n) for n in names)


@dataclass(frozen=True)
class FigureSpec:
    """A registered figure: how to draw it, which fits it needs, when it is drawn unasked
    (``applies``), and why it cannot be drawn for a campaign of some shape (``needs``: a
    sentence, or None when it can; the fits it asks for are checked besides)."""

    function: FigureFunction
    description: str
    fits: Callable[[Shape], Fits]
    applies: Callable[[Shape], bool] = field(default=lambda shape: True)
    options: tuple[str, ...] = ()
    needs: Callable[[Shape, Mapping[str, Any]], str | None] = field(
        default=lambda shape, options: None
    )
    #: the models whose observables it reads (``model:``)
    models: tuple[str, ...] = (DEFAULT_MODEL,)

    def drawn_for(self, shape: Shape) -> bool:
        """Whether it is drawn unasked for a campaign of ``shape``: its model's, and it
        applies."""
        return shape.model in self.models and self.applies(shape)


def _transition_along(axis: str) -> Callable[[Shape], Fits]:
    return lambda shape: [("transition", {"axis": axis})]


def _fig3_fits(shape: Shape) -> Fits:
    return [("scaling", {}), ("transition", {"axis": AMB})]


def _fig4_fits(shape: Shape) -> Fits:
    return [("anisotropy", {})] if shape.swept("eps") else []


REGISTRY: dict[str, FigureSpec] = {
    "fig2": FigureSpec(
        fig2,
        "snapshot, sigma2_S(t) and sigma2_S(t_final) vs alpha - B",
        _transition_along(AMB),
        _swept_all(AMB),
        FIG2_OPTIONS,
        _activity_line("fig2"),
    ),
    "fig3": FigureSpec(
        fig3,
        "pattern size vs K / (alpha - B - alpha_cr), inset alpha_cr(K)",
        _fig3_fits,
        _swept_all(AMB, "K"),
        FIG3_OPTIONS,
        _fig3_needs,
    ),
    "fig3_growth": FigureSpec(
        fig3_growth,
        "lambda(t) and sigma2_S(t) for several alpha - B at one K, the growth peak marked",
        lambda shape: [],
        _swept_all(AMB, "K"),
        FIG3_GROWTH_OPTIONS,
        _activity_line("fig3_growth"),
    ),
    "fig4": FigureSpec(
        fig4,
        "phase diagram over chi (alpha - B), K, eps with snapshots",
        _fig4_fits,
        _fig4_applies,
        FIG4_OPTIONS,
        _fig4_needs,
    ),
    "sh_phase": FigureSpec(
        sh_phase,
        "Swift-Hohenberg: both branches' patterns over (eps, g) against the amplitude equations",
        lambda shape: [],
        lambda shape: shape.chained and shape.swept("eps") and shape.swept("g"),
        SH_OPTIONS,
        lambda shape, options: (
            None
            if shape.chained and shape.swept("eps") and shape.swept("g")
            else "a chain along eps over a sweep of g"
        ),
        models=("swift-hohenberg",),
    ),
    "loop": FigureSpec(
        loop,
        "a chain's hysteresis loop: both branches, each jump, the settling time per point",
        lambda shape: [("transition", {"axis": shape.chain_axis or AMB})],
        lambda shape: shape.chained,
        LOOP_OPTIONS,
        _loop_needs,
    ),
    "moduli": FigureSpec(
        moduli_figure,
        "an oscillatory shear's storage and loss moduli vs the sweep, and the stress-strain loop",
        lambda shape: [("moduli", {})],
        lambda shape: shape.sine_of_eps() and not shape.chained,
        MODULI_FIGURE_OPTIONS,
    ),
    "switch": FigureSpec(
        switch,
        "a pattern through a switch-off of activity: sigma2_S(t), how far it fell, its memory",
        lambda shape: [("recovery", {})],
        lambda shape: all(shape.swept(n) for n in LEVELS),
        SWITCH_OPTIONS,
        _switch_needs,
    ),
    "figA1": FigureSpec(
        figA1,
        "stable/unstable runs in (chi (alpha - B), eps) and the linear-stability boundary",
        lambda shape: [("stability", {})],
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


def shape_problems(
    name: str, options: Mapping[str, Any], shape: Shape, fits: Mapping[str, Mapping[str, Any]]
) -> list[str]:
    """Why registered figure ``name`` with ``options`` cannot be drawn for a campaign of
    ``shape`` (empty if it can): the figure's own needs and those of the fits it asks for, with
    the options of the campaign's own ``fits`` entry where it has one (they win)."""
    from ..analysis.registry import fit_shape_problems, model_problem

    spec = REGISTRY[name]
    if shape.model not in spec.models:
        return [model_problem(spec.models, shape.model)]
    why = spec.needs(shape, options)
    out = [] if why is None else [why]
    for fit, fit_options in spec.fits(shape):
        for problem in fit_shape_problems(fit, fits.get(fit, fit_options), shape):
            out.append(f"{name} needs the fit {fit}: {problem}")
    return out
