r"""The ``moduli`` fit: storage and loss moduli from an oscillatory shear (a ``sine`` protocol
of eps, nematic_solids.model.protocol; docs/campaigns/fits.md, "Fits").

Under :math:`\epsilon(t) = \epsilon_0 \sin\varphi`, :math:`\varphi = 2\pi (t - t_s)/T`, the
macroscopic deviatoric stress of each run (the series ``stress_shear``,
:math:`\langle (P_{11} - P_{22})/2 \rangle`) is fitted by least squares over the full periods
of the fit window with

.. math::
    \sigma(t) = c_0 + c_1 (t - t_w) + a_1 \sin\varphi + b_1 \cos\varphi
                + a_3 \sin 3\varphi + b_3 \cos 3\varphi ,

(the drift :math:`c_1` absorbs a pattern that still coarsens, the third harmonic the
response's first nonlinearity), and

.. math::
    G' = a_1 / (2 \epsilon_0), \qquad G'' = b_1 / (2 \epsilon_0),

normalised so that the passive matrix at small strain has :math:`G' = G = 1`, :math:`G'' = 0`
(its stress is :math:`2 G \epsilon`). ``nonlinearity`` is
:math:`\sqrt{a_3^2 + b_3^2} / \sqrt{a_1^2 + b_1^2}`; a response linear in
:math:`\epsilon_0` has the same moduli at two amplitudes (a campaign sweeping
``eps_amplitude`` shows it).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..errors import FitError
from ..files import series_time
from .options import check_options
from .phase import coord_copy, other_dims, select, variable
from .statistics import finite_mean

MODULI_OPTIONS = ("skip", "periods")
PER_RUN = ("storage", "loss", "nonlinearity", "prestress")


def sine_of(phase: xr.Dataset, coords: Mapping[str, Any]) -> tuple[float, float, float]:
    """``(amplitude, period, start)`` of the eps sine of the campaign's protocol at
    ``coords`` (its swept numbers from there)."""
    raw = phase.attrs.get("param_protocol")
    spec = json.loads(str(raw)).get("eps", {}) if raw else {}
    sine = spec.get("sine") if isinstance(spec, Mapping) else None
    if sine is None:
        raise FitError("moduli: the protocol has no sine of eps (an oscillatory shear)")
    get = {k: coords.get(f"eps_{k}", sine.get(k)) for k in ("amplitude", "period", "start")}
    if get["amplitude"] is None or get["period"] is None:
        raise FitError("moduli: the sine of eps has no amplitude or period")
    return float(get["amplitude"]), float(get["period"]), float(get["start"] or 0.0)


def fit_moduli(
    t: np.ndarray, stress: np.ndarray, amplitude: float, period: float, start: float, window: float
) -> dict[str, float]:
    """The moduli of one stress series over the full periods after ``window`` (see the
    module docstring); NaN without one full period of finite values."""
    out = dict.fromkeys(PER_RUN, math.nan)
    periods = math.floor((t[-1] - window) / period + 1e-9) if t.size else 0
    if periods < 1 or amplitude == 0:
        return out
    end = window + periods * period
    use = (t >= window - 1e-9) & (t <= end + 1e-9) & np.isfinite(stress)
    if use.sum() < 8:
        return out
    phi = 2.0 * np.pi * (t[use] - start) / period
    X = np.stack(
        [
            np.ones_like(phi),
            t[use] - window,
            np.sin(phi),
            np.cos(phi),
            np.sin(3 * phi),
            np.cos(3 * phi),
        ],
        axis=1,
    )
    coef, *_ = np.linalg.lstsq(X, stress[use], rcond=None)
    c0, _, a1, b1, a3, b3 = (float(c) for c in coef)
    first = math.hypot(a1, b1)
    out.update(
        storage=a1 / (2.0 * amplitude),
        loss=b1 / (2.0 * amplitude),
        nonlinearity=math.hypot(a3, b3) / first if first > 0 else math.nan,
        prestress=c0,
    )
    return out


def moduli(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None) -> xr.Dataset:
    """The ``moduli`` fit (see the module docstring). Options: ``skip`` (periods after the
    sine's start left out of the window, default 1), ``periods`` (the last so many full
    periods fitted; default every full period after the skipped ones). Needs the run files."""
    check_options("moduli", options, MODULI_OPTIONS)
    if root is None:
        raise FitError("moduli: needs the campaign folder (run files)")
    ds = select(phase, options.get("select"))
    skip = float(options.get("skip", 1))
    last = options.get("periods")
    dims = [*other_dims(ds, []), "seed"]
    rids = ds["run_id"].transpose(*dims).values
    status = ds["status"].transpose(*dims).values
    values = {n: np.full(rids.shape, np.nan) for n in PER_RUN}
    for idx in np.ndindex(rids.shape):
        if status[idx] != 1:
            continue
        coords = {d: ds[d].values[i].item() for d, i in zip(dims, idx, strict=True)}
        amplitude, period, start = sine_of(ds, coords)
        with xr.open_dataset(root / "runs" / f"{rids[idx]}.nc") as run:
            t = series_time(run).values.astype(float)
            stress = run["stress_shear"].values.astype(float) if "stress_shear" in run else None
        if stress is None:
            continue
        window = start + skip * period
        if last is not None and t.size:
            full = math.floor((t[-1] - window) / period + 1e-9)
            window += max(full - int(last), 0) * period
        got = fit_moduli(t, stress, amplitude, period, start, window)
        for n in PER_RUN:
            values[n][idx] = got[n]
    long = {
        "storage": "storage modulus G' (in-phase stress over 2 eps0; 1 for the passive matrix)",
        "loss": "loss modulus G'' (quadrature stress over 2 eps0; 0 for the passive matrix)",
        "nonlinearity": "third-harmonic amplitude of the stress over its first harmonic",
        "prestress": "mean deviatoric stress over the fit window",
    }
    result = xr.Dataset(coords=coord_copy(ds, dims))
    for n in PER_RUN:
        result[f"moduli_{n}"] = variable(dims, values[n], long[n])
        result[f"moduli_{n}_mean"] = variable(
            dims[:-1], finite_mean(values[n]), "seed mean of " + long[n]
        )
    for v in result.data_vars.values():
        v.attrs.update({"fit_skip": skip, "fit_periods": -1 if last is None else int(last)})
    return result
