r"""The ``recovery`` fit: what a pattern does when activity is switched off and on again
(a ``pulse`` protocol on alpha - B, nematic_solids.model.protocol; docs/campaigns/fits.md, "Fits").

For every run, from its series and its snapshots: sigma2_S at the switch time :math:`t_s`
(the pulse's ``start``), at the restore time :math:`t_r = t_s + D` and at the end; whether the
pattern **vanished** while activity was low (sigma2_S at :math:`t_r` below ``vanish`` times its
value at :math:`t_s`), whether it **recovered** (sigma2_S at the end at least ``recover`` times
its value at :math:`t_s`) and how long after :math:`t_r` it took (the first saved time with
sigma2_S at that level again); and its **memory**, the Pearson correlation over the grid of
the order-parameter fields :math:`S(t_s)` and :math:`S(t_{\rm end})`
(:func:`memory`: 1 the same pattern in the same place, about 0 a new one), also of
:math:`S(t_s)` and :math:`S(t_r)`. A run without a pulse (a control) gives the values at
``switch`` (an option) and the end.
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

RECOVERY_OPTIONS = ("switch", "vanish", "recover")
PER_RUN = (
    "sigma2_before",
    "sigma2_restore",
    "sigma2_end",
    "vanished",
    "recovered",
    "recovery_time",
    "memory_restore",
    "memory_end",
)


def memory(a: np.ndarray, b: np.ndarray) -> float:
    """The Pearson correlation over the grid of two fields (NaN where one is uniform)."""
    da, db = a - a.mean(), b - b.mean()
    norm = math.sqrt(float(np.mean(da * da)) * float(np.mean(db * db)))
    return float(np.mean(da * db)) / norm if norm > 0 else math.nan


def pulse_times(phase: xr.Dataset, coords: Mapping[str, Any], switch: float | None) -> tuple:
    """``(t_s, t_r)`` of a run at ``coords``: the pulse of alpha - B's protocol (its swept
    numbers from ``coords``), else ``(switch, nan)``."""
    raw = phase.attrs.get("param_protocol")
    pulse = None
    if raw:
        spec = json.loads(str(raw)).get("alpha_minus_B", {})
        pulse = spec.get("pulse") if isinstance(spec, Mapping) else None
    if pulse is None:
        if switch is None:
            raise FitError("recovery: no pulse of alpha_minus_B in the protocol; give switch: TIME")
        return float(switch), math.nan
    numbers = {k: coords.get(f"alpha_minus_B_{k}", pulse.get(k)) for k in ("start", "duration")}
    if any(v is None for v in numbers.values()):
        raise FitError("recovery: the pulse has no start or duration")
    start = float(numbers["start"]) if switch is None else float(switch)
    return start, float(numbers["start"]) + float(numbers["duration"])


def _snapshot_S(run: xr.Dataset, t: float) -> np.ndarray | None:
    times: list[float] = (
        [float(x) for x in run["snapshot_time"].values] if "snapshot_time" in run.dims else []
    )
    k = next((i for i, s in enumerate(times) if math.isclose(s, t, abs_tol=1e-9)), None)
    if k is None or "q1" not in run:
        return None
    q1, q2 = (run[n].isel(snapshot_time=k).values.astype(float) for n in ("q1", "q2"))
    return np.sqrt(q1**2 + q2**2)


def run_recovery(
    path: Path, t_s: float, t_r: float, vanish: float, recover: float
) -> dict[str, float]:
    """The per-run values (:data:`PER_RUN`) of the run file ``path``."""
    out = dict.fromkeys(PER_RUN, math.nan)
    with xr.open_dataset(path) as run:
        t = series_time(run).values.astype(float)
        s2 = run["sigma2_S"].values.astype(float)

        def at(time: float) -> float:
            k = np.nonzero(np.isclose(t, time, atol=1e-9))[0]
            return float(s2[k[0]]) if k.size else math.nan

        before, end = at(t_s), float(s2[-1])
        out.update(sigma2_before=before, sigma2_end=end)
        S_s = _snapshot_S(run, t_s)
        S_end = _snapshot_S(run, float(run["snapshot_time"].values[-1]))
        if S_s is not None and S_end is not None:
            out["memory_end"] = memory(S_s, S_end)
        if math.isfinite(before) and before > 0:
            out["recovered"] = float(end >= recover * before)
        if math.isfinite(t_r):
            restore = at(t_r)
            out["sigma2_restore"] = restore
            out["vanished"] = float(restore < vanish * before)
            S_r = _snapshot_S(run, t_r)
            if S_s is not None and S_r is not None:
                out["memory_restore"] = memory(S_s, S_r)
            back = np.nonzero((t >= t_r) & (s2 >= recover * before))[0]
            out["recovery_time"] = float(t[back[0]] - t_r) if back.size else math.nan
    return out


def recovery(phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None) -> xr.Dataset:
    """The ``recovery`` fit (see the module docstring). Options: ``switch`` (the time the
    pattern is read before; default the pulse's start), ``vanish`` (default 0.01: two decades
    below), ``recover`` (default 0.5). Needs the run files (``root`` = results/<name>)."""
    check_options("recovery", options, RECOVERY_OPTIONS)
    if root is None:
        raise FitError("recovery: needs the campaign folder (run files)")
    ds = select(phase, options.get("select"))
    switch = options.get("switch")
    vanish, recover = float(options.get("vanish", 0.01)), float(options.get("recover", 0.5))
    dims = [*other_dims(ds, []), "seed"]
    rids = ds["run_id"].transpose(*dims).values
    status = ds["status"].transpose(*dims).values
    values = {n: np.full(rids.shape, np.nan) for n in PER_RUN}
    for idx in np.ndindex(rids.shape):
        if status[idx] != 1:
            continue
        coords = {d: ds[d].values[i].item() for d, i in zip(dims, idx, strict=True)}
        t_s, t_r = pulse_times(ds, coords, None if switch is None else float(switch))
        got = run_recovery(root / "runs" / f"{rids[idx]}.nc", t_s, t_r, vanish, recover)
        for n in PER_RUN:
            values[n][idx] = got[n]
    long = {
        "sigma2_before": "sigma2_S at the switch time (activity lowered)",
        "sigma2_restore": "sigma2_S at the restore time (activity back)",
        "sigma2_end": "sigma2_S at t_final",
        "vanished": f"1 if sigma2_S at the restore time is below {vanish:g} of its value at the "
        "switch time",
        "recovered": f"1 if sigma2_S at t_final is at least {recover:g} of its value at the "
        "switch time",
        "recovery_time": f"time after the restore until sigma2_S is back to {recover:g} of its "
        "value at the switch time (units of tau)",
        "memory_restore": "correlation over the grid of S at the switch and restore times",
        "memory_end": "correlation over the grid of S at the switch time and at t_final",
    }
    result = xr.Dataset(coords=coord_copy(ds, dims))
    point_dims = dims[:-1]
    for n in PER_RUN:
        result[f"recovery_{n}"] = variable(dims, values[n], long[n])
        mean = finite_mean(values[n])
        result[f"recovery_{n}_mean"] = variable(point_dims, mean, "seed mean of " + long[n])
    for v in result.data_vars.values():
        v.attrs.update({"fit_vanish": vanish, "fit_recover": recover})
    return result
