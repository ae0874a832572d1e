r"""The size laws, on arrays: the level that tells patterned from relaxed runs, the critical
activity :math:`\alpha^{cr}` from the pattern sizes and the exponent of
:math:`\lambda = c\,[K/(\alpha - B - \alpha^{cr})]^{\beta}` (paper Eq. (7)). The fits on
phase.nc that use them: :mod:`nematic_solids.sweep.analysis.sizes`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import FitError
from .statistics import Array, fit_line, fit_power_law


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


class AlphaCrFit(NamedTuple):
    """:func:`alpha_cr_from_sizes` for one K: the critical activity, the prefactor c and
    whether the bound ``alpha_cr >= alpha_cr_min`` is active (the unbounded optimum is
    below it)."""

    alpha_cr: float
    prefactor: float
    at_bound: bool


def alpha_cr_from_sizes(
    amb: ArrayLike,
    lam: ArrayLike,
    K: float,
    *,
    method: str = "linear",
    exponent: float = 0.5,
    alpha_cr_min: float | None = 0.0,
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
        opt = minimize_scalar(
            lambda acr: profile(acr)[1],
            bounds=(lower, top - 1e-9 * span),
            method="bounded",
            options={"xatol": 1e-10 * span},
        )
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


def size_scaling(
    K: ArrayLike,
    amb: ArrayLike,
    lam_mean: ArrayLike,
    *,
    method: str = "linear",
    exponent: float = 0.5,
    alpha_cr: ArrayLike | None = None,
    alpha_cr_min: float | None = 0.0,
) -> SizeScaling:
    r"""alpha_cr(K) (:func:`alpha_cr_from_sizes` with the bound ``alpha_cr_min``, unless
    given) and the exponent of :math:`\lambda = c\,x^\beta`,
    :math:`x = K/(\alpha - B - \alpha^{cr}(K))` (:func:`fit_power_law`) over the points with
    :math:`x > 0`. ``lam_mean`` is ``(len(K), len(amb))``, NaN where there is no pattern."""
    Ka = np.asarray(K, dtype=float)
    a = np.asarray(amb, dtype=float)
    lm = np.asarray(lam_mean, dtype=float)
    if alpha_cr is None:
        fits = [
            alpha_cr_from_sizes(
                a, lm[i], float(Ka[i]), method=method, exponent=exponent, alpha_cr_min=alpha_cr_min
            )
            for i in range(Ka.size)
        ]
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
    return SizeScaling(
        alpha_cr=acr, prefactor_K=cK, at_bound=at_bound, x=x, used=used, exponent=beta, prefactor=c
    )
