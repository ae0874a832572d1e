"""The ``stability`` fit: stable and unstable runs in the (activity, strain) plane against
the linear-stability boundary, paper Fig. A1 (docs/campaigns/fits.md, "Fits"). Reads the run
files as well as phase.nc."""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from nematic_solids.model.errors import NematicError

from ..campaign import AMB
from ..errors import FitError
from ..files import series_time
from .options import check_options
from .phase import fixed_parameter, is_swept, other_dims, select, variable, with_dim
from .statistics import Array

log = logging.getLogger(__name__)

STABILITY_OPTIONS = (
    "activity",
    "strain",
    "unstable_reasons",
    "fraction",
    "n_fine",
    "incompressible",
)


def run_growth(path: Path) -> float:
    """log10 sigma2_S(t_final) / sigma2_S(t_final / 2) of a run file (NaN if it cannot be
    read or has fewer than two saved times): the stability fit's criterion (Fig. A1), also
    the observable ``growth`` of an adaptive campaign (:mod:`nematic_solids.sweep.refine`)."""
    try:
        with xr.open_dataset(path, engine="netcdf4") as run:
            t = series_time(run).values.astype(float)
            s = run["sigma2_S"].values.astype(float)
    except (OSError, KeyError, ValueError) as e:
        log.warning("cannot read %s (%s)", path, e)
        return math.nan
    if t.size < 2:
        return math.nan
    half = int(np.argmin(np.abs(t - 0.5 * t[-1])))
    if half == t.size - 1:
        return math.nan
    floor = 1e-300  # sigma2_S = 0 exactly (S0 = 0 and no noise) is as small as it gets
    return float(np.log10(max(s[-1], floor)) - np.log10(max(s[half], floor)))


def stability_parameters(phase: xr.Dataset, coords: Mapping[str, float]) -> Any:
    """:class:`nematic_solids.model.parameters.Parameters` of a grid point: the fixed ``param_*``
    attributes of phase.nc with the swept values ``coords``."""
    from nematic_solids.model.parameters import Parameters

    # each attribute back to its field's type (netCDF stores ints and strings as they are)
    kinds = {
        f.name: {"int": int, "str": str}.get(str(f.type), float)
        for f in dataclasses.fields(Parameters)
    }
    values: dict[str, Any] = {}
    for key, value in phase.attrs.items():
        name = key.removeprefix("param_")
        if key.startswith("param_") and name in kinds:
            values[name] = kinds[name](value)
    values.update({k: float(v) for k, v in coords.items()})
    if AMB in values and "alpha" in values:
        if AMB in coords:
            values.pop("alpha")
        else:
            values.pop(AMB)
    return Parameters.from_dict(values)


def stability(
    phase: xr.Dataset, options: Mapping[str, Any], root: Path | None = None
) -> xr.Dataset:
    """The ``stability`` fit (docs/campaigns/fits.md, "Fits"). Options: ``activity`` (axis,
    default ``chi`` if swept else ``alpha_minus_B``), ``strain`` (default ``eps``),
    ``unstable_reasons`` (default [spin_diverged]), ``fraction`` (majority threshold,
    default 0.5), ``n_fine`` (points of the theory curve, default 400), ``incompressible``
    (default: the campaign's).
    Needs the run files (``root`` = results/<name>)."""
    check_options("stability", options, STABILITY_OPTIONS)
    if root is None:
        raise FitError("stability: needs the campaign folder (run files)")
    from nematic_solids.model.stability import critical_eps_closed_form, paper_eq6

    ds = select(phase, options.get("select"))
    act = str(options.get("activity") or ("chi" if is_swept(ds, "chi") else AMB))
    strain = str(options.get("strain", "eps"))
    ds = with_dim(with_dim(ds, act), strain)
    extra = other_dims(ds, [act, strain])
    if extra:
        raise FitError(
            f"stability: the phase diagram also varies {', '.join(extra)}; pick one "
            f"value with the option select: {{{extra[0]}: VALUE}}"
        )
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
            g = run_growth(root / "runs" / f"{rids[idx]}.nc")
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
    incompressible = bool(options.get("incompressible", int(ds.attrs.get("num_incompressible", 0))))
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
        return np.where(np.isfinite(ours), ours, np.nan), np.where(
            np.isfinite(paper), paper, np.nan
        )

    th, th_paper = theory(a)
    fth, fth_paper = theory(fine)
    amb = fixed_parameter(ds, AMB)
    scale = (
        amb
        if act == "chi" and amb is not None
        else (fixed_parameter(ds, "chi") or 1.0)
        if act == AMB
        else 1.0
    )
    res = xr.Dataset(
        coords={
            act: ds[act].variable,
            strain: ds[strain].variable,
            "seed": ds["seed"].variable,
            "activity_fine": (
                "activity_fine",
                fine,
                {"long_name": f"{act} on a fine grid (theory curve)", "units": "1"},
            ),
        }
    )
    attrs: dict[str, Any] = {
        "fit_criterion": "sigma2_S(t_final) > sigma2_S(t_final / 2), or failed with "
        "reason in " + (", ".join(sorted(reasons)) or "(none)"),
        "fit_activity": act,
        "fit_strain": strain,
        "fit_activity_scale": float(scale),
        "fit_incompressible": int(incompressible),
        "fit_mechanics": str(ds.attrs.get("num_mechanics", "")),
    }
    res["stability_growth"] = variable(
        dims, growth, "log10 sigma2_S(t_final) / sigma2_S(t_final / 2) (decades)", "1"
    )
    res["stability_unstable"] = variable(
        dims,
        unstable,
        "1 unstable, 0 stable, -1 unknown (missing, or failed for another reason)",
        **attrs,
    )
    res["stability_fraction_unstable"] = variable(
        [act, strain], frac, "fraction of classified seeds that are unstable"
    )
    res["stability_eps_c_sim"] = variable(
        [act],
        eps_sim,
        "simulated critical strain: midpoint between the last stable and the first unstable strain",
        fit_fraction=frac_needed,
    )
    res["stability_eps_c_sim_lower"] = variable(
        [act], eps_lo, "simulated critical strain, grid interval lower end"
    )
    res["stability_eps_c_sim_upper"] = variable(
        [act], eps_hi, "simulated critical strain, grid interval upper end"
    )
    res["stability_eps_c_theory"] = variable(
        [act],
        th,
        "critical strain of the linear stability analysis (docs/stability.md Eq. S10); NaN: none",
    )
    res["stability_eps_c_paper"] = variable(
        [act], th_paper, "critical strain of paper Eq. (6) as printed"
    )
    res["stability_theory_fine"] = variable(
        ["activity_fine"],
        fth,
        "critical strain of the linear stability analysis on the fine activity axis",
    )
    res["stability_paper_fine"] = variable(
        ["activity_fine"], fth_paper, "paper Eq. (6) as printed on the fine activity axis"
    )
    return res
