r"""The ``alpha_cr`` and ``scaling`` fits: the critical activity from the pattern sizes and
the exponent of :math:`\lambda = c\,[K/(\alpha - B - \alpha^{cr})]^{\beta}` (paper Eq. (7);
docs/campaigns/fits.md, "Fits"). The runs that count: patterned, and past the first peak of
:math:`\sigma^2_S(t)`."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from ..campaign import AMB
from ..errors import FitError
from .options import bootstrap_rng, check_options
from .phase import other_dims, select, variable, with_dim
from .size_laws import SizeScaling, patterned_level, size_scaling
from .statistics import (
    Array,
    bootstrap_seed_means,
    finite_mean,
    finite_std,
    percentiles,
)

log = logging.getLogger(__name__)

SIZE_OPTIONS = (
    "method",
    "exponent",
    "observable",
    "min_sigma2",
    "min_gap",
    "alpha_cr_min",
    "require_peak",
    "peak_margin",
)


def peak_not_reached(
    t_peak: ArrayLike, t_final: ArrayLike, save_every: ArrayLike = 0.0, margin: float = 1.0
) -> NDArray[np.bool_]:
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


def _unpeaked(
    ds: xr.Dataset, require: bool, margin: float, t_name: str = "t_peak"
) -> tuple[NDArray[np.bool_], str]:
    """:func:`peak_not_reached` for every run of ``ds`` (dims K, alpha_minus_B, seed), and a
    description of the check for the fit's attributes. Without the peak time ``t_name`` or
    ``t_final`` in phase.nc no run is flagged (logged)."""
    dims = ("K", AMB, "seed")
    none = np.zeros(tuple(ds.sizes[d] for d in dims), dtype=bool)
    if not require:
        return none, "off (require_peak: false)"
    if t_name not in ds:
        log.warning(
            "alpha_cr: phase.nc has no %s: cannot tell runs that did not reach "
            "the first peak of sigma2_S; every run counts",
            t_name,
        )
        return none, f"not done: phase.nc has no {t_name}"
    t_final = _run_setting(ds, "t_final")
    if t_final is None:
        log.warning(
            "alpha_cr: t_final of the runs unknown (no num_t_final attribute in "
            "phase.nc): cannot tell runs that did not reach the first peak of "
            "sigma2_S; every run counts"
        )
        return none, "not done: t_final unknown"
    save_every = _run_setting(ds, "save_every")
    check = f"{t_name} >= t_final - {margin:g} save_every"
    if save_every is None:
        log.warning(
            "alpha_cr: save_every of the runs unknown (no num_save_every attribute in "
            "phase.nc): only runs with t_peak = t_final count as without a peak"
        )
        save_every, check = xr.DataArray(0.0), f"{t_name} >= t_final (save_every unknown)"
    t_peak = ds[t_name]
    tp, tf, se = (
        v.broadcast_like(t_peak).transpose(*dims).values for v in (t_peak, t_final, save_every)
    )
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
    extra = other_dims(ds, ["K", AMB])
    if extra:
        raise FitError(
            f"alpha_cr/scaling: the phase diagram also varies {', '.join(extra)}; "
            f"pick one value with the option select: {{{extra[0]}: VALUE}}"
        )
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
        log.info(
            "alpha_cr: %d of %d patterned runs left out (first peak of sigma2_S not reached: %s)",
            n_left_out,
            int(sized.sum()),
            check,
        )
    peak_attrs: dict[str, Any] = {
        "fit_require_peak": int(require),
        "fit_peak_margin": margin,
        "fit_peak_check": check,
        "fit_n_unpeaked": n_left_out,
        "fit_n_patterned": int(sized.sum()),
    }
    return _SizeData(
        ds=ds,
        K=ds["K"].values.astype(float),
        amb=ds[AMB].values.astype(float),
        lam=np.where(sized & ~unpeaked, lam, np.nan),
        level=level,
        unpeaked=left_out.sum(-1).astype(np.int32),
        peak_attrs=peak_attrs,
    )


def _alpha_cr_bound(options: Mapping[str, Any]) -> float | None:
    bound = options.get("alpha_cr_min", 0.0)
    return None if bound is None else float(bound)


def _alpha_cr_vars(
    data: _SizeData,
    fit: SizeScaling,
    boot: Array,
    boot_at_bound: Array,
    conf: float,
    options: Mapping[str, Any],
    counts: Array,
) -> xr.Dataset:
    ds = data.ds
    res = xr.Dataset(coords={"K": ds["K"].variable, AMB: ds[AMB].variable})
    lo_hi = np.array([percentiles(boot[:, i], conf) for i in range(boot.shape[1])])
    method = str(options.get("method", "linear"))
    bound = _alpha_cr_bound(options)
    attrs: dict[str, Any] = {
        "fit_method": method,
        "fit_exponent": float(options.get("exponent", 0.5)),
        "fit_observable": str(options.get("observable", "lambda_peak")),
        "fit_min_sigma2": data.level,
        "fit_alpha_cr_min": "none" if bound is None else bound,
        **data.peak_attrs,
    }
    res["alpha_cr"] = variable(
        ["K"],
        fit.alpha_cr,
        "critical activity alpha_cr from the pattern sizes (paper Eq. 7)",
        **attrs,
    )
    res["alpha_cr_lower"] = variable(
        ["K"], lo_hi[:, 0], "alpha_cr seed-bootstrap interval, lower end"
    )
    res["alpha_cr_upper"] = variable(
        ["K"], lo_hi[:, 1], "alpha_cr seed-bootstrap interval, upper end"
    )
    res["alpha_cr_std"] = variable(
        ["K"], finite_std(boot.T), "alpha_cr seed-bootstrap standard deviation"
    )
    res["alpha_cr_prefactor"] = variable(
        ["K"], fit.prefactor_K, "c in lambda = c (K / (alpha - B - alpha_cr))^(1/2) at this K", "L"
    )
    res["alpha_cr_at_bound"] = variable(
        ["K"],
        fit.at_bound.astype(np.int8),
        "1 if alpha_cr is at its lower bound "
        "alpha_cr_min (the unbounded fit would put it below), 0 otherwise",
        flag_values=np.array([0, 1], dtype=np.int8),
        flag_meanings="free at_bound",
        fit_alpha_cr_min=attrs["fit_alpha_cr_min"],
    )
    finite = np.isfinite(boot).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(finite > 0, boot_at_bound.sum(axis=0) / np.maximum(finite, 1), np.nan)
    res["alpha_cr_bound_fraction"] = variable(
        ["K"],
        frac,
        "fraction of the bootstrap replicates (with a fit) whose alpha_cr is at its lower bound",
    )
    res["alpha_cr_n_points"] = variable(
        ["K"], counts.astype(np.int32), "alpha - B values with a pattern used in the fit"
    )
    res["alpha_cr_unpeaked_count"] = variable(
        ["K", AMB],
        data.unpeaked,
        "patterned runs left out of the alpha_cr and scaling fits "
        "because the first peak of sigma2_S(t) was not reached by t_final "
        f"({data.peak_attrs['fit_peak_check']})",
        fit_peak_check=data.peak_attrs["fit_peak_check"],
    )
    res["alpha_cr_n_unpeaked"] = variable(
        ["K"],
        data.unpeaked.sum(axis=1).astype(np.int32),
        "patterned runs at this K left out of the fits: first "
        "peak of sigma2_S(t) not reached by t_final",
    )
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
    rng = bootstrap_rng(options)
    mean = finite_mean(lam)
    fit = size_scaling(K, amb, mean, method=method, exponent=exponent, alpha_cr_min=bound)
    counts = np.isfinite(mean).sum(axis=1)
    if not np.any(np.isfinite(fit.alpha_cr)):
        log.warning(
            "alpha_cr: no fit at any K (each needs two patterned alpha - B values "
            "with lambda^-2 increasing in alpha - B)"
        )
    if np.any(fit.at_bound):
        log.info(
            "alpha_cr: at its bound %g for K = %s",
            bound,
            ", ".join(f"{k:g}" for k in K[fit.at_bound]),
        )
    boots = bootstrap_seed_means(lam, n_boot, rng)
    acr_b = np.full((n_boot, K.size), np.nan)
    bound_b = np.zeros((n_boot, K.size), dtype=bool)
    beta_b = np.full(n_boot, np.nan)
    for b in range(n_boot):
        fb = size_scaling(K, amb, boots[b], method=method, exponent=exponent, alpha_cr_min=bound)
        acr_b[b] = fb.alpha_cr
        bound_b[b] = fb.at_bound
        beta_b[b] = fb.exponent
    res = _alpha_cr_vars(data, fit, acr_b, bound_b, conf, options, counts)
    if not with_scaling:
        return res
    dims2 = ["K", AMB]
    res["scaling_x"] = variable(dims2, fit.x, "K / (alpha - B - alpha_cr(K))")
    res["scaling_lambda_mean"] = variable(
        dims2,
        mean,
        "seed mean of the pattern size over the patterned runs that reached their peak",
        "L",
    )
    res["scaling_lambda_std"] = variable(
        dims2,
        finite_std(lam),
        "seed standard deviation "
        "(ddof = 1) of the pattern size over the patterned runs "
        "that reached their peak",
        "L",
    )
    res["scaling_lambda_count"] = variable(
        dims2,
        np.isfinite(lam).sum(-1).astype(np.int32),
        "patterned runs that reached their peak at this point",
    )
    res["scaling_used"] = variable(
        dims2, fit.used.astype(np.int8), "1 if the point enters the exponent fit"
    )
    lo, hi = percentiles(beta_b, conf)
    n_K = int(np.any(fit.used, axis=1).sum())
    attrs: dict[str, Any] = {
        "fit_alpha_cr_method": method,
        "fit_n_boot": n_boot,
        "fit_confidence": conf,
        "fit_n_points": int(fit.used.sum()),
        "fit_n_K": n_K,
        "fit_alpha_cr_min": "none" if bound is None else bound,
        "fit_n_alpha_cr_at_bound": int(fit.at_bound.sum()),
        **data.peak_attrs,
    }
    res["scaling_exponent"] = variable(
        [],
        fit.exponent,
        "exponent beta of lambda = c (K / (alpha - B - alpha_cr))^beta (paper Eq. 7: 1/2)",
        **attrs,
    )
    res["scaling_exponent_lower"] = variable(
        [], lo, "scaling exponent, seed-bootstrap interval lower end"
    )
    res["scaling_exponent_upper"] = variable(
        [], hi, "scaling exponent, seed-bootstrap interval upper end"
    )
    res["scaling_exponent_std"] = variable(
        [], finite_std(beta_b[None, :])[0], "scaling exponent, seed-bootstrap standard deviation"
    )
    res["scaling_prefactor"] = variable([], fit.prefactor, "prefactor c of the scaling fit", "L")
    if n_K < 2:
        log.warning(
            "scaling: %d value(s) of K with a pattern; the exponent then mostly "
            "restates the alpha_cr fit (see docs/campaigns/fits.md, Fits)",
            n_K,
        )
    return res


def alpha_cr(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None) -> xr.Dataset:
    """The ``alpha_cr`` fit (docs/campaigns/fits.md). Options: ``method`` (linear, nonlinear),
    ``exponent``, ``observable`` (default ``lambda_peak``), ``min_sigma2``, ``min_gap``."""
    check_options("alpha_cr", options, SIZE_OPTIONS)
    return _size_fit(phase, options, with_scaling=False)


def scaling(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None) -> xr.Dataset:
    """The ``scaling`` fit (docs/campaigns/fits.md, "Fits"); also writes the ``alpha_cr`` variables.
    Options: those of ``alpha_cr``."""
    check_options("scaling", options, SIZE_OPTIONS)
    return _size_fit(phase, options, with_scaling=True)
