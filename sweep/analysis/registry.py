"""The fits a campaign can ask for (``fits:`` in its YAML), by name: :data:`REGISTRY`."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import xarray as xr

from ..errors import FitError
from .anisotropy import ANISOTROPY_OPTIONS, anisotropy
from .options import invalid_options
from .recovery import RECOVERY_OPTIONS, recovery
from .rheology import MODULI_OPTIONS, moduli
from .sizes import SIZE_OPTIONS, alpha_cr, scaling
from .stability import STABILITY_OPTIONS, stability
from .transition import TRANSITION_OPTIONS, transition

FitFunction = Callable[[xr.Dataset, Mapping[str, Any], Path | None], xr.Dataset]


@dataclass(frozen=True)
class FitSpec:
    """A registered fit: its function, its options (besides :data:`COMMON_OPTIONS`) and the
    fits it also writes."""

    function: FitFunction
    description: str
    options: tuple[str, ...] = ()
    includes: tuple[str, ...] = ()


REGISTRY: dict[str, FitSpec] = {
    "transition": FitSpec(
        transition,
        "location of the jump of the seed-mean sigma2_S along "
        "an axis, interval from the grid and the seeds",
        TRANSITION_OPTIONS,
    ),
    "alpha_cr": FitSpec(
        alpha_cr, "critical activity alpha_cr(K) from the pattern sizes", SIZE_OPTIONS
    ),
    "scaling": FitSpec(
        scaling,
        "exponent of lambda vs K / (alpha - B - alpha_cr) with a seed "
        "bootstrap interval (includes alpha_cr)",
        SIZE_OPTIONS,
        includes=("alpha_cr",),
    ),
    "anisotropy": FitSpec(
        anisotropy, "trend of <cos 2 theta> with the applied strain eps", ANISOTROPY_OPTIONS
    ),
    "moduli": FitSpec(
        moduli,
        "storage and loss moduli G', G'' from the stress under an oscillatory shear (a sine "
        "of eps)",
        MODULI_OPTIONS,
    ),
    "recovery": FitSpec(
        recovery,
        "a pattern through a switch-off of activity: vanished, recovered, how fast, and its "
        "memory (correlation of S before and after)",
        RECOVERY_OPTIONS,
    ),
    "stability": FitSpec(
        stability,
        "stable/unstable runs in the (activity, eps) plane and "
        "the linear-stability boundary (Fig. A1)",
        STABILITY_OPTIONS,
    ),
}


def option_problems(name: str, options: Mapping[str, Any]) -> list[str]:
    """What is wrong with the options of registered fit ``name`` (empty if nothing), for
    validating a campaign before it runs."""
    if name not in REGISTRY:
        return [f"unknown fit {name!r}; registered: {', '.join(sorted(REGISTRY))}"]
    return invalid_options(name, options, REGISTRY[name].options)


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
