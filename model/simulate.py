"""One simulation: ``run(params, numerics, seed) -> xarray.Dataset``, the one entry that
:mod:`nematic_solids.sweep` calls.

The Dataset (:mod:`nematic_solids.model.run_dataset`) is self-describing: time series of every
observable (dim ``t``), snapshots of the fields (dims ``snapshot_time, x, y``), per-run scalars
(values at ``t_final``, time and pattern size at the first peak of sigma2_S by the growth-peak rule
and by the paper's literal rule, the smallest well-posedness margin, wall time) and, as attributes,
every parameter (``param_<name>``), every numerics field (``num_<name>``), the seed, the code
version, the git commit and the status. A run that fails (J <= 0, no convergence, NaN, ...) does not
raise: it returns what it computed up to the failure with ``status = "failed"`` and the ``reason``.

A run continues exactly from a saved state of itself (``start``), hands out its state on a
schedule (``checkpoint``) and returns its end state (``keep_state``):
:mod:`nematic_solids.model.checkpoint`. A new run can begin from another run's fields (``initial``,
an :class:`nematic_solids.model.checkpoint.InitialState`) instead of the seeded texture.

Early stop (numerics ``steady_tol > 0``; off by default): the run ends at the first save time
where the observables are steady (:func:`steady`); it is ok, its series and snapshots end
there (the fields at that time are stored), the scalars ``stopped_early`` (1) and
``t_stopped`` say so, and the ``*_final`` scalars are the values at ``t_stopped``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from typing import Any, Literal, overload

import numpy as np
import xarray as xr
from pde.solvers import Controller
from pde.trackers.base import FinishedSimulation, TrackerBase

from . import tensors as T
from .checkpoint import CheckpointError, InitialState, RunState, Schedule
from .errors import ParameterError, SimulationFailure
from .initial import initial_fields
from .mechanics import MechanicalState
from .observables import snapshot_observables
from .parameters import FLOAT64_ONLY, Numerics, Parameters, check_compatible, save_times
from .pde import ActiveNematicPDE, make_state
from .run_dataset import LONG_NAMES, SCALARS, SCHEMA_VERSION, SERIES, UNITS, RunWork, to_dataset
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

__all__ = ["LONG_NAMES", "SCALARS", "SCHEMA_VERSION", "SERIES", "STEADY", "UNITS", "run", "steady"]

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


@overload
def run(
    params: Parameters,
    numerics: Numerics,
    seed: int,
    *,
    progress: Callable[[float], None] | None = ...,
    start: RunState | None = ...,
    initial: InitialState | None = ...,
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
    initial: InitialState | None = ...,
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
    initial: InitialState | None = None,
    checkpoint: Callable[[RunState], None] | None = None,
    schedule: Schedule = Schedule(),
    keep_state: bool = False,
) -> xr.Dataset | tuple[xr.Dataset, RunState | None]:
    """Simulate paper Eqs. (1)-(5) from the seeded initial condition, or continue the run
    from ``start`` (a :class:`nematic_solids.model.checkpoint.RunState` of this run, whose
    ``t_final`` may be shorter: the result equals the run that never stopped); see the module
    docstring.

    ``checkpoint`` is called with the run's state after the saves that ``schedule`` says are
    due (never at the end); ``keep_state`` returns ``(Dataset, end state)``, the end state
    (None for a failed run) being what a longer run continues from. ``initial`` begins the
    run at t = 0 from given fields (another run's:
    :class:`nematic_solids.model.checkpoint.InitialState`) instead of the seeded texture; the seed
    then changes nothing."""
    _check_inputs(params, numerics, seed, start, initial)
    wall0 = time.perf_counter()
    eq = ActiveNematicPDE(params, numerics)
    grid = eq.spectral
    solver = SCHEMES[numerics.scheme](eq)
    times = save_times(numerics)
    snap_set = snapshot_set(numerics)
    rows: list[dict[str, float]] = []
    snaps: list[tuple[float, np.ndarray]] = []
    stopped = math.nan  # the time the run ended early
    wall_before, t_start = 0.0, 0.0
    if initial is not None:
        state = make_state(*np.array(initial.fields, dtype=float))
        _initial_displacement(eq, initial)
    elif start is None:
        state = make_state(*initial_fields(params, numerics.resolution, seed))
    else:
        state = make_state(*np.array(start.fields, dtype=float))
        _resume(start, state.data, solver, eq)
        rows = [dict(r) for r in start.rows]
        wall_before, t_start, stopped = start.wall, start.t, start.stopped
        if math.isnan(stopped) and rows and rows[-1]["time"] == t_start and steady(rows, numerics):
            stopped = t_start  # a longer run may end where a shorter one reached its end
        # the state's snapshots this run keeps (an early end stores its fields)
        kept = snap_set | ({stopped} if math.isfinite(stopped) else set())
        snaps = [s for s in start.snaps if float(np.round(s[0], 12)) in kept]
    # a continued run's save times start after the state's (its save is in its rows)
    interrupts = [
        float(t) for t in times if start is None or t > t_start + 1e-12 * max(1.0, t_start)
    ]
    origin = initial.origin if initial is not None else start.initial_from if start else ""
    recorder = RunRecorder(
        eq,
        solver,
        params,
        numerics,
        seed,
        rows=rows,
        snaps=snaps,
        stopped=stopped,
        checkpoint=checkpoint,
        schedule=schedule,
        keep_state=keep_state,
        lineage=[] if start is None else list(start.lineage),
        origin=origin,
        clock=(t_start, wall0, wall_before),
        interrupts=interrupts,
    )

    if progress is not None:
        solver.on_step = lambda t, h: progress(min(t / numerics.t_final, 1.0))
    status, reason, detail, t_failed = "ok", "", "", float("nan")
    controller = Controller(solver, t_range=(t_start, numerics.t_final), tracker=[recorder])
    try:
        if math.isnan(recorder.stopped) and interrupts:
            controller.run(state, numerics.dt)
        elif keep_state and start is not None:  # nothing left to integrate: the state is the end
            recorder.end = dataclasses.replace(
                start, numerics=numerics.to_dict(), snaps=list(snaps), stopped=recorder.stopped
            )
    except SimulationFailure as exc:
        status, reason, detail = "failed", exc.reason, exc.detail
        t_failed = float(exc.t) if exc.t is not None else float("nan")
        log.info("run failed: %s", exc)
    if status == "ok" and ends_non_finite(rows):
        status, reason, detail = "failed", "nan", "non-finite observables at the end"
    wall = wall_before + time.perf_counter() - wall0
    ds = to_dataset(
        rows,
        snaps,
        grid.x,
        params,
        numerics,
        seed,
        RunWork.of_solver(solver),
        status=status,
        reason=reason,
        detail=detail,
        t_failed=t_failed,
        wall=wall,
        t_stopped=recorder.stopped,
    )
    ds.attrs["initial_from"] = origin
    if not keep_state:
        return ds
    return ds, recorder.end if status == "ok" else None


def _check_inputs(
    params: Parameters,
    numerics: Numerics,
    seed: int,
    start: RunState | None,
    initial: InitialState | None,
) -> None:
    """Refuse what a run cannot start from: incompatible settings, another precision than
    float64, a seed that is not an integer >= 0, initial fields of another shape (or with a
    state), a state of another run."""
    check_compatible(params, numerics)
    if numerics.precision != "float64":
        raise ParameterError("precision", numerics.precision, FLOAT64_ONLY)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError("seed", seed, "an integer >= 0")
    n = numerics.resolution
    if initial is not None and (start is not None or np.shape(initial.fields) != (3, n, n)):
        raise ParameterError(
            "initial", initial.origin or "fields", f"fields of shape (3, {n}, {n}), without start"
        )
    if start is not None and (why := start.problem(params, numerics, seed)) is not None:
        raise CheckpointError(f"the state at t = {start.t:g} does not continue this run: {why}")


def _initial_displacement(eq: ActiveNematicPDE, initial: InitialState) -> None:
    """Finite strain from given fields: the displacement they come with, as Newton's first
    guess (the exact end state's spectrum) or at t = 0 (a snapshot's)."""
    if eq.numerics.mechanics == "linear":
        return
    if initial.displacement_hat is not None:
        eq.mechanics.u_hat = np.array(initial.displacement_hat, dtype=complex)
    elif initial.displacement is not None:
        eq.mechanics.u_hat = eq.spectral.forward(np.asarray(initial.displacement, dtype=float))


class RunRecorder(TrackerBase):
    """The run state of one simulation, as a py-pde tracker: at each save time it records the
    observables (a row of the series), the snapshot where one is due, the early stop, the
    checkpoint that ``schedule`` says is due (never at the end) and, with ``keep_state``, the
    end state a longer run continues from (:attr:`end`). ``clock`` is the run's start
    ``(t, wall clock, wall seconds of the run it continues)``; ``interrupts`` its save times
    (a continued run's after its state's)."""

    def __init__(
        self,
        eq: ActiveNematicPDE,
        solver: ETDSolver,
        params: Parameters,
        numerics: Numerics,
        seed: int,
        *,
        rows: list[dict[str, float]],
        snaps: list[tuple[float, np.ndarray]],
        stopped: float,
        checkpoint: Callable[[RunState], None] | None,
        schedule: Schedule,
        keep_state: bool,
        lineage: list[str],
        origin: str,
        clock: tuple[float, float, float],
        interrupts: list[float],
    ):
        super().__init__(interrupts=interrupts)
        self.eq, self.solver, self.params, self.numerics = eq, solver, params, numerics
        self.seed = int(seed)
        self.rows, self.snaps, self.stopped = rows, snaps, stopped
        self.checkpoint, self.schedule, self.keep_state = checkpoint, schedule, keep_state
        self.lineage, self.origin = lineage, origin
        self.snap_set = snapshot_set(numerics)
        #: the time and wall clock of the last state handed out (the run's start at first)
        self.last_t, self.last_wall, self.wall_before = clock
        self.wall0 = clock[1]
        #: the end state (with ``keep_state``, once the run ended well)
        self.end: RunState | None = None

    def capture(self, st: Any, t: float, stop: bool) -> RunState:
        """The run's state at ``t`` (``stop``: it ends early there)."""
        return RunState(
            t=float(t),
            fields=st.data.copy(),
            solver=self.solver.saved_state(st.data),
            mechanics=self.eq.mechanics.saved_state(),
            counters=_counters(self.eq),
            rows=[dict(r) for r in self.rows],
            snaps=list(self.snaps),
            parameters=self.params.to_dict(),
            numerics=self.numerics.to_dict(),
            seed=self.seed,
            stopped=float(t) if stop else math.nan,
            wall=self.wall_before + time.perf_counter() - self.wall0,
            lineage=list(self.lineage),
            initial_from=self.origin,
        )

    def handle(self, field: Any, t: float) -> None:
        """One save time: its row, its snapshot, the early stop, a checkpoint or the end."""
        d, numerics = field.data, self.numerics
        obs, mech = observe_state(self.eq, d, t, steps=self.solver.stats["steps"])
        self.rows.append(obs)
        stop = steady(self.rows, numerics)
        if stop or float(np.round(t, 12)) in self.snap_set:  # an early end stores its fields
            self.snaps.append((float(t), snapshot_fields(self.eq, d, mech)))
        final = stop or t >= numerics.t_final - 1e-9 * max(numerics.t_final, 1.0)
        if final and self.keep_state:
            self.end = self.capture(field, t, stop)
        elif not final and self.checkpoint is not None:
            now = time.perf_counter()
            if self.schedule.due(t - self.last_t, now - self.last_wall):
                self.checkpoint(self.capture(field, t, stop))
                self.last_t, self.last_wall = t, time.perf_counter()
        if stop:
            self.stopped = float(t)
            raise FinishedSimulation("steady")


