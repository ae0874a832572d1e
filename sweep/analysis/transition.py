r"""The ``transition`` fit: where the seed mean of an observable jumps along a sweep axis
(docs/campaigns/fits.md, "Fits")."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from ..campaign import BRANCH
from ..errors import FitError
from .options import bootstrap_rng, check_options
from .phase import coord_copy, default_axis, other_dims, select, variable, with_dim
from .statistics import Array, bootstrap_seed_means, finite_mean, log10, percentiles

TRANSITION_OPTIONS = ("axis", "observable", "log", "min_jump", "mean", "prefix", "crossing")


@dataclass(frozen=True)
class TransitionFit:
    """Result of :func:`fit_transition` (see docs/campaigns/fits.md, "Fits" for the definitions)."""

    location: float
    lower: float
    upper: float
    grid_lower: float
    grid_upper: float
    seed_lower: float
    seed_upper: float
    jump: float
    level: float
    direction: int
    fraction_high: Array = field(repr=False)
    #: why the location is NaN ("" when it is not)
    reason: str = ""


def largest_step(x: Array, y: Array, across: float | None = None) -> tuple[int, int, float]:
    """Indices ``(i, j)`` of the neighbouring finite points (``x`` sorted) with the largest
    ``|y_j - y_i|`` (among the steps from one side of ``across`` to the other, if given) and
    that signed step; ``(-1, -1, nan)`` with fewer than two points (or no such step)."""
    idx = np.nonzero(np.isfinite(y))[0]
    if idx.size < 2:
        return -1, -1, math.nan
    steps = crossing_steps(y[idx][None], across)[0]
    if not np.any(np.isfinite(steps)):
        return -1, -1, math.nan
    k = int(np.nanargmax(np.abs(steps)))
    return int(idx[k]), int(idx[k + 1]), float(steps[k])


def crossing_steps(y: Array, across: float | None) -> Array:
    """The steps between neighbours along the last axis of ``y``; with ``across``, NaN
    where a step does not go from one side of it to the other."""
    steps = np.diff(y, axis=-1)
    if across is None:
        return steps
    crossed = (y[..., :-1] - across) * (y[..., 1:] - across) < 0
    return np.where(crossed, steps, np.nan)


def fit_transition(
    x: ArrayLike,
    values: ArrayLike,
    *,
    log: bool = True,
    min_jump: float = 1.0,
    mean: str = "geometric",
    n_boot: int = 1000,
    confidence: float = 0.95,
    rng: np.random.Generator | None = None,
    crossing: float | None = None,
) -> TransitionFit:
    r"""Locate the jump of the seed mean of ``values`` (shape ``(len(x), n_seeds)``, NaN for
    missing runs) along ``x``; see docs/campaigns/fits.md. With ``log`` the step is measured in
    decades, else in the observable's units; a step below ``min_jump`` is not a transition
    (location NaN). ``mean``: ``geometric`` (with ``log``, the seed mean of
    :math:`\log_{10}` values) or ``arithmetic`` (log of the seed mean, which one patterned seed
    among many relaxed ones already lifts by orders of magnitude: it marks the onset).
    ``crossing``: a value of the observable the jump must cross (e.g. a patterned level), so
    that steps among values all below it (the relaxation of a texture at round-off level) or
    all above it are not the transition."""
    if mean not in ("geometric", "arithmetic"):
        raise FitError(f"transition: mean = {mean!r}; expected 'geometric' or 'arithmetic'")
    rng = rng if rng is not None else np.random.default_rng(0)
    xa = np.asarray(x, dtype=float)
    v = np.asarray(values, dtype=float)
    if v.ndim != 2 or v.shape[0] != xa.size:
        raise FitError(f"values must have shape (len(x), n_seeds) = ({xa.size}, n); got {v.shape}")
    order = np.argsort(xa)
    xa, v = xa[order], v[order]

    geometric = log and mean == "geometric"
    samples = log10(v) if geometric else v

    def transform(m: Array) -> Array:
        return log10(m) if log and not geometric else m

    y = transform(finite_mean(samples))
    across = None if crossing is None else (math.log10(crossing) if log else float(crossing))
    i, j, step = largest_step(xa, y, across)
    nan = math.nan
    frac = np.full(xa.size, np.nan)
    if i < 0 or not abs(step) >= min_jump:
        why = no_jump_reason(y, step, min_jump, crossing, log, geometric)
        return TransitionFit(nan, nan, nan, nan, nan, nan, nan, step, nan, 0, frac, why)
    level = 0.5 * (y[i] + y[j])
    direction = 1 if step > 0 else -1
    tv = log10(v) if log else v
    ok = np.isfinite(tv)
    n = ok.sum(axis=1)
    high = (np.where(ok, direction * (tv - level), -np.inf) > 0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(n > 0, high / np.maximum(n, 1), np.nan)
    location = 0.5 * (xa[i] + xa[j])
    boot = transform(bootstrap_seed_means(samples, n_boot, rng))
    # A grid value has a (finite) bootstrap mean iff it has a run: the same points as ``y``.
    idx = np.nonzero(np.isfinite(y))[0]
    steps = np.nan_to_num(crossing_steps(boot[:, idx], across), nan=0.0)
    k = np.argmax(np.abs(steps), axis=1)
    big = np.abs(np.take_along_axis(steps, k[:, None], axis=1)[:, 0]) >= max(min_jump, 1e-300)
    lows = np.where(big, xa[idx[k]], np.nan)
    highs = np.where(big, xa[idx[k + 1]], np.nan)
    mids = 0.5 * (lows + highs)
    seed_lower, seed_upper = percentiles(mids, confidence)
    blo, _ = percentiles(lows, confidence)
    _, bhi = percentiles(highs, confidence)
    lower = float(np.nanmin([xa[i], blo]))
    upper = float(np.nanmax([xa[j], bhi]))
    return TransitionFit(
        location=float(location),
        lower=lower,
        upper=upper,
        grid_lower=float(xa[i]),
        grid_upper=float(xa[j]),
        seed_lower=seed_lower,
        seed_upper=seed_upper,
        jump=step,
        level=float(level),
        direction=direction,
        fraction_high=frac,
    )


def no_jump_reason(
    y: Array, step: float, min_jump: float, crossing: float | None, log: bool, geometric: bool
) -> str:
    """Why :func:`fit_transition` found no transition in the seed means ``y``: one sentence."""
    finite = int(np.isfinite(y).sum())
    if finite < 2:
        return f"{finite} grid value(s) with a finite seed mean: a jump needs two"
    unit = " decades" if log else ""
    if math.isnan(step):  # only with a crossing: no step goes across it
        mean = "geometric seed mean (the mean of log10)" if geometric else "seed mean"
        return f"the {mean} never crosses {crossing:g}, the class threshold (crossing); " + (
            "a seed that stays below it pulls the geometric mean down: the option "
            "mean: arithmetic marks where the first seed crosses"
            if geometric
            else "no grid value has its mean on the other side"
        )
    return (
        f"the largest step of the seed mean, {abs(step):.3g}{unit}, is below min_jump {min_jump:g}"
    )


def transition(
    phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
) -> xr.Dataset:
    """The ``transition`` fit (docs/campaigns/fits.md, "Fits"). Options: ``axis``, ``observable``
    (default ``sigma2_S``), ``log`` (default true), ``min_jump`` (decades, default 1),
    ``prefix`` (variable prefix, default ``transition``), and the common options."""
    check_options("transition", options, TRANSITION_OPTIONS)
    ds = select(phase, options.get("select"))
    axis = str(options.get("axis") or default_axis(ds))
    observable = str(options.get("observable", "sigma2_S"))
    if observable not in ds:
        raise FitError(f"transition: observable {observable!r} is not in phase.nc")
    ds = with_dim(ds, axis)
    others = other_dims(ds, [axis])
    data = ds[observable].transpose(*others, axis, "seed")
    x = ds[axis].values.astype(float)
    pre = str(options.get("prefix", "transition"))
    log_scale = bool(options.get("log", True))
    min_jump = float(options.get("min_jump", 1.0 if log_scale else 0.0))
    mean_kind = str(options.get("mean", "geometric"))
    rng = bootstrap_rng(options)
    oshape = tuple(ds.sizes[d] for d in others)
    flat = data.values.reshape(-1, x.size, data.sizes["seed"])
    names = (
        "location",
        "lower",
        "upper",
        "grid_lower",
        "grid_upper",
        "seed_lower",
        "seed_upper",
        "jump",
        "level",
        "direction",
    )
    out = {n: np.full(flat.shape[0], np.nan) for n in names}
    reasons: list[str] = []
    frac = np.full((flat.shape[0], x.size), np.nan)
    order = np.argsort(x)
    for k in range(flat.shape[0]):
        f = fit_transition(
            x,
            flat[k],
            log=log_scale,
            min_jump=min_jump,
            mean=mean_kind,
            n_boot=int(options.get("n_boot", 1000)),
            confidence=float(options.get("confidence", 0.95)),
            rng=rng,
            crossing=None if options.get("crossing") is None else float(options["crossing"]),
        )
        for n in names:
            out[n][k] = getattr(f, n)
        frac[k, order] = f.fraction_high
        reasons.append(f.reason)
    unit = "1"  # CF: a pure number; a log-scale jump is in decades (its long_name says so)
    what = f"seed mean of {observable} along {axis}"
    long = {
        "location": f"transition location: midpoint of the grid bracket of the largest step "
        f"of the {what}",
        "lower": "transition interval, lower end (grid bracket and seed bootstrap combined)",
        "upper": "transition interval, upper end (grid bracket and seed bootstrap combined)",
        "grid_lower": "grid value below the largest step",
        "grid_upper": "grid value above the largest step",
        "seed_lower": "seed-bootstrap percentile interval of the location, lower end",
        "seed_upper": "seed-bootstrap percentile interval of the location, upper end",
        "jump": f"signed size of the largest step of the {what}"
        + (" (decades: in log10 of the observable)" if log_scale else ""),
        "level": "mid level of the step (log10 of the observable when log)",
        "direction": "+1 if the observable rises across the transition, -1 if it falls",
    }
    coords = coord_copy(ds, others)
    result = xr.Dataset(coords=coords)
    for n in names:
        result[f"{pre}_{n}"] = variable(others, out[n].reshape(oshape), long[n], unit)
    result[f"{pre}_fraction_high"] = variable(
        [*others, axis],
        frac.reshape(*oshape, x.size),
        "fraction of seeds beyond the step's mid level",
    )
    result = result.assign_coords({axis: ds[axis].variable})
    attrs = {
        "axis": axis,
        "observable": observable,
        "log": int(log_scale),
        "min_jump": min_jump,
        "mean": mean_kind,
        "crossing": "none" if options.get("crossing") is None else float(options["crossing"]),
        "method": "largest step of the seed mean; bracket midpoint",
        "n_seeds": int(ds.sizes["seed"]),
    }
    why = nan_reason(reasons, [dict(zip(others, c, strict=True)) for c in _cells(ds, others)])
    for n in names:
        result[f"{pre}_{n}"].attrs.update({f"fit_{k}": v for k, v in attrs.items()})
        if why and n not in ("jump", "direction"):
            result[f"{pre}_{n}"].attrs["nan_reason"] = why
    if BRANCH in others:
        _loop_width(result, pre, attrs)
    return result


def _cells(ds: xr.Dataset, dims: list[str]) -> list[tuple[Any, ...]]:
    """The values of ``dims`` of each fitted line, in the order of the flattened fit."""
    import itertools

    return list(itertools.product(*([v.item() for v in ds[d].values] for d in dims)))


def nan_reason(reasons: list[str], cells: list[dict[str, Any]]) -> str:
    """The ``nan_reason`` attribute of a fit over several lines: each line's reason with the
    values that name the line (``branch = up: ...``), "" when no line is NaN."""
    parts = []
    for why, cell in zip(reasons, cells, strict=True):
        if why:
            where = ", ".join(
                f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}" for k, v in cell.items()
            )
            parts.append(f"{where}: {why}" if where else why)
    return "; ".join(parts)


def _loop_width(result: xr.Dataset, pre: str, attrs: Mapping[str, Any]) -> None:
    """A chain's two branches (nematic_solids.sweep.chains): the width of the hysteresis loop, the
    up branch's jump minus the down branch's, with the interval of the two jumps' intervals combined
    (from the lower end of one to the upper end of the other); NaN without both jumps."""
    branches = [str(b) for b in result[BRANCH].values]
    if "up" not in branches or "down" not in branches:
        return
    up, down = (result.sel({BRANCH: b}, drop=True) for b in ("up", "down"))
    width = {
        "loop_width": up[f"{pre}_location"] - down[f"{pre}_location"],
        "loop_width_lower": up[f"{pre}_lower"] - down[f"{pre}_upper"],
        "loop_width_upper": up[f"{pre}_upper"] - down[f"{pre}_lower"],
    }
    long = {
        "loop_width": "hysteresis loop width: the up branch's transition location minus the "
        "down branch's",
        "loop_width_lower": "hysteresis loop width, lower end (up branch's lower end minus the "
        "down branch's upper end)",
        "loop_width_upper": "hysteresis loop width, upper end (up branch's upper end minus the "
        "down branch's lower end)",
    }
    lost = str(result[f"{pre}_location"].attrs.get("nan_reason", ""))
    for name, value in width.items():
        value.attrs = {"long_name": long[name], "units": "1"}
        value.attrs.update({f"fit_{k}": v for k, v in attrs.items()})
        if not np.all(np.isfinite(value.values)):
            value.attrs["nan_reason"] = "no transition on a branch: " + (
                lost or "the loop width needs one on both"
            )
        result[f"{pre}_{name}"] = value
