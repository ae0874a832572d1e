"""The ``anisotropy`` fit: the trend of <cos 2 theta> with the applied strain
(docs/campaigns/fits.md, "Fits")."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..errors import FitError
from .options import bootstrap_rng, check_options
from .phase import coord_copy, other_dims, select, variable, with_dim
from .statistics import bootstrap_seed_means, finite_mean, finite_std, fit_line, percentiles

ANISOTROPY_OPTIONS = ("axis", "observable")


def anisotropy(
    phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
) -> xr.Dataset:
    """The ``anisotropy`` fit (docs/campaigns/fits.md, "Fits"). Options: ``axis`` (default ``eps``),
    ``observable`` (default ``cos2theta``)."""
    check_options("anisotropy", options, ANISOTROPY_OPTIONS)
    ds = select(phase, options.get("select"))
    axis = str(options.get("axis", "eps"))
    observable = str(options.get("observable", "cos2theta"))
    if observable not in ds:
        raise FitError(f"anisotropy: observable {observable!r} is not in phase.nc")
    ds = with_dim(ds, axis)
    others = other_dims(ds, [axis])
    data = ds[observable].transpose(*others, axis, "seed").values.astype(float)
    x = ds[axis].values.astype(float)
    oshape = tuple(ds.sizes[d] for d in others)
    flat = data.reshape(-1, x.size, data.shape[-1])
    n_boot = int(options.get("n_boot", 1000))
    conf = float(options.get("confidence", 0.95))
    rng = bootstrap_rng(options)
    xs = np.broadcast_to(x[:, None], flat.shape[1:])
    slope = np.full(flat.shape[0], np.nan)
    icept = np.full(flat.shape[0], np.nan)
    lo = np.full(flat.shape[0], np.nan)
    hi = np.full(flat.shape[0], np.nan)
    for k in range(flat.shape[0]):
        slope[k], icept[k] = fit_line(xs.ravel(), flat[k].ravel())
        if np.isfinite(flat[k]).sum(-1).max(initial=0) < 2:
            continue  # one seed: nothing to resample, the interval is unknown (NaN), not zero
        if np.isfinite(flat[k]).any(-1).sum() < 2:
            continue  # one strain with values (a refined campaign's line): no slope
        boot = bootstrap_seed_means(flat[k], n_boot, rng)
        sb = np.array([fit_line(x, boot[b])[0] for b in range(n_boot)])
        lo[k], hi[k] = percentiles(sb, conf)
    mean = finite_mean(flat)
    count = np.isfinite(flat).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        sem = finite_std(flat) / np.sqrt(np.where(count > 0, count, np.nan))
    res = xr.Dataset(coords={**coord_copy(ds, others), axis: ds[axis].variable})
    per = [*others, axis]
    res["anisotropy_mean"] = variable(
        per, mean.reshape(*oshape, x.size), f"seed mean of {observable}"
    )
    res["anisotropy_sem"] = variable(
        per, sem.reshape(*oshape, x.size), f"standard error of the seed mean of {observable}"
    )
    attrs: dict[str, Any] = {
        "fit_axis": axis,
        "fit_observable": observable,
        "fit_n_boot": n_boot,
        "fit_confidence": conf,
    }
    res["anisotropy_slope"] = variable(
        others,
        slope.reshape(oshape),
        f"least-squares slope d<{observable}>/d{axis} over all runs",
        **attrs,
    )
    res["anisotropy_slope_lower"] = variable(
        others, lo.reshape(oshape), "slope seed-bootstrap interval, lower end"
    )
    res["anisotropy_slope_upper"] = variable(
        others, hi.reshape(oshape), "slope seed-bootstrap interval, upper end"
    )
    res["anisotropy_intercept"] = variable(
        others, icept.reshape(oshape), f"least-squares intercept of {observable} at {axis} = 0"
    )
    return res