def snapshot_set(numerics: Numerics) -> set[float]:
    """The times (rounded to 12 decimals) whose fields a run stores: ``snapshot_times`` and
    ``t_final``."""
    return {float(t) for t in np.round(list(numerics.snapshot_times) + [numerics.t_final], 12)}


def ends_non_finite(rows: list[dict[str, float]]) -> bool:
    """Whether the last save's mean_S, sigma2_S or min_J is not finite (an ok run that ends so
    is failed with reason ``nan``)."""
    return bool(rows) and not all(np.isfinite(rows[-1][k]) for k in ("mean_S", "sigma2_S", "min_J"))


def observe_state(
    eq: ActiveNematicPDE, d: np.ndarray, t: float, *, steps: int
) -> tuple[dict[str, float], MechanicalState]:
    """One save of a run: the observables of the fields ``d`` (q1, q2, A) at time ``t``
    (:func:`nematic_solids.model.observables.snapshot_observables`, with the mechanics solved
    at them and the rate problem's well-posedness margin) as a row of the run's series, with
    ``time`` and the accepted ``steps`` so far; and the mechanical state. Every transform of a
    save counts as the save's (``fft_parts["saves"]``: the parts are disjoint)."""
    grid, linear = eq.spectral, eq.numerics.mechanics == "linear"
    parts, count = dict(eq.mechanics.fft_parts), grid.fft.count
    eq.at_time(t)  # a save sees a protocol's value after a switch at its time
    mech = eq.mechanics.solve(d[0], d[1], t=t)
    residual = mech.residual if not linear else eq.mechanics.residual(mech.P)
    obs = snapshot_observables(
        d[0], d[1], d[2], mech.F, residual, eq.params, grid, linear=linear, P=mech.P
    )
    obs["rate_margin"] = eq.mechanics.rate_margin(d[0], d[1], mech)[0]
    obs["time"] = float(t)
    obs["steps"] = float(steps)
    eq.mechanics.fft_parts.update(parts)
    eq.mechanics.fft_parts["saves"] += grid.fft.count - count
    return obs, mech


def snapshot_fields(eq: ActiveNematicPDE, d: np.ndarray, mech: MechanicalState) -> np.ndarray:
    """The snapshot of the fields ``d`` (q1, q2, A) with the mechanical state ``mech``:
    :data:`nematic_solids.model.checkpoint.SNAPSHOT_FIELDS` (q1, q2, A, u1, u2, I1bar)."""
    count = eq.spectral.fft.count
    u = eq.spectral.inverse(mech.u_hat)
    eq.mechanics.fft_parts["saves"] += eq.spectral.fft.count - count
    C = T.matmul(T.transpose(mech.F), mech.F)
    I1bar = T.trace(C) / T.det(mech.F)
    return np.stack([d[0], d[1], d[2], u[0], u[1], I1bar])


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
    eq.at_time(start.t)  # the constants the state was saved under (nematic_solids.model.protocol)
    eq.mechanics.resume(start.mechanics, u[0], u[1])
    c = start.counters
    eq.spectral.fft.count = int(c["fft_count"])
    eq.mechanics.fft_parts.update({k: int(v) for k, v in c["fft_parts"].items()})
    eq.mechanics.spin_iterations = int(c["spin_iterations"])
    eq.mechanics.cg_iterations = int(c["cg_iterations"])
