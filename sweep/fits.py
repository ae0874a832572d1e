r"""Fits of a campaign's phase diagram, with uncertainties: ``results/<name>/fits.nc``.

Every fit reads only results files (``phase.nc``; the ``stability`` fit also the run files
``runs/<run_id>.nc``) and returns an :class:`xarray.Dataset` whose variables carry the fit's
name as prefix. :func:`write_fits` merges them into ``fits.nc`` (written atomically).
Registered fits (:data:`REGISTRY`; a campaign lists them under ``fits:``, options as
``{name: {option: value}}``):

``transition``
    Where the seed mean of an observable (default ``sigma2_S`` at ``t_final``) jumps along one
    sweep axis (default ``alpha_minus_B``, else ``chi``, else ``eps``), for every combination
    of the other sweep values. The jump is the largest step of
    :math:`y(x) = \langle\log_{10}\sigma^2_S\rangle_{\rm seeds}(x)` (geometric seed mean;
    option ``mean: arithmetic`` uses :math:`\log_{10}\langle\sigma^2_S\rangle`, which the
    first seed to form a pattern already lifts by orders of magnitude, so it marks the onset
    rather than the transition of the majority) between neighbouring grid
    values :math:`x_i < x_{i+1}`; the location is the bracket's midpoint
    :math:`x_t = (x_i + x_{i+1})/2`. Interval: the union of the grid bracket
    :math:`[x_i, x_{i+1}]` (the grid cannot resolve more) and the bootstrap interval over
    seeds (resample the seeds of every grid point with replacement, redo the jump search;
    percentiles of the brackets' ends). A step smaller than ``min_jump`` decades is no
    transition (NaN). Also the fraction of seeds above the mid level
    :math:`(y_i + y_{i+1})/2` at every grid value (a subcritical transition shows seeds that
    disagree near the jump).

``alpha_cr``
    The critical activity :math:`\alpha^{cr}(K)` from the pattern sizes (paper Eq. (7),
    :math:`\lambda = c\,[K/(\alpha - B - \alpha^{cr})]^{1/2}`), for every Frank constant K:
    ``method: linear`` (default) fits :math:`\lambda^{-2} = m(\alpha - B) + b` to the seed
    means of :math:`\lambda` (ordinary least squares), so :math:`\alpha^{cr} = -b/m` and
    :math:`c = (mK)^{-1/2}`; ``method: nonlinear`` fits
    :math:`\lambda = c\,[K/(\alpha - B - \alpha^{cr})]^{p}` with :math:`p` = ``exponent``
    (default 1/2) by least squares in :math:`\lambda` (c in closed form, a bounded scalar
    search over :math:`\alpha^{cr}`). The fit is bounded: :math:`\alpha^{cr} \ge`
    ``alpha_cr_min`` (default 0: a negative critical activity is unphysical, it would put the
    onset of patterning below zero contractility, where nothing drives it). When
    the unbounded optimum lies below the bound, the bounded fit is at the bound
    (:math:`\alpha^{cr}` = ``alpha_cr_min``, the linear fit becomes
    :math:`\lambda^{-2} = m(\alpha - B - \alpha^{cr}_{\min})`, the least-squares optimum under
    the bound) and ``alpha_cr_at_bound`` is 1; ``alpha_cr_bound_fraction`` is the fraction of
    bootstrap replicates at the bound. ``alpha_cr_min: null`` fits without bound. Only
    patterned runs count: those whose :math:`\sigma^2_S(t_{\rm final})` exceeds ``min_sigma2``
    (default: automatic, the middle of the widest gap of at least ``min_gap`` decades in the
    sorted :math:`\log_{10}\sigma^2_S` of all runs; no gap, every run counts). The pattern
    size is ``lambda_peak`` (Fig. 3: at the first peak of :math:`\sigma^2_S(t)` by the
    growth-peak rule, docs/model.md section 6) unless ``observable`` says otherwise
    (``lambda_peak_literal``: the paper's literal first-peak rule, checked against
    ``t_peak_literal``; ``lambda_mean_peak``: the mean-|k| length at the growth peak). A run
    whose first peak is at :math:`t_{\rm final}` or
    within ``peak_margin`` (default 1) save intervals of it (:math:`t_{\rm peak} \ge
    t_{\rm final} - {\rm peak\_margin}\cdot{\rm save\_every}`, from phase.nc's ``t_peak`` and
    the campaign's ``t_final`` and ``save_every``) has not reached its peak: its
    ``lambda_peak`` is merely :math:`\lambda` near :math:`t_{\rm final}`, not Fig. 3's
    quantity, so it is left out (``require_peak``, default true for the ``lambda*_peak*``
    observables, false for any other). The runs left out are counted per grid point
    (``alpha_cr_unpeaked_count``), per K (``alpha_cr_n_unpeaked``) and in total (attribute
    ``fit_n_unpeaked`` of ``alpha_cr`` and ``scaling_exponent``). Interval: bootstrap over
    seeds (of the runs that count).

``scaling``
    The exponent :math:`\beta` of :math:`\lambda = c\,x^{\beta}`,
    :math:`x = K/(\alpha - B - \alpha^{cr}(K))`, over all K (paper Eq. (7) predicts
    :math:`\beta = 1/2`): least squares on :math:`(\log_{10}x, \log_{10}\langle\lambda\rangle)`
    over the patterned grid points with :math:`\alpha - B > \alpha^{cr}`, from the same runs
    as ``alpha_cr`` (runs without a peak left out). The interval is a
    bootstrap over seeds of the whole chain (:math:`\alpha^{cr}(K)` refitted in every
    replicate). Also writes the ``alpha_cr`` variables; ``scaling_exponent`` carries the
    number of K whose :math:`\alpha^{cr}` is at its bound (``fit_n_alpha_cr_at_bound``).
    Note: with one K and the linear
    :math:`\alpha^{cr}` fit, :math:`\beta = 1/2` nearly by construction (:math:`\lambda^{-2}`
    linear in :math:`\alpha - B` *is* exponent 1/2 in :math:`\alpha - B`); the exponent is a
    test of the K dependence and needs several K.

``anisotropy``
    The trend of :math:`\langle\cos 2\theta\rangle` with the applied strain :math:`\varepsilon`
    (axis option, default ``eps``) for every combination of the other sweep values: seed mean
    and standard error per strain, and the slope :math:`d\langle\cos 2\theta\rangle/d\varepsilon`
    of a least-squares line through all runs, with a bootstrap interval over seeds.

``stability``
    Paper Fig. A1: every run is classified unstable when :math:`\sigma^2_S(t_{\rm final}) >
    \sigma^2_S(t_{\rm final}/2)` (the perturbation grows over the second half of the run) or
    when it failed with a reason in ``unstable_reasons`` (default ``spin_diverged``, the
    linear model losing well-posedness in the patterned state); the fraction of unstable seeds
    per (activity, strain) point; the simulated critical strain per activity (first strain
    with a majority of unstable seeds; interval from the grid: down to the strain before it
    that has classified runs) and the theory
    (:func:`model.stability.critical_eps_closed_form`, docs/stability.md Eq. (S10), and the
    paper's Eq. (6) as printed) on the grid and on a fine activity axis ``activity_fine``.

Intervals are central ``confidence`` (default 0.95) percentile intervals of ``n_boot``
(default 1000) bootstrap replicates drawn from a generator seeded with ``bootstrap_seed``
(default 0): the same phase.nc always gives the same fits.nc.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from model.errors import NematicError

from .provenance import code_version, git_commit, library_versions_text
from .spec import AMB
from .store import PHASE, atomic_to_netcdf, now_iso, series_time

log = logging.getLogger(__name__)

FITS = "fits.nc"
#: Floor for log10 of a (non-negative) variance: sigma2_S = 0 exactly happens (S0 = 0, no noise).
LOG_FLOOR = 1e-300
Array = NDArray[np.float64]

COMMON_OPTIONS = ("n_boot", "confidence", "bootstrap_seed", "select")
TRANSITION_OPTIONS = ("axis", "observable", "log", "min_jump", "mean", "prefix")
SIZE_OPTIONS = ("method", "exponent", "observable", "min_sigma2", "min_gap", "alpha_cr_min",
                "require_peak", "peak_margin")
ANISOTROPY_OPTIONS = ("axis", "observable")
STABILITY_OPTIONS = ("activity", "strain", "unstable_reasons", "fraction", "n_fine",
                     "incompressible")


class FitError(NematicError, ValueError):
    """A fit cannot be done on this phase diagram (missing axis, bad option, no data)."""


# --------------------------------------------------------------------------- small helpers
def _finite_mean(values: Array, axis: int = -1) -> Array:
    """Mean over ``axis`` ignoring NaN; NaN (no warning) where nothing is finite."""
    ok = np.isfinite(values)
    n = ok.sum(axis=axis)
    s = np.where(ok, values, 0.0).sum(axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def _finite_std(values: Array, axis: int = -1) -> Array:
    """Sample standard deviation (ddof = 1) ignoring NaN; NaN below two values."""
    ok = np.isfinite(values)
    n = ok.sum(axis=axis)
    m = _finite_mean(values, axis)
    d = np.where(ok, values - np.expand_dims(m, axis), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1, np.sqrt((d**2).sum(axis=axis) / np.maximum(n - 1, 1)), np.nan)


def _log10(values: ArrayLike) -> Array:
    v = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.isfinite(v), np.log10(np.maximum(v, LOG_FLOOR)), np.nan)


def _percentiles(samples: Array, confidence: float) -> tuple[float, float]:
    s = np.asarray(samples, dtype=float)
    s = s[np.isfinite(s)]
    if not s.size:
        return math.nan, math.nan
    lo, hi = np.percentile(s, [50 * (1 - confidence), 50 * (1 + confidence)])
    return float(lo), float(hi)


def bootstrap_seed_means(values: ArrayLike, n_boot: int, rng: np.random.Generator,
                         batch: int = 64) -> Array:
    """Bootstrap replicates of the seed mean at every point.

    ``values`` has the seeds on its last axis (NaN = missing run). For every replicate and
    every point the point's finite values are resampled with replacement (as many as there
    are) and averaged; a point without values stays NaN. Returns ``(n_boot, *shape[:-1])``.
    """
    v = np.asarray(values, dtype=float)
    shape, n_seed = v.shape[:-1], v.shape[-1]
    flat = np.sort(v.reshape(-1, n_seed), axis=-1)  # finite values first, NaN last
    count = np.isfinite(flat).sum(axis=-1)
    out = np.empty((n_boot, flat.shape[0]))
    cols = np.arange(n_seed)
    for start in range(0, n_boot, batch):
        b = min(batch, n_boot - start)
        u = rng.random((b, flat.shape[0], n_seed))
        idx = np.minimum((u * count[:, None]).astype(np.int64), np.maximum(count - 1, 0)[:, None])
        picked = np.take_along_axis(np.broadcast_to(flat, (b, *flat.shape)), idx, axis=-1)
        picked = np.where(cols < count[:, None], picked, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[start:start + b] = np.where(count > 0, picked.sum(-1) / np.maximum(count, 1),
                                            np.nan)
    return out.reshape(n_boot, *shape)


# --------------------------------------------------------------------------- pure fits
@dataclass(frozen=True)
class TransitionFit:
    """Result of :func:`fit_transition` (see the module docstring for the definitions)."""

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


def largest_step(x: Array, y: Array) -> tuple[int, int, float]:
    """Indices ``(i, j)`` of the neighbouring finite points (``x`` sorted) with the largest
    ``|y_j - y_i|`` and that signed step; ``(-1, -1, nan)`` with fewer than two points."""
    idx = np.nonzero(np.isfinite(y))[0]
    if idx.size < 2:
        return -1, -1, math.nan
    steps = np.diff(y[idx])
    k = int(np.argmax(np.abs(steps)))
    return int(idx[k]), int(idx[k + 1]), float(steps[k])


def fit_transition(x: ArrayLike, values: ArrayLike, *, log: bool = True, min_jump: float = 1.0,
                   mean: str = "geometric", n_boot: int = 1000, confidence: float = 0.95,
                   rng: np.random.Generator | None = None) -> TransitionFit:
    r"""Locate the jump of the seed mean of ``values`` (shape ``(len(x), n_seeds)``, NaN for
    missing runs) along ``x``; see the module docstring. With ``log`` the step is measured in
    decades, else in the observable's units; a step below ``min_jump`` is not a transition
    (location NaN). ``mean``: ``geometric`` (with ``log``, the seed mean of
    :math:`\log_{10}` values) or ``arithmetic`` (log of the seed mean, which one patterned seed
    among many relaxed ones already lifts by orders of magnitude: it marks the onset)."""
    if mean not in ("geometric", "arithmetic"):
        raise FitError(f"transition: mean = {mean!r}; expected 'geometric' or 'arithmetic'")
    rng = rng if rng is not None else np.random.default_rng(0)
    xa = np.asarray(x, dtype=float)
    v = np.asarray(values, dtype=float)
    if v.ndim != 2 or v.shape[0] != xa.size:
        raise FitError(f"values must have shape (len(x), n_seeds) = ({xa.size}, n); "
                       f"got {v.shape}")
    order = np.argsort(xa)
    xa, v = xa[order], v[order]

    geometric = log and mean == "geometric"
    samples = _log10(v) if geometric else v

    def transform(m: Array) -> Array:
        return _log10(m) if log and not geometric else m

    y = transform(_finite_mean(samples))
    i, j, step = largest_step(xa, y)
    nan = math.nan
    frac = np.full(xa.size, np.nan)
    if i < 0 or not abs(step) >= min_jump:
        return TransitionFit(nan, nan, nan, nan, nan, nan, nan, step, nan, 0, frac)
    level = 0.5 * (y[i] + y[j])
    direction = 1 if step > 0 else -1
    tv = _log10(v) if log else v
    ok = np.isfinite(tv)
    n = ok.sum(axis=1)
    high = (np.where(ok, direction * (tv - level), -np.inf) > 0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(n > 0, high / np.maximum(n, 1), np.nan)
    location = 0.5 * (xa[i] + xa[j])
    boot = transform(bootstrap_seed_means(samples, n_boot, rng))
    # A grid value has a (finite) bootstrap mean iff it has a run: the same points as ``y``.
    idx = np.nonzero(np.isfinite(y))[0]
    steps = np.diff(boot[:, idx], axis=1)
    k = np.argmax(np.abs(steps), axis=1)
    big = np.abs(np.take_along_axis(steps, k[:, None], axis=1)[:, 0]) >= min_jump
    lows = np.where(big, xa[idx[k]], np.nan)
    highs = np.where(big, xa[idx[k + 1]], np.nan)
    mids = 0.5 * (lows + highs)
    seed_lower, seed_upper = _percentiles(mids, confidence)
    blo, _ = _percentiles(lows, confidence)
    _, bhi = _percentiles(highs, confidence)
    lower = float(np.nanmin([xa[i], blo]))
    upper = float(np.nanmax([xa[j], bhi]))
    return TransitionFit(location=float(location), lower=lower, upper=upper,
                         grid_lower=float(xa[i]), grid_upper=float(xa[j]),
                         seed_lower=seed_lower, seed_upper=seed_upper, jump=step,
                         level=float(level), direction=direction, fraction_high=frac)


def patterned_level(sigma2: ArrayLike, *, min_gap: float = 2.0) -> float:
    """The sigma2_S level separating patterned runs from relaxed ones: the geometric middle
    of the widest gap of at least ``min_gap`` decades in the sorted finite positive values;
    ``0.0`` (every run counts as patterned) when there is no such gap."""
    v = np.asarray(sigma2, dtype=float).ravel()
    v = np.sort(v[np.isfinite(v) & (v > 0)])
    if v.size < 2:
        return 0.0
    lv = np.log10(v)
    gaps = np.diff(lv)
    k = int(np.argmax(gaps))
    if gaps[k] < min_gap:
        return 0.0
    return float(10 ** (0.5 * (lv[k] + lv[k + 1])))


def fit_line(x: ArrayLike, y: ArrayLike) -> tuple[float, float]:
    """Least-squares ``y = slope x + intercept`` over the finite pairs; NaN below 2 distinct x."""
    xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(xa) & np.isfinite(ya)
    xa, ya = xa[ok], ya[ok]
    if xa.size < 2 or np.ptp(xa) == 0:
        return math.nan, math.nan
    xm, ym = xa.mean(), ya.mean()
    slope = float(((xa - xm) * (ya - ym)).sum() / ((xa - xm) ** 2).sum())
    return slope, float(ym - slope * xm)


def fit_power_law(x: ArrayLike, y: ArrayLike) -> tuple[float, float]:
    r"""``(exponent, prefactor)`` of :math:`y = c\,x^{\beta}` by least squares on
    :math:`(\log_{10} x, \log_{10} y)` over the pairs with :math:`x, y > 0`."""
    xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(xa) & np.isfinite(ya) & (xa > 0) & (ya > 0)
    beta, b = fit_line(np.log10(xa[ok]), np.log10(ya[ok]))
    return beta, (10.0**b if math.isfinite(b) else math.nan)


class AlphaCrFit(NamedTuple):
    """:func:`alpha_cr_from_sizes` for one K: the critical activity, the prefactor c and
    whether the bound ``alpha_cr >= alpha_cr_min`` is active (the unbounded optimum is
    below it)."""

    alpha_cr: float
    prefactor: float
    at_bound: bool


def alpha_cr_from_sizes(amb: ArrayLike, lam: ArrayLike, K: float, *, method: str = "linear",
                        exponent: float = 0.5, alpha_cr_min: float | None = 0.0
                        ) -> AlphaCrFit:
    r"""``(alpha_cr, c, at_bound)`` for one Frank constant from the seed-mean pattern sizes
    ``lam`` at the contractilities ``amb`` (NaN entries are skipped), paper Eq. (7):
    :math:`\lambda = c\,[K/(\alpha - B - \alpha^{cr})]^{p}`, with
    :math:`\alpha^{cr} \ge` ``alpha_cr_min`` (``None``: unbounded).

    ``linear`` (:math:`p = 1/2`): :math:`\lambda^{-2} = m(\alpha - B) + b`,
    :math:`\alpha^{cr} = -b/m`, :math:`c = (mK)^{-1/2}` (NaN unless :math:`m > 0`). For
    :math:`m > 0` the bound is the linear constraint :math:`b \le -m\,\alpha^{cr}_{\min}`, so
    when the unbounded optimum violates it the bounded least-squares optimum lies on it: the
    line through :math:`(\alpha^{cr}_{\min}, 0)`,
    :math:`\lambda^{-2} = m(\alpha - B - \alpha^{cr}_{\min})` (NaN unless that :math:`m > 0`).
    ``nonlinear``: least squares in :math:`\lambda` with :math:`p` = ``exponent``: for fixed
    :math:`\alpha^{cr}` the model is linear in c (closed form), and the residual is minimised
    over :math:`\max(\alpha^{cr}_{\min}, \cdot) \le \alpha^{cr} < \min(\alpha - B)` (bounded
    scalar search; NaN when :math:`\min(\alpha - B) \le \alpha^{cr}_{\min}`, as the model
    needs :math:`\alpha - B > \alpha^{cr}` at every point).
    """
    nan = AlphaCrFit(math.nan, math.nan, False)
    a = np.asarray(amb, dtype=float)
    lv = np.asarray(lam, dtype=float)
    ok = np.isfinite(a) & np.isfinite(lv) & (lv > 0)
    a, lv = a[ok], lv[ok]
    if a.size < 2 or np.ptp(a) == 0:
        return nan
    bound = None if alpha_cr_min is None else float(alpha_cr_min)
    if method == "linear":
        y = lv**-2.0
        m, b = fit_line(a, y)
        if not m > 0:
            return nan
        if bound is None or -b / m >= bound:
            return AlphaCrFit(-b / m, 1.0 / math.sqrt(m * K), False)
        d = a - bound
        m = float(d @ y / (d @ d))
        if not m > 0:
            return nan
        return AlphaCrFit(bound, 1.0 / math.sqrt(m * K), True)
    if method != "nonlinear":
        raise FitError(f"alpha_cr method {method!r}: expected 'linear' or 'nonlinear'")
    from scipy.optimize import minimize_scalar

    top = float(a.min())
    span = float(np.ptp(a))
    lower = top - 50.0 * span
    bounded = False
    if bound is not None and bound >= lower:  # else the bound is far below the data: inactive
        if bound >= top:
            return nan
        lower, bounded = bound, True

    def profile(acr: float) -> tuple[float, float]:
        """Least-squares c at fixed alpha_cr (linear in c) and the residual sum of squares."""
        g = (K / np.maximum(a - acr, 1e-300)) ** exponent
        c = float(g @ lv / (g @ g))
        return c, float(((lv - c * g) ** 2).sum())

    with np.errstate(all="ignore"):
        opt = minimize_scalar(lambda acr: profile(acr)[1], bounds=(lower, top - 1e-9 * span),
                              method="bounded", options={"xatol": 1e-10 * span})
        acr = float(opt.x)
        if not opt.success:
            return nan
        near = acr < lower + 1e-3 * span
        if near and bounded and profile(lower)[1] <= profile(acr)[1]:
            return AlphaCrFit(lower, profile(lower)[0], True)  # the optimum is at the bound
        if near and not bounded:  # the residual falls without end: no finite alpha_cr fits
            return nan
        return AlphaCrFit(acr, profile(acr)[0], False)


@dataclass(frozen=True)
class SizeScaling:
    """:func:`size_scaling` on one set of seed means: alpha_cr and c per K (and whether the
    bound of alpha_cr is active), the exponent."""

    alpha_cr: Array
    prefactor_K: Array
    at_bound: NDArray[np.bool_]
    x: Array
    used: NDArray[np.bool_]
    exponent: float
    prefactor: float


def size_scaling(K: ArrayLike, amb: ArrayLike, lam_mean: ArrayLike, *, method: str = "linear",
                 exponent: float = 0.5, alpha_cr: ArrayLike | None = None,
                 alpha_cr_min: float | None = 0.0) -> SizeScaling:
    r"""alpha_cr(K) (:func:`alpha_cr_from_sizes` with the bound ``alpha_cr_min``, unless
    given) and the exponent of :math:`\lambda = c\,x^\beta`,
    :math:`x = K/(\alpha - B - \alpha^{cr}(K))` (:func:`fit_power_law`) over the points with
    :math:`x > 0`. ``lam_mean`` is ``(len(K), len(amb))``, NaN where there is no pattern."""
    Ka = np.asarray(K, dtype=float)
    a = np.asarray(amb, dtype=float)
    lm = np.asarray(lam_mean, dtype=float)
    if alpha_cr is None:
        fits = [alpha_cr_from_sizes(a, lm[i], float(Ka[i]), method=method, exponent=exponent,
                                    alpha_cr_min=alpha_cr_min) for i in range(Ka.size)]
        acr = np.array([f.alpha_cr for f in fits])
        cK = np.array([f.prefactor for f in fits])
        at_bound = np.array([f.at_bound for f in fits], dtype=bool)
    else:
        acr = np.asarray(alpha_cr, dtype=float)
        cK = np.full(Ka.size, np.nan)
        at_bound = np.zeros(Ka.size, dtype=bool)
    d = a[None, :] - acr[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.where(d > 0, Ka[:, None] / np.where(d > 0, d, 1.0), np.nan)
    used = np.isfinite(x) & np.isfinite(lm) & (lm > 0)
    beta, c = fit_power_law(x[used], lm[used])
    return SizeScaling(alpha_cr=acr, prefactor_K=cK, at_bound=at_bound, x=x, used=used,
                       exponent=beta, prefactor=c)


def peak_not_reached(t_peak: ArrayLike, t_final: ArrayLike, save_every: ArrayLike = 0.0,
                     margin: float = 1.0) -> NDArray[np.bool_]:
    r"""Which runs have not reached the first peak of :math:`\sigma^2_S(t)` by
    :math:`t_{\rm final}`: :math:`t_{\rm peak} \ge t_{\rm final} - {\rm margin}\cdot
    {\rm save\_every}` (to a relative 1e-9 of :math:`t_{\rm final}`; the arrays broadcast).
    Such a run's "first peak" is the last saved point or one a save interval before it (the
    series was still rising, or only just turned): not the peak of Fig. 3. NaN
    ``t_peak`` (missing or failed run): False."""
    tp = np.asarray(t_peak, dtype=float)
    tf = np.asarray(t_final, dtype=float)
    se = np.asarray(save_every, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.isfinite(tp) & (tp >= tf - margin * se - 1e-9 * np.abs(tf))


# --------------------------------------------------------------------------- phase.nc access
def sweep_dims(phase: xr.Dataset) -> list[str]:
    """The sweep dims of a phase Dataset (every dim of ``status`` but ``seed``)."""
    ref = "status" if "status" in phase else next(
        (n for n, v in phase.data_vars.items() if "seed" in v.dims), None)
    if ref is None:
        raise FitError("not a phase diagram: no variable over the seed dim")
    return [str(d) for d in phase[ref].dims if d != "seed"]


def fixed_parameter(phase: xr.Dataset, name: str) -> float | None:
    """A model parameter that the campaign did not sweep (phase.nc attribute ``param_<name>``),
    ``alpha_minus_B`` derived from ``alpha`` and ``B`` when needed."""
    key = f"param_{name}"
    if key in phase.attrs:
        return float(phase.attrs[key])
    if name == AMB and "param_alpha" in phase.attrs and "param_B" in phase.attrs:
        return float(phase.attrs["param_alpha"]) - float(phase.attrs["param_B"])
    return None


def is_swept(phase: xr.Dataset, name: str) -> bool:
    """Whether ``name`` varies over the phase diagram (a sweep dim or a zipped coordinate;
    ``alpha_minus_B`` also when ``alpha`` or ``B`` is swept)."""
    if name in phase.coords and name not in ("seed",) and phase[name].ndim == 1:
        return True
    return name == AMB and (is_swept(phase, "alpha") or is_swept(phase, "B"))


def with_dim(phase: xr.Dataset, name: str) -> xr.Dataset:
    """``phase`` with ``name`` as a dimension: a zipped coordinate is swapped in,
    ``alpha_minus_B`` is derived from a swept ``alpha`` or ``B``, a fixed parameter becomes a
    length-1 dim. Raises :class:`FitError` if ``name`` is neither swept nor fixed."""
    if name in phase.dims:
        return phase
    if name in phase.coords and phase[name].ndim == 1:
        return phase.swap_dims({phase[name].dims[0]: name})
    if name == AMB:
        for swept, other in (("alpha", "B"), ("B", "alpha")):
            if is_swept(phase, swept):
                fixed = fixed_parameter(phase, other)
                if fixed is None:
                    raise FitError("alpha_minus_B: both alpha and B are swept on different "
                                   "dims; sweep alpha_minus_B instead")
                sign = 1.0 if swept == "alpha" else -1.0
                amb = sign * (phase[swept] - fixed)
                ds = phase.assign_coords({AMB: (phase[swept].dims, amb.values,
                                                {"long_name": "contractility alpha - B",
                                                 "units": "1"})})
                return with_dim(ds, AMB)
    value = fixed_parameter(phase, name)
    if value is None:
        raise FitError(f"{name!r} is neither swept nor a fixed parameter of this campaign "
                       f"(sweep dims: {', '.join(sweep_dims(phase)) or 'none'})")
    return phase.expand_dims({name: [value]})


def select(phase: xr.Dataset, choice: Mapping[str, Any] | None) -> xr.Dataset:
    """``phase`` at the sweep values ``choice`` (nearest grid value; the dim is dropped)."""
    for name, value in (choice or {}).items():
        if name not in phase.coords:
            raise FitError(f"select: {name!r} is not a coordinate of the phase diagram "
                           f"(coordinates: {', '.join(map(str, phase.coords))})")
        ds = with_dim(phase, name)
        phase = ds.sel({name: value}, method="nearest")
    return phase


def default_axis(phase: xr.Dataset, candidates: Sequence[str] = (AMB, "chi", "eps")) -> str:
    for name in candidates:
        if is_swept(phase, name):
            return name
    dims = sweep_dims(phase)
    if not dims:
        raise FitError("the campaign sweeps nothing: no axis to fit along")
    return dims[0]


def _others(ds: xr.Dataset, used: Iterable[str]) -> list[str]:
    u = set(used)
    return [d for d in sweep_dims(ds) if d not in u]


def _rng(options: Mapping[str, Any]) -> np.random.Generator:
    return np.random.default_rng(int(options.get("bootstrap_seed", 0)))


def _problems(name: str, options: Mapping[str, Any], allowed: Iterable[str]) -> list[str]:
    valid = sorted({*allowed, *COMMON_OPTIONS})
    out = [f"unknown option {key!r}; allowed: {', '.join(valid)}" for key in options
           if key not in valid]
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
    if bound is not None and (isinstance(bound, bool) or not isinstance(bound, (int, float))
                              or not math.isfinite(bound)):
        out.append(f"alpha_cr_min = {bound!r}; expected a number (the lower bound of alpha_cr) "
                   "or null (no bound)")
    require = options.get("require_peak")
    if require is not None and not isinstance(require, bool):
        out.append(f"require_peak = {require!r}; expected true or false")
    margin = options.get("peak_margin", 1.0)
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not margin >= 0:
        out.append(f"peak_margin = {margin!r}; expected a number of save intervals >= 0")
    return out


def _check_options(name: str, options: Mapping[str, Any], allowed: Iterable[str]) -> None:
    problems = _problems(name, options, allowed)
    if problems:
        raise FitError(f"fit {name!r}: " + "; ".join(problems))


def _coord_copy(ds: xr.Dataset, dims: Sequence[str]) -> dict[str, xr.Variable]:
    """The coordinates of ``ds`` that live on ``dims`` only (for a fit's output)."""
    out = {}
    for name, c in ds.coords.items():
        if c.ndim == 1 and c.dims[0] in dims:
            out[str(name)] = c.variable
    return out


def _var(dims: Sequence[str], data: Any, long_name: str, units: str = "1",
         **attrs: Any) -> xr.Variable:
    return xr.Variable(tuple(dims), np.asarray(data), {"long_name": long_name, "units": units,
                                                       **attrs})


# --------------------------------------------------------------------------- dataset fits
def transition(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
               ) -> xr.Dataset:
    """The ``transition`` fit (module docstring). Options: ``axis``, ``observable``
    (default ``sigma2_S``), ``log`` (default true), ``min_jump`` (decades, default 1),
    ``prefix`` (variable prefix, default ``transition``), and the common options."""
    _check_options("transition", options, TRANSITION_OPTIONS)
    ds = select(phase, options.get("select"))
    axis = str(options.get("axis") or default_axis(ds))
    observable = str(options.get("observable", "sigma2_S"))
    if observable not in ds:
        raise FitError(f"transition: observable {observable!r} is not in phase.nc")
    ds = with_dim(ds, axis)
    others = _others(ds, [axis])
    data = ds[observable].transpose(*others, axis, "seed")
    x = ds[axis].values.astype(float)
    pre = str(options.get("prefix", "transition"))
    log_scale = bool(options.get("log", True))
    min_jump = float(options.get("min_jump", 1.0 if log_scale else 0.0))
    mean_kind = str(options.get("mean", "geometric"))
    rng = _rng(options)
    oshape = tuple(ds.sizes[d] for d in others)
    flat = data.values.reshape(-1, x.size, data.sizes["seed"])
    names = ("location", "lower", "upper", "grid_lower", "grid_upper", "seed_lower",
             "seed_upper", "jump", "level", "direction")
    out = {n: np.full(flat.shape[0], np.nan) for n in names}
    frac = np.full((flat.shape[0], x.size), np.nan)
    order = np.argsort(x)
    for k in range(flat.shape[0]):
        f = fit_transition(x, flat[k], log=log_scale, min_jump=min_jump, mean=mean_kind,
                           n_boot=int(options.get("n_boot", 1000)),
                           confidence=float(options.get("confidence", 0.95)), rng=rng)
        for n in names:
            out[n][k] = getattr(f, n)
        frac[k, order] = f.fraction_high
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
    coords = _coord_copy(ds, others)
    result = xr.Dataset(coords=coords)
    for n in names:
        result[f"{pre}_{n}"] = _var(others, out[n].reshape(oshape), long[n], unit)
    result[f"{pre}_fraction_high"] = _var(
        [*others, axis], frac.reshape(*oshape, x.size),
        "fraction of seeds beyond the step's mid level")
    result = result.assign_coords({axis: ds[axis].variable})
    attrs = {"axis": axis, "observable": observable, "log": int(log_scale),
             "min_jump": min_jump, "mean": mean_kind,
             "method": "largest step of the seed mean; bracket midpoint",
             "n_seeds": int(ds.sizes["seed"])}
    for n in names:
        result[f"{pre}_{n}"].attrs.update({f"fit_{k}": v for k, v in attrs.items()})
    return result


def _run_setting(ds: xr.Dataset, name: str) -> xr.DataArray | None:
    """A numerics setting of the runs (``t_final``, ``save_every``) over the phase diagram:
    the coordinate ``name`` when swept (a dim, a zipped coordinate, or a scalar left by
    ``select``), else phase.nc's attribute ``num_<name>``; ``None`` if neither is there."""
    if name in ds.coords:
        return ds[name].astype(float)
    value = ds.attrs.get(f"num_{name}")
    try:
        return None if value is None else xr.DataArray(float(value))
    except (TypeError, ValueError):
        return None


#: the peak time that goes with each peak observable (the growth-peak rule by default)
PEAK_TIMES = {"lambda_peak_literal": "t_peak_literal"}


def _unpeaked(ds: xr.Dataset, require: bool, margin: float, t_name: str = "t_peak"
              ) -> tuple[NDArray[np.bool_], str]:
    """:func:`peak_not_reached` for every run of ``ds`` (dims K, alpha_minus_B, seed), and a
    description of the check for the fit's attributes. Without the peak time ``t_name`` or
    ``t_final`` in phase.nc no run is flagged (logged)."""
    dims = ("K", AMB, "seed")
    none = np.zeros(tuple(ds.sizes[d] for d in dims), dtype=bool)
    if not require:
        return none, "off (require_peak: false)"
    if t_name not in ds:
        log.warning("alpha_cr: phase.nc has no %s: cannot tell runs that did not reach "
                    "the first peak of sigma2_S; every run counts", t_name)
        return none, f"not done: phase.nc has no {t_name}"
    t_final = _run_setting(ds, "t_final")
    if t_final is None:
        log.warning("alpha_cr: t_final of the runs unknown (no num_t_final attribute in "
                    "phase.nc): cannot tell runs that did not reach the first peak of "
                    "sigma2_S; every run counts")
        return none, "not done: t_final unknown"
    save_every = _run_setting(ds, "save_every")
    check = f"{t_name} >= t_final - {margin:g} save_every"
    if save_every is None:
        log.warning("alpha_cr: save_every of the runs unknown (no num_save_every attribute in "
                    "phase.nc): only runs with t_peak = t_final count as without a peak")
        save_every, check = xr.DataArray(0.0), f"{t_name} >= t_final (save_every unknown)"
    t_peak = ds[t_name]
    tp, tf, se = (v.broadcast_like(t_peak).transpose(*dims).values
                  for v in (t_peak, t_final, save_every))
    return peak_not_reached(tp, tf, se, margin), check


@dataclass(frozen=True)
class _SizeData:
    """The runs that enter the ``alpha_cr`` and ``scaling`` fits (:func:`_size_data`)."""

    ds: xr.Dataset
    K: Array
    amb: Array
    #: (K, alpha_minus_B, seed): the pattern size of every run that counts, NaN elsewhere
    lam: Array
    level: float
    #: (K, alpha_minus_B): patterned runs left out because their peak was not reached
    unpeaked: NDArray[np.int32]
    #: attributes of the fit variables describing the peak check
    peak_attrs: dict[str, Any]


def _size_data(phase: xr.Dataset, options: Mapping[str, Any]) -> _SizeData:
    ds = select(phase, options.get("select"))
    observable = str(options.get("observable", "lambda_peak"))
    if observable not in ds:
        raise FitError(f"alpha_cr: observable {observable!r} is not in phase.nc")
    ds = with_dim(with_dim(ds, "K"), AMB)
    extra = _others(ds, ["K", AMB])
    if extra:
        raise FitError(f"alpha_cr/scaling: the phase diagram also varies {', '.join(extra)}; "
                       f"pick one value with the option select: {{{extra[0]}: VALUE}}")
    lam = ds[observable].transpose("K", AMB, "seed").values.astype(float)
    sig = ds["sigma2_S"].transpose("K", AMB, "seed").values.astype(float)
    level = options.get("min_sigma2")
    if level is None:
        level = patterned_level(sig, min_gap=float(options.get("min_gap", 2.0)))
    level = float(level)
    with np.errstate(invalid="ignore"):
        sized = np.isfinite(sig) & (sig > level) & np.isfinite(lam) & (lam > 0)
    require = options.get("require_peak")
    peaked = observable.startswith("lambda") and "_peak" in observable
    require = peaked if require is None else bool(require)
    margin = float(options.get("peak_margin", 1.0))
    unpeaked, check = _unpeaked(ds, require, margin, PEAK_TIMES.get(observable, "t_peak"))
    left_out = sized & unpeaked
    n_left_out = int(left_out.sum())
    if n_left_out:
        log.info("alpha_cr: %d of %d patterned runs left out (first peak of sigma2_S not "
                 "reached: %s)", n_left_out, int(sized.sum()), check)
    peak_attrs: dict[str, Any] = {
        "fit_require_peak": int(require), "fit_peak_margin": margin, "fit_peak_check": check,
        "fit_n_unpeaked": n_left_out, "fit_n_patterned": int(sized.sum())}
    return _SizeData(ds=ds, K=ds["K"].values.astype(float), amb=ds[AMB].values.astype(float),
                     lam=np.where(sized & ~unpeaked, lam, np.nan), level=level,
                     unpeaked=left_out.sum(-1).astype(np.int32), peak_attrs=peak_attrs)


def _alpha_cr_bound(options: Mapping[str, Any]) -> float | None:
    bound = options.get("alpha_cr_min", 0.0)
    return None if bound is None else float(bound)


def _alpha_cr_vars(data: _SizeData, fit: SizeScaling, boot: Array, boot_at_bound: Array,
                   conf: float, options: Mapping[str, Any], counts: Array) -> xr.Dataset:
    ds = data.ds
    res = xr.Dataset(coords={"K": ds["K"].variable, AMB: ds[AMB].variable})
    lo_hi = np.array([_percentiles(boot[:, i], conf) for i in range(boot.shape[1])])
    method = str(options.get("method", "linear"))
    bound = _alpha_cr_bound(options)
    attrs: dict[str, Any] = {
        "fit_method": method, "fit_exponent": float(options.get("exponent", 0.5)),
        "fit_observable": str(options.get("observable", "lambda_peak")),
        "fit_min_sigma2": data.level,
        "fit_alpha_cr_min": "none" if bound is None else bound,
        **data.peak_attrs}
    res["alpha_cr"] = _var(["K"], fit.alpha_cr, "critical activity alpha_cr from the pattern "
                           "sizes (paper Eq. 7)", **attrs)
    res["alpha_cr_lower"] = _var(["K"], lo_hi[:, 0], "alpha_cr seed-bootstrap interval, "
                                 "lower end")
    res["alpha_cr_upper"] = _var(["K"], lo_hi[:, 1], "alpha_cr seed-bootstrap interval, "
                                 "upper end")
    res["alpha_cr_std"] = _var(["K"], _finite_std(boot.T), "alpha_cr seed-bootstrap standard "
                               "deviation")
    res["alpha_cr_prefactor"] = _var(["K"], fit.prefactor_K, "c in lambda = c (K / (alpha - B "
                                     "- alpha_cr))^(1/2) at this K", "L")
    res["alpha_cr_at_bound"] = _var(
        ["K"], fit.at_bound.astype(np.int8), "1 if alpha_cr is at its lower bound "
        "alpha_cr_min (the unbounded fit would put it below), 0 otherwise",
        flag_values=np.array([0, 1], dtype=np.int8), flag_meanings="free at_bound",
        fit_alpha_cr_min=attrs["fit_alpha_cr_min"])
    finite = np.isfinite(boot).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(finite > 0, boot_at_bound.sum(axis=0) / np.maximum(finite, 1), np.nan)
    res["alpha_cr_bound_fraction"] = _var(["K"], frac, "fraction of the bootstrap replicates "
                                          "(with a fit) whose alpha_cr is at its lower bound")
    res["alpha_cr_n_points"] = _var(["K"], counts.astype(np.int32), "alpha - B values with a "
                                    "pattern used in the fit")
    res["alpha_cr_unpeaked_count"] = _var(
        ["K", AMB], data.unpeaked, "patterned runs left out of the alpha_cr and scaling fits "
        "because the first peak of sigma2_S(t) was not reached by t_final "
        f"({data.peak_attrs['fit_peak_check']})",
        fit_peak_check=data.peak_attrs["fit_peak_check"])
    res["alpha_cr_n_unpeaked"] = _var(["K"], data.unpeaked.sum(axis=1).astype(np.int32),
                                      "patterned runs at this K left out of the fits: first "
                                      "peak of sigma2_S(t) not reached by t_final")
    return res


def _size_fit(phase: xr.Dataset, options: Mapping[str, Any], with_scaling: bool) -> xr.Dataset:
    data = _size_data(phase, options)
    K, amb, lam = data.K, data.amb, data.lam
    method = str(options.get("method", "linear"))
    if method not in ("linear", "nonlinear"):
        raise FitError(f"alpha_cr: method = {method!r}; expected 'linear' or 'nonlinear'")
    exponent = float(options.get("exponent", 0.5))
    bound = _alpha_cr_bound(options)
    n_boot = int(options.get("n_boot", 1000))
    conf = float(options.get("confidence", 0.95))
    rng = _rng(options)
    mean = _finite_mean(lam)
    fit = size_scaling(K, amb, mean, method=method, exponent=exponent, alpha_cr_min=bound)
    counts = np.isfinite(mean).sum(axis=1)
    if not np.any(np.isfinite(fit.alpha_cr)):
        log.warning("alpha_cr: no fit at any K (each needs two patterned alpha - B values "
                    "with lambda^-2 increasing in alpha - B)")
    if np.any(fit.at_bound):
        log.info("alpha_cr: at its bound %g for K = %s", bound,
                 ", ".join(f"{k:g}" for k in K[fit.at_bound]))
    boots = bootstrap_seed_means(lam, n_boot, rng)
    acr_b = np.full((n_boot, K.size), np.nan)
    bound_b = np.zeros((n_boot, K.size), dtype=bool)
    beta_b = np.full(n_boot, np.nan)
    for b in range(n_boot):
        fb = size_scaling(K, amb, boots[b], method=method, exponent=exponent,
                          alpha_cr_min=bound)
        acr_b[b] = fb.alpha_cr
        bound_b[b] = fb.at_bound
        beta_b[b] = fb.exponent
    res = _alpha_cr_vars(data, fit, acr_b, bound_b, conf, options, counts)
    if not with_scaling:
        return res
    dims2 = ["K", AMB]
    res["scaling_x"] = _var(dims2, fit.x, "K / (alpha - B - alpha_cr(K))")
    res["scaling_lambda_mean"] = _var(dims2, mean, "seed mean of the pattern size over the "
                                      "patterned runs that reached their peak", "L")
    res["scaling_lambda_std"] = _var(dims2, _finite_std(lam), "seed standard deviation "
                                     "(ddof = 1) of the pattern size over the patterned runs "
                                     "that reached their peak", "L")
    res["scaling_lambda_count"] = _var(dims2, np.isfinite(lam).sum(-1).astype(np.int32),
                                       "patterned runs that reached their peak at this point")
    res["scaling_used"] = _var(dims2, fit.used.astype(np.int8), "1 if the point enters the "
                               "exponent fit")
    lo, hi = _percentiles(beta_b, conf)
    n_K = int(np.any(fit.used, axis=1).sum())
    attrs: dict[str, Any] = {
        "fit_alpha_cr_method": method, "fit_n_boot": n_boot, "fit_confidence": conf,
        "fit_n_points": int(fit.used.sum()), "fit_n_K": n_K,
        "fit_alpha_cr_min": "none" if bound is None else bound,
        "fit_n_alpha_cr_at_bound": int(fit.at_bound.sum()),
        **data.peak_attrs}
    res["scaling_exponent"] = _var([], fit.exponent, "exponent beta of lambda = c (K / (alpha"
                                   " - B - alpha_cr))^beta (paper Eq. 7: 1/2)", **attrs)
    res["scaling_exponent_lower"] = _var([], lo, "scaling exponent, seed-bootstrap interval "
                                         "lower end")
    res["scaling_exponent_upper"] = _var([], hi, "scaling exponent, seed-bootstrap interval "
                                         "upper end")
    res["scaling_exponent_std"] = _var([], _finite_std(beta_b[None, :])[0],
                                       "scaling exponent, seed-bootstrap standard deviation")
    res["scaling_prefactor"] = _var([], fit.prefactor, "prefactor c of the scaling fit", "L")
    if n_K < 2:
        log.warning("scaling: %d value(s) of K with a pattern; the exponent then mostly "
                    "restates the alpha_cr fit (see sweep.fits docs)", n_K)
    return res


def alpha_cr(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
             ) -> xr.Dataset:
    """The ``alpha_cr`` fit (module docstring). Options: ``method`` (linear, nonlinear),
    ``exponent``, ``observable`` (default ``lambda_peak``), ``min_sigma2``, ``min_gap``."""
    _check_options("alpha_cr", options, SIZE_OPTIONS)
    return _size_fit(phase, options, with_scaling=False)


def scaling(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
            ) -> xr.Dataset:
    """The ``scaling`` fit (module docstring); also writes the ``alpha_cr`` variables.
    Options: those of ``alpha_cr``."""
    _check_options("scaling", options, SIZE_OPTIONS)
    return _size_fit(phase, options, with_scaling=True)


def anisotropy(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
               ) -> xr.Dataset:
    """The ``anisotropy`` fit (module docstring). Options: ``axis`` (default ``eps``),
    ``observable`` (default ``cos2theta``)."""
    _check_options("anisotropy", options, ANISOTROPY_OPTIONS)
    ds = select(phase, options.get("select"))
    axis = str(options.get("axis", "eps"))
    observable = str(options.get("observable", "cos2theta"))
    if observable not in ds:
        raise FitError(f"anisotropy: observable {observable!r} is not in phase.nc")
    ds = with_dim(ds, axis)
    others = _others(ds, [axis])
    data = ds[observable].transpose(*others, axis, "seed").values.astype(float)
    x = ds[axis].values.astype(float)
    oshape = tuple(ds.sizes[d] for d in others)
    flat = data.reshape(-1, x.size, data.shape[-1])
    n_boot = int(options.get("n_boot", 1000))
    conf = float(options.get("confidence", 0.95))
    rng = _rng(options)
    xs = np.broadcast_to(x[:, None], flat.shape[1:])
    slope = np.full(flat.shape[0], np.nan)
    icept = np.full(flat.shape[0], np.nan)
    lo = np.full(flat.shape[0], np.nan)
    hi = np.full(flat.shape[0], np.nan)
    for k in range(flat.shape[0]):
        slope[k], icept[k] = fit_line(xs.ravel(), flat[k].ravel())
        if np.isfinite(flat[k]).sum(-1).max(initial=0) < 2:
            continue  # one seed: nothing to resample, the interval is unknown (NaN), not zero
        boot = bootstrap_seed_means(flat[k], n_boot, rng)
        sb = np.array([fit_line(x, boot[b])[0] for b in range(n_boot)])
        lo[k], hi[k] = _percentiles(sb, conf)
    mean = _finite_mean(flat)
    count = np.isfinite(flat).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        sem = _finite_std(flat) / np.sqrt(np.where(count > 0, count, np.nan))
    res = xr.Dataset(coords={**_coord_copy(ds, others), axis: ds[axis].variable})
    per = [*others, axis]
    res["anisotropy_mean"] = _var(per, mean.reshape(*oshape, x.size),
                                  f"seed mean of {observable}")
    res["anisotropy_sem"] = _var(per, sem.reshape(*oshape, x.size),
                                 f"standard error of the seed mean of {observable}")
    attrs: dict[str, Any] = {"fit_axis": axis, "fit_observable": observable, "fit_n_boot": n_boot,
             "fit_confidence": conf}
    res["anisotropy_slope"] = _var(others, slope.reshape(oshape),
                                   f"least-squares slope d<{observable}>/d{axis} over all runs",
                                   **attrs)
    res["anisotropy_slope_lower"] = _var(others, lo.reshape(oshape), "slope seed-bootstrap "
                                         "interval, lower end")
    res["anisotropy_slope_upper"] = _var(others, hi.reshape(oshape), "slope seed-bootstrap "
                                         "interval, upper end")
    res["anisotropy_intercept"] = _var(others, icept.reshape(oshape),
                                       f"least-squares intercept of {observable} at {axis} = 0")
    return res


def _run_growth(path: Path) -> float:
    """log10 sigma2_S(t_final) / sigma2_S(t_final / 2) of one run file (NaN if unreadable)."""
    try:
        with xr.open_dataset(path) as run:
            t = series_time(run).values.astype(float)
            s = run["sigma2_S"].values.astype(float)
    except (OSError, KeyError, ValueError) as e:
        log.warning("stability: cannot read %s (%s)", path, e)
        return math.nan
    if t.size < 2:
        return math.nan
    half = int(np.argmin(np.abs(t - 0.5 * t[-1])))
    if half == t.size - 1:
        return math.nan
    return float(_log10(s[-1]) - _log10(s[half]))


def stability_parameters(phase: xr.Dataset, coords: Mapping[str, float]) -> Any:
    """:class:`model.parameters.Parameters` of a grid point: the fixed ``param_*`` attributes
    of phase.nc with the swept values ``coords``."""
    from model.parameters import Parameters

    fields = set(Parameters.names())
    values: dict[str, Any] = {}
    for key, value in phase.attrs.items():
        name = key.removeprefix("param_")
        if key.startswith("param_") and name in fields:
            values[name] = int(value) if name == "noise_modes" else float(value)
    values.update({k: float(v) for k, v in coords.items()})
    if AMB in values and "alpha" in values:
        if AMB in coords:
            values.pop("alpha")
        else:
            values.pop(AMB)
    return Parameters.from_dict(values)


def stability(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
              ) -> xr.Dataset:
    """The ``stability`` fit (module docstring). Options: ``activity`` (axis, default ``chi``
    if swept else ``alpha_minus_B``), ``strain`` (default ``eps``), ``unstable_reasons``
    (default [spin_diverged]), ``fraction`` (majority threshold, default 0.5), ``n_fine``
    (points of the theory curve, default 400), ``incompressible`` (default: the campaign's).
    Needs the run files (``root`` = results/<name>)."""
    _check_options("stability", options, STABILITY_OPTIONS)
    if root is None:
        raise FitError("stability: needs the campaign folder (run files)")
    from model.stability import critical_eps_closed_form, paper_eq6

    ds = select(phase, options.get("select"))
    act = str(options.get("activity") or ("chi" if is_swept(ds, "chi") else AMB))
    strain = str(options.get("strain", "eps"))
    ds = with_dim(with_dim(ds, act), strain)
    extra = _others(ds, [act, strain])
    if extra:
        raise FitError(f"stability: the phase diagram also varies {', '.join(extra)}; pick one "
                       f"value with the option select: {{{extra[0]}: VALUE}}")
    reasons = set(options.get("unstable_reasons", ["spin_diverged"]))
    frac_needed = float(options.get("fraction", 0.5))
    dims = [act, strain, "seed"]
    status = ds["status"].transpose(*dims).values
    reason = ds["reason"].transpose(*dims).values
    rids = ds["run_id"].transpose(*dims).values
    growth = np.full(status.shape, np.nan)
    unstable = np.full(status.shape, -1, dtype=np.int8)
    for idx in np.ndindex(status.shape):
        if status[idx] == 1:
            g = _run_growth(root / "runs" / f"{rids[idx]}.nc")
            growth[idx] = g
            if math.isfinite(g):
                unstable[idx] = int(g > 0)
        elif status[idx] == 2 and str(reason[idx]) in reasons:
            unstable[idx] = 1
    known = unstable >= 0
    n_known = known.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(n_known > 0, (unstable == 1).sum(-1) / np.maximum(n_known, 1), np.nan)
    a = ds[act].values.astype(float)
    e = ds[strain].values.astype(float)
    order = np.argsort(e)
    eps_sim = np.full(a.size, np.nan)
    eps_lo = np.full(a.size, np.nan)
    eps_hi = np.full(a.size, np.nan)
    for i in range(a.size):
        f = frac[i, order]
        hit = np.nonzero(f >= frac_needed)[0]
        if hit.size:
            j = int(hit[0])
            eps_hi[i] = e[order][j]
            # the last strain below it that has classified runs (a refined campaign's
            # phase.nc has strains that were not run at every activity)
            below = np.nonzero(np.isfinite(f[:j]))[0]
            eps_lo[i] = e[order][below[-1]] if below.size else e[order][j]
            eps_sim[i] = 0.5 * (eps_lo[i] + eps_hi[i])
    incompressible = bool(options.get("incompressible",
                                      int(ds.attrs.get("num_incompressible", 0))))
    n_fine = int(options.get("n_fine", 400))
    lo_a, hi_a = float(np.min(a)), float(np.max(a))
    fine = np.linspace(lo_a, hi_a, n_fine) if hi_a > lo_a else np.array([lo_a])

    def theory(values: Array) -> tuple[Array, Array]:
        ours, paper = np.full(values.size, np.nan), np.full(values.size, np.nan)
        for k, v in enumerate(values):
            try:
                p = stability_parameters(ds, {act: float(v), strain: 0.0})
            except NematicError as exc:
                log.warning("stability: no theory at %s = %g: %s", act, v, exc)
                continue
            ours[k] = critical_eps_closed_form(p, incompressible=incompressible)
            paper[k] = paper_eq6(p)
        return np.where(np.isfinite(ours), ours, np.nan), np.where(np.isfinite(paper),
                                                                     paper, np.nan)

    th, th_paper = theory(a)
    fth, fth_paper = theory(fine)
    amb = fixed_parameter(ds, AMB)
    scale = (amb if act == "chi" and amb is not None else
             (fixed_parameter(ds, "chi") or 1.0) if act == AMB else 1.0)
    res = xr.Dataset(coords={act: ds[act].variable, strain: ds[strain].variable,
                             "seed": ds["seed"].variable,
                             "activity_fine": ("activity_fine", fine, {
                                 "long_name": f"{act} on a fine grid (theory curve)",
                                 "units": "1"})})
    attrs: dict[str, Any] = {
        "fit_criterion": "sigma2_S(t_final) > sigma2_S(t_final / 2), or failed with "
        "reason in " + (", ".join(sorted(reasons)) or "(none)"),
             "fit_activity": act, "fit_strain": strain, "fit_activity_scale": float(scale),
             "fit_incompressible": int(incompressible),
             "fit_mechanics": str(ds.attrs.get("num_mechanics", ""))}
    res["stability_growth"] = _var(dims, growth, "log10 sigma2_S(t_final) / "
                                   "sigma2_S(t_final / 2) (decades)", "1")
    res["stability_unstable"] = _var(dims, unstable, "1 unstable, 0 stable, -1 unknown "
                                     "(missing, or failed for another reason)", **attrs)
    res["stability_fraction_unstable"] = _var([act, strain], frac, "fraction of classified "
                                              "seeds that are unstable")
    res["stability_eps_c_sim"] = _var([act], eps_sim, "simulated critical strain: midpoint "
                                      "between the last stable and the first unstable strain",
                                      fit_fraction=frac_needed)
    res["stability_eps_c_sim_lower"] = _var([act], eps_lo, "simulated critical strain, grid "
                                            "interval lower end")
    res["stability_eps_c_sim_upper"] = _var([act], eps_hi, "simulated critical strain, grid "
                                            "interval upper end")
    res["stability_eps_c_theory"] = _var([act], th, "critical strain of the linear stability "
                                         "analysis (docs/stability.md Eq. S10); NaN: none")
    res["stability_eps_c_paper"] = _var([act], th_paper, "critical strain of paper Eq. (6) "
                                        "as printed")
    res["stability_theory_fine"] = _var(["activity_fine"], fth, "critical strain of the linear "
                                        "stability analysis on the fine activity axis")
    res["stability_paper_fine"] = _var(["activity_fine"], fth_paper, "paper Eq. (6) as printed "
                                       "on the fine activity axis")
    return res


# --------------------------------------------------------------------------- registry
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
    "transition": FitSpec(transition, "location of the jump of the seed-mean sigma2_S along "
                          "an axis, interval from the grid and the seeds", TRANSITION_OPTIONS),
    "alpha_cr": FitSpec(alpha_cr, "critical activity alpha_cr(K) from the pattern sizes",
                        SIZE_OPTIONS),
    "scaling": FitSpec(scaling, "exponent of lambda vs K / (alpha - B - alpha_cr) with a seed "
                       "bootstrap interval (includes alpha_cr)", SIZE_OPTIONS,
                       includes=("alpha_cr",)),
    "anisotropy": FitSpec(anisotropy, "trend of <cos 2 theta> with the applied strain eps",
                          ANISOTROPY_OPTIONS),
    "stability": FitSpec(stability, "stable/unstable runs in the (activity, eps) plane and "
                         "the linear-stability boundary (Fig. A1)", STABILITY_OPTIONS),
}


