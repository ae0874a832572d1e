"""Statistics over seeds that the fits share: NaN-aware means and standard deviations,
the seed bootstrap, percentile intervals and least-squares lines."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Floor for log10 of a (non-negative) variance: sigma2_S = 0 exactly happens (S0 = 0, no noise).
LOG_FLOOR = 1e-300
Array = NDArray[np.float64]


def finite_mean(values: Array, axis: int = -1) -> Array:
    """Mean over ``axis`` ignoring NaN; NaN (no warning) where nothing is finite."""
    ok = np.isfinite(values)
    n = ok.sum(axis=axis)
    s = np.where(ok, values, 0.0).sum(axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def finite_std(values: Array, axis: int = -1) -> Array:
    """Sample standard deviation (ddof = 1) ignoring NaN; NaN below two values."""
    ok = np.isfinite(values)
    n = ok.sum(axis=axis)
    m = finite_mean(values, axis)
    d = np.where(ok, values - np.expand_dims(m, axis), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1, np.sqrt((d**2).sum(axis=axis) / np.maximum(n - 1, 1)), np.nan)


def log10(values: ArrayLike) -> Array:
    v = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.isfinite(v), np.log10(np.maximum(v, LOG_FLOOR)), np.nan)


def percentiles(samples: Array, confidence: float) -> tuple[float, float]:
    s = np.asarray(samples, dtype=float)
    s = s[np.isfinite(s)]
    if not s.size:
        return math.nan, math.nan
    lo, hi = np.percentile(s, [50 * (1 - confidence), 50 * (1 + confidence)])
    return float(lo), float(hi)


def bootstrap_seed_means(
    values: ArrayLike, n_boot: int, rng: np.random.Generator, batch: int = 64
) -> Array:
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
            out[start : start + b] = np.where(
                count > 0, picked.sum(-1) / np.maximum(count, 1), np.nan
            )
    return out.reshape(n_boot, *shape)


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
