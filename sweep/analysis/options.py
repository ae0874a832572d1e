"""The options every fit takes (:data:`COMMON_OPTIONS`) and the check of a fit's options."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from ..errors import FitError

COMMON_OPTIONS = ("n_boot", "confidence", "bootstrap_seed", "select")


def bootstrap_rng(options: Mapping[str, Any]) -> np.random.Generator:
    """The generator of a fit's bootstrap, seeded with its ``bootstrap_seed`` (default 0)."""
    return np.random.default_rng(int(options.get("bootstrap_seed", 0)))


def invalid_options(name: str, options: Mapping[str, Any], allowed: Iterable[str]) -> list[str]:
    """What is wrong with the ``options`` of fit ``name``, whose own options are ``allowed``
    (besides :data:`COMMON_OPTIONS`): one message per problem, empty if none."""
    valid = sorted({*allowed, *COMMON_OPTIONS})
    out = [
        f"unknown option {key!r}; allowed: {', '.join(valid)}"
        for key in options
        if key not in valid
    ]
    n_boot = options.get("n_boot", 1000)
    if not isinstance(n_boot, int) or isinstance(n_boot, bool) or n_boot < 1:
        out.append(f"n_boot = {n_boot!r}; expected an integer >= 1")
    conf = options.get("confidence", 0.95)
    if isinstance(conf, bool) or not isinstance(conf, (int, float)) or not 0 < conf < 1:
        out.append(f"confidence = {conf!r}; expected 0 < confidence < 1")
    sel = options.get("select")
    if sel is not None and not isinstance(sel, Mapping):
        out.append(f"select = {sel!r}; expected a mapping {{sweep axis: value}}")
    bound = options.get("alpha_cr_min")
    if bound is not None and (
        isinstance(bound, bool) or not isinstance(bound, (int, float)) or not math.isfinite(bound)
    ):
        out.append(
            f"alpha_cr_min = {bound!r}; expected a number (the lower bound of alpha_cr) "
            "or null (no bound)"
        )
    require = options.get("require_peak")
    if require is not None and not isinstance(require, bool):
        out.append(f"require_peak = {require!r}; expected true or false")
    margin = options.get("peak_margin", 1.0)
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not margin >= 0:
        out.append(f"peak_margin = {margin!r}; expected a number of save intervals >= 0")
    return out


def check_options(name: str, options: Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Raise :class:`FitError` naming every problem of :func:`invalid_options`."""
    problems = invalid_options(name, options, allowed)
    if problems:
        raise FitError(f"fit {name!r}: " + "; ".join(problems))