def option_problems(name: str, options: Mapping[str, Any]) -> list[str]:
    """What is wrong with the options of registered fit ``name`` (empty if nothing), for
    validating a campaign before it runs."""
    if name not in REGISTRY:
        return [f"unknown fit {name!r}; registered: {', '.join(sorted(REGISTRY))}"]
    return _problems(name, options, REGISTRY[name].options)


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


def compute_fits(phase: xr.Dataset, requests: Iterable[tuple[str, Mapping[str, Any]]],
                 root: Path | None = None, *, strict: bool = True
                 ) -> tuple[xr.Dataset, dict[str, str]]:
    """Run the requested fits on ``phase``; return the merged Dataset and the failures
    (``{name: message}``; with ``strict`` the first failure raises)."""
    parts: list[xr.Dataset] = []
    failures: dict[str, str] = {}
    done: list[str] = []
    for name, options in resolve(requests):
        try:
            part = REGISTRY[name].function(phase, options, root)
        except NematicError as e:
            if strict:
                raise
            failures[name] = str(e)
            log.warning("fit %s skipped: %s", name, e)
            continue
        except Exception as e:
            if strict:
                raise
            failures[name] = f"{type(e).__name__}: {e}"  # a bug, or data we did not foresee
            log.warning("fit %s failed", name, exc_info=True)
            continue
        for var in part.data_vars.values():
            var.attrs.setdefault("fit", name)
        parts.append(part)
        done.append(f"{name}: {json.dumps(options, sort_keys=True, default=str)}")
    merged = xr.merge(parts, compat="no_conflicts", join="outer",
                      combine_attrs="override") if parts else xr.Dataset()
    merged.attrs.update({
        "Conventions": "CF-1.11",
        "title": f"fits of campaign {phase.attrs.get('campaign', '')}",
        "history": f"{now_iso()}: fitted from phase.nc by sweep.fits",
        "library_versions": library_versions_text(),
        "campaign": str(phase.attrs.get("campaign", "")),
        "source": "active-nematic-solids fits (sweep.fits) of phase.nc",
        "phase_created": str(phase.attrs.get("created", "")),
        "code_version": code_version(),
        "git_commit": git_commit(),
        "created": now_iso(),
        "fits": "; ".join(done),
        "failed_fits": "; ".join(f"{k}: {v}" for k, v in failures.items()),
    })
    return merged, failures


