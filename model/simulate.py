"""One simulation: ``run(params, numerics, seed) -> xarray.Dataset``, the one entry that
:mod:`sweep` calls.

The Dataset is self-describing: time series of every observable (dim ``t``), snapshots of
the fields (dims ``snapshot_time, x, y``), per-run scalars (values at ``t_final``, time and
pattern size at the first peak of sigma2_S by the growth-peak rule and by the paper's
literal rule, the smallest well-posedness margin, wall time) and, as attributes, every parameter
(``param_<name>``), every numerics field (``num_<name>``), the seed, the code version, the git
commit and the status. A run that fails (J <= 0, no convergence, NaN, ...) does not raise: it
returns what it computed up to the failure with ``status = "failed"`` and the ``reason``.

Early stop (numerics ``steady_tol > 0``; off by default): the run ends at the first save time
where the observables are steady (:func:`steady`); it is ok, its series and snapshots end
there (the fields at that time are stored), the scalars ``stopped_early`` (1) and
``t_stopped`` say so, and the ``*_final`` scalars are the values at ``t_stopped``.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import math
import time
from collections.abc import Callable
from typing import Any, Literal, overload

import numpy as np
import xarray as xr
from pde.solvers import Controller
from pde.trackers import CallbackTracker
from pde.trackers.base import FinishedSimulation

from . import __version__
from . import tensors as T
from .checkpoint import SNAPSHOT_FIELDS, CheckpointError, RunState, Schedule
from .errors import ParameterError, SimulationFailure
from .initial import initial_fields
from .observables import first_peak, growth_peak, snapshot_observables
from .parameters import Numerics, Parameters, check_compatible, save_times
from .pde import ActiveNematicPDE, make_state
from .provenance import git_commit, library_versions_text
from .solver import SCHEMES, ETDSolver

log = logging.getLogger(__name__)


class _TrackerTimeIsExpected(logging.Filter):
    """py-pde warns "Spent more time on handling trackers ... than on the actual simulation"
    when its trackers take longer than the solver. Here the tracker computes the observables
    (a force-balance solve per save), so that is expected, not a problem: the message is
    demoted to DEBUG (shown only with debug logging)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if str(record.msg).startswith("Spent more time on handling trackers"):
            record.levelno, record.levelname = logging.DEBUG, "DEBUG"
            return logging.getLogger(record.name).isEnabledFor(logging.DEBUG)
        return True


logging.getLogger("pde.solvers.controller").addFilter(_TrackerTimeIsExpected())

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
#: Observables whose steadiness ends a run early (numerics steady_tol > 0).
STEADY = ("sigma2_S", "mean_S")


def steady(rows: list[dict[str, float]], numerics: Numerics) -> bool:
    """Whether the run may end at the last saved row: early stop is on, the row is before
    t_final and every :data:`STEADY` observable changed by at most ``steady_tol`` of the
    larger of its two values since the last saved row at least ``steady_window`` earlier."""
    tol, window = numerics.steady_tol, numerics.steady_window
    if tol <= 0 or not rows:
        return False
    now = rows[-1]
    t = now["time"]
    if t >= numerics.t_final - 1e-9 * numerics.t_final or t < window - 1e-9:
        return False
    before = [r for r in rows if r["time"] <= t - window + 1e-9 * max(window, 1.0)]
    if not before:
        return False
    then = before[-1]
    for name in STEADY:
        a, b = then[name], now[name]
        if not (math.isfinite(a) and math.isfinite(b)) or abs(b - a) > tol * max(abs(a), abs(b)):
            return False
    return True


def _attr(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (list, tuple)):
        return json.dumps(list(value))
    return value


@overload
def run(
    params: Parameters,
    numerics: Numerics,
    seed: int,
    *,
    progress: Callable[[float], None] | None = ...,
    start: RunState | None = ...,
    checkpoint: Callable[[RunState], None] | None = ...,
    schedule: Schedule = ...,
    keep_state: Literal[False] = ...,
) -> xr.Dataset: ...


@overload
def run(
    params: Parameters,
    numerics: Numerics,
    seed: int,
    *,
    progress: Callable[[float], None] | None = ...,
    start: RunState | None = ...,
    checkpoint: Callable[[RunState], None] | None = ...,
    schedule: Schedule = ...,
    keep_state: Literal[True],
) -> tuple[xr.Dataset, RunState | None]: ...


