"""The fits a campaign can ask for (``fits:`` in its YAML), by name: :data:`REGISTRY`."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import xarray as xr

from ..campaign import AMB, DEFAULT_MODEL
from ..errors import FitError
from .anisotropy import ANISOTROPY_OPTIONS, anisotropy
from .options import invalid_options
from .recovery import RECOVERY_OPTIONS, recovery
from .rheology import MODULI_OPTIONS, moduli
from .shape import Shape, pick_one
from .sizes import SIZE_OPTIONS, alpha_cr, scaling
from .stability import STABILITY_OPTIONS, stability
from .transition import TRANSITION_OPTIONS, transition

FitFunction = Callable[[xr.Dataset, Mapping[str, Any], Path | None], xr.Dataset]


Needs = Callable[[Shape, Mapping[str, Any]], "str | None"]


@dataclass(frozen=True)
class FitSpec:
    """A registered fit: its function, its options (besides :data:`COMMON_OPTIONS`), the
    fits it also writes, and why it cannot be fitted for a campaign of some shape (``needs``:
    a sentence, or None when it can; the validator reports it at the fit's file:line)."""

    function: FitFunction
    description: str
    options: tuple[str, ...] = ()
    includes: tuple[str, ...] = ()
    needs: Needs = field(default=lambda shape, options: None)
    #: the models whose observables it reads (``model:``)
    models: tuple[str, ...] = (DEFAULT_MODEL,)


def _transition_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    return None if shape.dims else "the campaign sweeps nothing: no axis to fit along"


def _sizes_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    extra = shape.others(["K", AMB], options)
    return pick_one("alpha_cr/scaling (along K and alpha - B)", extra) if extra else None


def _anisotropy_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    axis = str(options.get("axis", "eps"))
    if axis in shape.protocol and not shape.swept(axis):
        return f"anisotropy is a trend along {axis}, which follows a time protocol here"
    return None


def _moduli_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    if shape.sine_of_eps():
        return None
    return "moduli needs an oscillatory shear: a sine of eps in protocol:"


def _recovery_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    if shape.pulse_of_activity() or options.get("switch") is not None:
        return None
    return "recovery needs a pulse of alpha_minus_B in protocol: (or the option switch: TIME)"


def _stability_needs(shape: Shape, options: Mapping[str, Any]) -> str | None:
    act = str(options.get("activity") or ("chi" if shape.swept("chi") else AMB))
    extra = shape.others([act, str(options.get("strain", "eps"))], options)
    return pick_one(f"stability (along {act} and eps)", extra) if extra else None


REGISTRY: dict[str, FitSpec] = {
    "transition": FitSpec(
        transition,
        "location of the jump of the seed-mean sigma2_S along "
        "an axis, interval from the grid and the seeds",
        TRANSITION_OPTIONS,
        needs=_transition_needs,
    ),
    "alpha_cr": FitSpec(
        alpha_cr,
        "critical activity alpha_cr(K) from the pattern sizes",
        SIZE_OPTIONS,
        needs=_sizes_needs,
    ),
    "scaling": FitSpec(
        scaling,
        "exponent of lambda vs K / (alpha - B - alpha_cr) with a seed "
        "bootstrap interval (includes alpha_cr)",
        SIZE_OPTIONS,
        includes=("alpha_cr",),
        needs=_sizes_needs,
    ),
    "anisotropy": FitSpec(
        anisotropy,
        "trend of <cos 2 theta> with the applied strain eps",
        ANISOTROPY_OPTIONS,
        needs=_anisotropy_needs,
    ),
    "moduli": FitSpec(
        moduli,
        "storage and loss moduli G', G'' from the stress under an oscillatory shear (a sine "
        "of eps)",
        MODULI_OPTIONS,
        needs=_moduli_needs,
    ),
    "recovery": FitSpec(
        recovery,
        "a pattern through a switch-off of activity: vanished, recovered, how fast, and its "
        "memory (correlation of S before and after)",
        RECOVERY_OPTIONS,
        needs=_recovery_needs,
    ),
    "stability": FitSpec(
        stability,
        "stable/unstable runs in the (activity, eps) plane and "
        "the linear-stability boundary (Fig. A1)",
        STABILITY_OPTIONS,
        needs=_stability_needs,
    ),
}


def option_problems(name: str, options: Mapping[str, Any]) -> list[str]:
    """What is wrong with the options of registered fit ``name`` (empty if nothing), for
    validating a campaign before it runs."""
    if name not in REGISTRY:
        return [f"unknown fit {name!r}; registered: {', '.join(sorted(REGISTRY))}"]
    return invalid_options(name, options, REGISTRY[name].options)


def fit_shape_problems(name: str, options: Mapping[str, Any], shape: Shape) -> list[str]:
    """Why registered fit ``name`` with ``options`` cannot be fitted for a campaign of
    ``shape`` (empty if it can, or if the name is unknown: :func:`option_problems` says so)."""
    if name not in REGISTRY:
        return []
    spec = REGISTRY[name]
    if shape.model not in spec.models:
        return [model_problem(spec.models, shape.model)]
    why = spec.needs(shape, options)
    return [] if why is None else [why]


def model_problem(models: tuple[str, ...], model: str) -> str:
    """Why a fit or figure of ``models`` is not made for a campaign of ``model``."""
    return (
        f"it reads the observables of the model {', '.join(models)}; this campaign runs the "
        f"model {model}"
    )


def resolve(requests: Iterable[tuple[str, Mapping[str, Any]]]) -> list[tuple[str, dict[str, Any]]]:
    """Normalise a list of (fit name, options): unknown names raise :class:`FitError`, a fit
    included in another requested one (``alpha_cr`` in ``scaling``) is merged into it,
    repeated names keep the first options."""
    out: dict[str, dict[str, Any]] = {}
    for name, options in requests:
        if name not in REGISTRY:
            raise FitError(f"unknown fit {name!r}; registered: {', '.join(sorted(REGISTRY))}")
        out.setdefault(name, dict(options or {}))
    for name, spec in REGISTRY.items():
        for inc in spec.includes:
            if name in out and inc in out:
                out[name] = {**out.pop(inc), **out[name]}
    return list(out.items())