def fit_notes(ds: xr.Dataset) -> list[str]:
    """One-line caveats about the fits in ``ds`` (a fits.nc) for the command line: the runs
    the ``alpha_cr`` / ``scaling`` fits left out because the first peak of sigma2_S was not
    reached by t_final, a peak check that could not be done, and the K whose alpha_cr is at
    its lower bound. Empty when there is nothing to say (or no such fit)."""
    if "alpha_cr" not in ds:
        return []
    notes = []
    attrs = ds["alpha_cr"].attrs
    n = int(attrs.get("fit_n_unpeaked", 0))
    check = str(attrs.get("fit_peak_check", ""))
    if n:
        notes.append(f"alpha_cr/scaling: {n} of {int(attrs.get('fit_n_patterned', n))} "
                     "patterned run(s) left out: the first peak of sigma2_S was not reached "
                     f"by t_final ({check}; per point: alpha_cr_unpeaked_count in {FITS})")
    elif check.startswith("not done"):
        notes.append(f"alpha_cr/scaling: runs without a peak of sigma2_S not looked for "
                     f"({check})")
    if "alpha_cr_at_bound" in ds:
        at = np.asarray(ds["alpha_cr_at_bound"].values).astype(bool)
        if at.any():
            K = ", ".join(f"{float(k):g}" for k in ds["K"].values[at])
            notes.append(f"alpha_cr at its bound {attrs.get('fit_alpha_cr_min', 0)} for K = "
                         f"{K} (the unbounded fit would put it lower)")
    return notes


def load_phase(root: Path) -> xr.Dataset:
    """``root/phase.nc`` loaded into memory (the file is closed)."""
    path = Path(root) / PHASE
    if not path.is_file():
        raise FitError(f"no phase diagram at {path}: run the campaign (nematic run) or "
                       "aggregate it (nematic aggregate) first")
    with xr.open_dataset(path) as ds:
        return ds.load()


def write_fits(root: Path, requests: Iterable[tuple[str, Mapping[str, Any]]], *,
               strict: bool = False) -> tuple[Path, dict[str, str]]:
    """Compute the requested fits from ``root/phase.nc`` and write ``root/fits.nc``
    atomically; return its path and the failures."""
    root = Path(root)
    phase = load_phase(root)
    ds, failures = compute_fits(phase, requests, root, strict=strict)
    path = root / FITS
    atomic_to_netcdf(ds, path)
    log.info("wrote %s (%s)", path, ds.attrs.get("fits", ""))
    return path, failures


def load_fits(root: Path) -> xr.Dataset:
    """``root/fits.nc`` loaded into memory, or an empty Dataset if there is none."""
    path = Path(root) / FITS
    if not path.is_file():
        return xr.Dataset()
    with xr.open_dataset(path) as ds:
        return ds.load()