def run(
    params: Parameters,
    numerics: Numerics,
    seed: int,
    *,
    progress: Callable[[float], None] | None = None,
    start: RunState | None = None,
    checkpoint: Callable[[RunState], None] | None = None,
    schedule: Schedule = Schedule(),
    keep_state: bool = False,
) -> xr.Dataset | tuple[xr.Dataset, RunState | None]:
    """Simulate paper Eqs. (1)-(5) from the seeded initial condition, or continue the run
    from ``start`` (a :class:`model.checkpoint.RunState` of this run, whose ``t_final`` may be
    shorter: the result equals the run that never stopped); see the module docstring.

    ``checkpoint`` is called with the run's state after the saves that ``schedule`` says are
    due (never at the end); ``keep_state`` returns ``(Dataset, end state)``, the end state
    (None for a failed run) being what a longer run continues from."""
    check_compatible(params, numerics)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError("seed", seed, "an integer >= 0")
    if start is not None and (why := start.problem(params, numerics, seed)) is not None:
        raise CheckpointError(f"the state at t = {start.t:g} does not continue this run: {why}")
    wall0 = time.perf_counter()
    eq = ActiveNematicPDE(params, numerics)
    grid = eq.spectral
    linear = numerics.mechanics == "linear"
    solver = SCHEMES[numerics.scheme](eq)
    times = save_times(numerics)
    snap_set = {float(t) for t in np.round(list(numerics.snapshot_times) + [numerics.t_final], 12)}
    rows: list[dict[str, float]] = []
    snaps: list[tuple[float, np.ndarray]] = []
    stopped = [math.nan]  # the time the run ended early
    wall_before, t_start = 0.0, 0.0
    if start is None:
        state = make_state(*initial_fields(params, numerics.resolution, seed))
    else:
        state = make_state(*np.array(start.fields, dtype=float))
        _resume(start, state.data, solver, eq)
        rows = [dict(r) for r in start.rows]
        snaps = [s for s in start.snaps if float(np.round(s[0], 12)) in snap_set]
        wall_before, t_start, stopped[0] = start.wall, start.t, start.stopped
        if (
            math.isnan(stopped[0])
            and rows
            and rows[-1]["time"] == t_start
            and steady(rows, numerics)
        ):
            stopped[0] = t_start  # a longer run may end where a shorter one reached its end
        if math.isfinite(stopped[0]):
            snaps = [s for s in start.snaps if float(np.round(s[0], 12)) in snap_set | {stopped[0]}]
    last = [t_start, wall0]  # the time and wall clock of the last state handed out
    end: list[RunState | None] = [None]

    def capture(st, t: float, stop: bool) -> RunState:
        return RunState(
            t=float(t),
            fields=st.data.copy(),
            solver=solver.saved_state(st.data),
            mechanics=eq.mechanics.saved_state(),
            counters=_counters(eq),
            rows=[dict(r) for r in rows],
            snaps=list(snaps),
            parameters=params.to_dict(),
            numerics=numerics.to_dict(),
            seed=int(seed),
            stopped=float(t) if stop else math.nan,
            wall=wall_before + time.perf_counter() - wall0,
            lineage=[] if start is None else list(start.lineage),
        )

    def record(st, t: float) -> None:
        d = st.data
        parts, count = dict(eq.mechanics.fft_parts), grid.fft.count
        mech = eq.mechanics.solve(d[0], d[1], t=t)
        residual = mech.residual if not linear else eq.mechanics.residual(mech.P)
        obs = snapshot_observables(d[0], d[1], d[2], mech.F, residual, params, grid, linear=linear)
        obs["rate_margin"] = eq.mechanics.rate_margin(d[0], d[1], mech)[0]
        obs["time"] = float(t)
        obs["steps"] = float(solver.stats["steps"])
        rows.append(obs)
        stop = steady(rows, numerics)
        if stop or float(np.round(t, 12)) in snap_set:  # an early end stores its fields
            u = grid.inverse(mech.u_hat)
            C = T.matmul(T.transpose(mech.F), mech.F)
            I1bar = T.trace(C) / T.det(mech.F)
            snaps.append((float(t), np.stack([d[0], d[1], d[2], u[0], u[1], I1bar])))
        # every transform of a save counts as the save's (the parts are disjoint)
        eq.mechanics.fft_parts.update(parts)
        eq.mechanics.fft_parts["saves"] += grid.fft.count - count
        final = stop or t >= numerics.t_final - 1e-9 * max(numerics.t_final, 1.0)
        if final and keep_state:
            end[0] = capture(st, t, stop)
        elif not final and checkpoint is not None:
            now = time.perf_counter()
            if schedule.due(t - last[0], now - last[1]):
                checkpoint(capture(st, t, stop))
                last[:] = [t, time.perf_counter()]
        if stop:
            stopped[0] = float(t)
            raise FinishedSimulation("steady")

    if progress is not None:
        solver.on_step = lambda t, h: progress(min(t / numerics.t_final, 1.0))
    status, reason, detail, t_failed = "ok", "", "", float("nan")
    # a continued run's save times start after the state's (its save is in its rows)
    interrupts = [
        float(t) for t in times if start is None or t > t_start + 1e-12 * max(1.0, t_start)
    ]
    tracker = CallbackTracker(record, interrupts=interrupts)
    controller = Controller(solver, t_range=(t_start, numerics.t_final), tracker=[tracker])
    try:
        if math.isnan(stopped[0]) and interrupts:
            controller.run(state, numerics.dt)
        elif keep_state:
            end[0] = start
    except SimulationFailure as exc:
        status, reason, detail = "failed", exc.reason, exc.detail
        t_failed = float(exc.t) if exc.t is not None else float("nan")
        log.info("run failed: %s", exc)
    if (
        status == "ok"
        and rows
        and not all(np.isfinite(rows[-1][k]) for k in ("mean_S", "sigma2_S", "min_J"))
    ):
        status, reason, detail = "failed", "nan", "non-finite observables at the end"
    wall = wall_before + time.perf_counter() - wall0
    ds = _to_dataset(
        rows,
        snaps,
        grid.x,
        params,
        numerics,
        seed,
        solver,
        status=status,
        reason=reason,
        detail=detail,
        t_failed=t_failed,
        wall=wall,
        t_stopped=stopped[0],
    )
    if not keep_state:
        return ds
    return ds, end[0] if status == "ok" else None


