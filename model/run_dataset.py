"""The Dataset of one run (and its run file): the CF-1.11 layout that
:func:`nematic_solids.model.simulate.run` returns, built from what the run recorded
(:func:`to_dataset`).

Dims ``t`` (the time series of every observable), ``snapshot_time, x, y`` (the fields at the
snapshot times); per-run scalars; every parameter (``param_<name>``) and numerics field
(``num_<name>``), the seed, the code version, the git commit, the status and the work counted
(solver steps, transforms by part) as attributes.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from . import __version__
from .checkpoint import SNAPSHOT_FIELDS
from .observables import first_peak, growth_peak
from .parameters import Numerics, Parameters
from .provenance import git_commit, library_versions_text
from .solver_base import ETDSolver

#: Layout of the Dataset (and run file): 2 names the time-series dimension ``t`` (1 called it
#: ``time``, which CF reserves for calendar time; readers take either).
SCHEMA_VERSION = 2
SERIES = (
    "mean_S",
    "sigma2_S",
    "cos2theta",
    "lambda",
    "lambda_mean",
    "mean_I1bar",
    "min_J",
    "mean_A",
    "free_energy",
    "residual",
    "rate_margin",
    "stress_shear",
    "stress_xy",
    "stress_mean",
)
#: CF units: the model is dimensionless (lengths in units of the domain size L, times in units
#: of tau, energies in units of G L^2), so every quantity has units "1" (UDUNITS: a pure
#: number) and its long_name says the scale; only the wall time is in seconds.
UNITS = {
    "mean_S": "1",
    "sigma2_S": "1",
    "cos2theta": "1",
    "lambda": "1",
    "lambda_mean": "1",
    "mean_I1bar": "1",
    "min_J": "1",
    "mean_A": "1",
    "free_energy": "1",
    "residual": "1",
    "rate_margin": "1",
    "stress_shear": "1",
    "stress_xy": "1",
    "stress_mean": "1",
}
LONG_NAMES = {
    "mean_S": "area mean of the nematic order parameter S",
    "sigma2_S": "variance of S over the unit domain (paper sigma_S^2)",
    "cos2theta": "anisotropy <cos 2 theta> = <q1 / S>",
    "lambda": "pattern size L / n, n the E^2-weighted mean shell of the radial spectrum of "
    "S - <S>, in units of L",
    "lambda_mean": "pattern size 2 pi / (spectrum-weighted mean |k| of S - <S>), in units of L",
    "mean_I1bar": "area mean of I1bar = tr C / J",
    "min_J": "minimum of J = det F",
    "mean_A": "area mean of the activity A",
    "free_energy": "total free energy, paper Eq. (1), in units of G L^2",
    "residual": "force-balance residual |Div P|_{H^-1} / max(1, |P|)",
    "rate_margin": "well-posedness margin of the rate problem, min det of its symbol / "
    "(kappa + 1): 1 passive, 0 ill posed",
    "stress_shear": "macroscopic deviatoric stress <(P11 - P22)/2>, conjugate to the applied "
    "pure shear eps, in units of G",
    "stress_xy": "macroscopic shear stress <P12>, in units of G",
    "stress_mean": "macroscopic mean normal stress <(P11 + P22)/2>, in units of G",
}
#: long_name and units of the per-run scalars
SCALARS = {
    "sigma2_S_final": ("sigma2_S at t_final", "1"),
    "mean_S_final": ("mean_S at t_final", "1"),
    "cos2theta_final": ("cos2theta at t_final", "1"),
    "lambda_final": ("pattern size lambda at t_final, in units of L", "1"),
    "lambda_mean_final": ("pattern size lambda_mean at t_final, in units of L", "1"),
    "t_peak": (
        "time of the first peak of sigma2_S(t) (growth-peak rule: the end of the "
        "growth phase), in units of tau",
        "1",
    ),
    "lambda_peak": (
        "pattern size lambda at the first peak of sigma2_S(t) (growth-peak rule), in units of L",
        "1",
    ),
    "lambda_mean_peak": (
        "pattern size lambda_mean at the first peak of sigma2_S(t) "
        "(growth-peak rule), in units of L",
        "1",
    ),
    "t_peak_literal": (
        "time of the first local maximum of sigma2_S(t) (the paper's literal "
        "rule), in units of tau",
        "1",
    ),
    "lambda_peak_literal": (
        "pattern size lambda at the first local maximum of sigma2_S(t) "
        "(the paper's literal rule), in units of L",
        "1",
    ),
    "rate_margin_min": ("smallest well-posedness margin of the rate problem over the run", "1"),
    "stopped_early": (
        "1 if the run ended before t_final because sigma2_S and mean_S were "
        "steady (numerics steady_tol, steady_window), else 0; the *_final "
        "values are then those at t_stopped",
        "1",
    ),
    "t_stopped": (
        "time the run ended early (steady observables); NaN if it ran to t_final, in units of tau",
        "1",
    ),
    "wall_time": ("wall-clock time of the run", "s"),
}


def _attr(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (list, tuple)):
        return json.dumps(list(value))
    if isinstance(
        value, dict
    ):  # a protocol (nematic_solids.model.protocol): its canonical form as JSON
        return json.dumps(value, sort_keys=True)
    return value


@dataclass
class RunWork:
    """The work a run counted and how it ran, as its file records them (attributes
    ``solver_*``, ``fft_*``; the scalar ``rate_margin_min`` with the saves' margins):
    :meth:`of_solver` for :func:`nematic_solids.model.simulate.run`; the accelerated backend
    fills it per seed (:mod:`nematic_solids.model.accelerated.datasets`). ``backend`` names
    what integrated the run, ``extra`` holds further attributes (a batch's)."""

    margin_min: float
    stats: dict[str, int]
    spin_iterations: int
    cg_iterations: int
    fft_count: int
    fft_parts: dict[str, int]
    fft_backend: str
    fft_plans: str
    backend: str = "compiled"
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of_solver(cls, solver: ETDSolver) -> RunWork:
        """What ``solver`` (and its PDE's mechanics and grid) counted."""
        mech, fft = solver.pde.mechanics, solver.pde.spectral.fft
        return cls(
            margin_min=solver.margin_min,
            stats=dict(solver.stats),
            spin_iterations=int(mech.spin_iterations),
            cg_iterations=int(mech.cg_iterations),
            fft_count=int(fft.count),
            fft_parts=dict(mech.fft_parts),
            fft_backend=fft.backend,
            fft_plans=fft.plan_source,
            backend=solver.pde.numerics.backend,
        )


def to_dataset(
    rows,
    snaps,
    x,
    params: Parameters,
    numerics: Numerics,
    seed: int,
    work: RunWork,
    *,
    status: str,
    reason: str,
    detail: str,
    t_failed: float,
    wall: float,
    t_stopped: float = math.nan,
    entry: str = "nematic_solids.model.simulate.run",
) -> xr.Dataset:
    """The run's Dataset from its saved ``rows`` (one dict of observables per save time),
    ``snaps`` ((time, fields) pairs), the grid's coordinates ``x``, its settings, the
    ``work`` it counted, its outcome, and the function that made it (``entry``)."""
    t = np.array([r["time"] for r in rows], dtype=float)
    data_vars: dict[str, Any] = {}
    for name in (*SERIES, "steps"):
        data_vars[name] = (
            "t",
            # (a run continued from a state saved before a series existed: NaN there)
            np.array([r.get(name, math.nan) for r in rows], dtype=float),
            {
                "long_name": LONG_NAMES.get(name, "accepted time steps"),
                "units": UNITS.get(name, "1"),
            },
        )
    fields = SNAPSHOT_FIELDS
    n = len(x)
    snap_t = np.array([s[0] for s in snaps], dtype=float)
    stack = np.stack([s[1] for s in snaps], axis=1) if snaps else np.zeros((len(fields), 0, n, n))
    for i, name in enumerate(fields):
        data_vars[name] = (
            ("snapshot_time", "x", "y"),
            stack[i],
            {
                "long_name": {
                    "q1": "Q11 = S cos 2 theta",
                    "q2": "Q12 = S sin 2 theta",
                    "A": "activity A",
                    "u1": "periodic displacement fluctuation u~_1",
                    "u2": "periodic displacement fluctuation u~_2",
                    "I1bar": "I1bar = tr C / J",
                }[name],
                "units": "1",
            },
        )
    sig = data_vars["sigma2_S"][1]
    lam = data_vars["lambda"][1]
    ok_final = status == "ok" and len(t) > 0
    scalars = {}
    for name in ("sigma2_S", "mean_S", "cos2theta", "lambda"):
        series = data_vars[name][1]
        scalars[f"{name}_final"] = float(series[-1]) if ok_final else float("nan")
    lam_mean = data_vars["lambda_mean"][1]
    scalars["lambda_mean_final"] = float(lam_mean[-1]) if ok_final else float("nan")
    peaks = {"": growth_peak(sig, t), "_literal": first_peak(sig)} if len(t) else {}
    for suffix in ("", "_literal"):
        ip = peaks.get(suffix)
        scalars[f"t_peak{suffix}"] = float(t[ip]) if ip is not None else float("nan")
        scalars[f"lambda_peak{suffix}"] = float(lam[ip]) if ip is not None else float("nan")
    ip = peaks.get("")
    scalars["lambda_mean_peak"] = float(lam_mean[ip]) if ip is not None else float("nan")
    rates = data_vars["rate_margin"][1]
    margin = min(work.margin_min, float(np.nanmin(rates)) if np.any(np.isfinite(rates)) else np.inf)
    scalars["rate_margin_min"] = margin if np.isfinite(margin) else float("nan")
    scalars["stopped_early"] = float(math.isfinite(t_stopped))
    scalars["t_stopped"] = t_stopped
    scalars["wall_time"] = wall
    for name, value in scalars.items():
        long_name, units = SCALARS[name]
        data_vars[name] = ((), value, {"long_name": long_name, "units": units})
    created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    attrs: dict[str, Any] = {
        "Conventions": "CF-1.11",
        "title": "active nematic solid simulation (Yang, Guo, Mahadevan, Eqs. 1-5)",
        "source": f"active-nematic-solids {__version__} {entry}",
        "history": f"{created}: simulated by {entry} (seed {int(seed)})",
        "library_versions": library_versions_text(),
        "status": status,
        "reason": reason,
        "detail": detail,
        "t_failed": t_failed,
        "seed": int(seed),
        "code_version": __version__,
        "git_commit": git_commit(),
        "schema_version": SCHEMA_VERSION,
        "parameters_json": json.dumps(params.to_dict(), sort_keys=True),
        "numerics_json": json.dumps(numerics.to_dict(), sort_keys=True),
        "run_backend": work.backend,
        "fft_backend": work.fft_backend,
        "fft_plans": work.fft_plans,
        **{f"solver_{k}": int(v) for k, v in work.stats.items()},
        "solver_spin_iterations": int(work.spin_iterations),
        "solver_cg_iterations": int(work.cg_iterations),
        "fft_count": int(work.fft_count),
        **{f"fft_{k}": int(v) for k, v in work.fft_parts.items()},
        **work.extra,
    }
    attrs.update({f"param_{k}": _attr(v) for k, v in params.to_dict().items()})
    attrs["param_alpha_minus_B"] = params.alpha_minus_B
    attrs.update({f"num_{k}": _attr(v) for k, v in numerics.to_dict().items()})
    # the dimensionless time is "t", not "time": CF (and its checkers) take a coordinate named
    # time for a calendar time ("<unit> since <epoch>")
    coords = {
        "t": ("t", t, {"units": "1", "long_name": "time t, in units of tau"}),
        "snapshot_time": (
            "snapshot_time",
            snap_t,
            {"units": "1", "long_name": "time of the snapshot, in units of tau"},
        ),
        "x": ("x", x, {"units": "1", "long_name": "reference coordinate X1, in units of L"}),
        "y": ("y", x, {"units": "1", "long_name": "reference coordinate X2, in units of L"}),
    }
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)