def _counters(eq: ActiveNematicPDE) -> dict[str, Any]:
    """The work a run has counted: transforms (in all and by part), spin and CG iterations."""
    m = eq.mechanics
    return {
        "fft_count": int(eq.spectral.fft.count),
        "fft_parts": {k: int(v) for k, v in m.fft_parts.items()},
        "spin_iterations": int(m.spin_iterations),
        "cg_iterations": int(m.cg_iterations),
    }


def _resume(start: RunState, u: np.ndarray, solver: ETDSolver, eq: ActiveNematicPDE) -> None:
    """Put the solver and the mechanics in the state ``start`` holds (``u``: its fields)."""
    solver.resume(start.solver, u)
    eq.mechanics.resume(start.mechanics, u[0], u[1])
    c = start.counters
    eq.spectral.fft.count = int(c["fft_count"])
    eq.mechanics.fft_parts.update({k: int(v) for k, v in c["fft_parts"].items()})
    eq.mechanics.spin_iterations = int(c["spin_iterations"])
    eq.mechanics.cg_iterations = int(c["cg_iterations"])


def _to_dataset(
    rows,
    snaps,
    x,
    params: Parameters,
    numerics: Numerics,
    seed: int,
    solver: ETDSolver,
    *,
    status: str,
    reason: str,
    detail: str,
    t_failed: float,
    wall: float,
    t_stopped: float = math.nan,
) -> xr.Dataset:
    t = np.array([r["time"] for r in rows], dtype=float)
    data_vars: dict[str, Any] = {}
    for name in (*SERIES, "steps"):
        data_vars[name] = (
            "t",
            np.array([r[name] for r in rows], dtype=float),
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
    margin = min(
        solver.margin_min, float(np.nanmin(rates)) if np.any(np.isfinite(rates)) else np.inf
    )
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
        "source": f"active-nematic-solids {__version__} model.simulate.run",
        "history": f"{created}: simulated by model.simulate.run (seed {int(seed)})",
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
        "fft_backend": solver.pde.spectral.fft.backend,
        "fft_plans": solver.pde.spectral.fft.plan_source,
        **{f"solver_{k}": int(v) for k, v in solver.stats.items()},
        "solver_spin_iterations": int(solver.pde.mechanics.spin_iterations),
        "solver_cg_iterations": int(solver.pde.mechanics.cg_iterations),
        "fft_count": int(solver.pde.spectral.fft.count),
        **{f"fft_{k}": int(v) for k, v in solver.pde.mechanics.fft_parts.items()},
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
