"""The seeds of one point in one accelerated run: :func:`run_batch` (small-strain or
finite-strain mechanics, ETDRK4), from each seed's initial texture
(:func:`nematic_solids.model.initial.initial_fields`, as
:func:`nematic_solids.model.simulate.run`) to ``t_final``, with the observables at the save times of
:func:`nematic_solids.model.parameters.save_times`.

Each seed has its own step control (:mod:`nematic_solids.model.accelerated.etdrk4`), so seed i of a
batch follows the trajectory it has when run alone; one seed's failure (its reason tag as in
:mod:`nematic_solids.model.errors`) stops that seed only. Compiled executables are kept per
(constants, control, batch size, device), so a second run of the same shape compiles nothing.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..accelerated_support import check_supported
from ..checkpoint import CheckpointError, RunState
from ..errors import ParameterError
from ..initial import initial_fields
from ..parameters import Numerics, Parameters, check_compatible, save_times
from . import finite, finite_step
from .device import describe, select_device
from .dtypes import complex_dtype, real_dtype
from .etdrk4 import REASONS, Control, SeedState, advance, initial_state
from .linear_rhs import Constants, setup, symbols_on
from .observables import NAMES, ShellData, observe, shell_data

#: the name of the seeds' axis under jax.vmap
SEEDS = "seeds"
#: the work counted per seed (:class:`nematic_solids.model.accelerated.etdrk4.SeedState`)
WORK = ("steps", "rejected", "stage_failures", "rhs", "spin_iterations", "transforms")


@dataclass
class BatchResult:
    """What :func:`run_batch` returns. ``series[name]`` is (B, T) over ``times`` (NaN at the
    saves after a seed failed), ``fields`` the (B, 3, N, N) fields q1, q2, A at the end (or
    where the seed failed), ``status`` "ok" or "failed" per seed with its ``reason`` and
    ``t_failed``, ``work[name]`` the counters of :data:`WORK` per seed, ``margin_min`` the
    smallest well-posedness margin per seed; ``wall`` and ``cpu`` the seconds of the run
    (wall clock, and CPU of this process's threads) without ``compile``, the seconds of the
    first calls, which compile (a few milliseconds when JAX has the code already)."""

    seeds: tuple[int, ...]
    times: np.ndarray
    series: dict[str, np.ndarray]
    fields: np.ndarray
    status: list[str]
    reason: list[str]
    t_failed: np.ndarray
    work: dict[str, np.ndarray]
    margin_min: np.ndarray
    device: str
    wall: float
    cpu: float
    compile: float
    jax_version: str


def _work(state: SeedState) -> dict[str, np.ndarray]:
    """The work counted per seed: :data:`WORK`, and finite strain's Newton iterations of the
    projections (``newton``) and CG iterations of every force balance (``cg_iterations``)."""
    work = {name: np.asarray(getattr(state, name)) for name in WORK}
    if isinstance(state.mech, finite_step.Mechanics):
        work["newton"] = np.asarray(state.mech.newton)
        work["cg_iterations"] = np.asarray(state.mech.cg_iterations)
    return work


def _check_start(
    start: Sequence[RunState], params: Parameters, numerics: Numerics, seeds: tuple[int, ...]
) -> float:
    """The one time of the states ``start``, each of which must continue its seed's run;
    else :class:`nematic_solids.model.checkpoint.CheckpointError` or a ``ParameterError``."""
    if len(start) != len(seeds):
        raise ParameterError("start", len(start), f"one state per seed ({len(seeds)})")
    for state, seed in zip(start, seeds, strict=True):
        why = state.problem(params, numerics, seed)
        if why is not None:
            raise CheckpointError(f"the state at t = {state.t:g} does not continue this run: {why}")
    t = {float(state.t) for state in start}
    if len(t) != 1:
        raise ParameterError("start", sorted(t), "states at one time")
    return t.pop()


def _resumed(
    start: Sequence[RunState], dev: jax.Device, precision: str, fin: tuple | None = None
) -> SeedState:
    """The batch's device state from the seeds' saved states (the spectra transformed anew
    where a state has none: a state saved before its run's first step), the fields in the
    run's ``precision``; with finite strain's ``fin`` = (symbols on the device, constants)
    their mechanics too (:func:`nematic_solids.model.accelerated.finite_step.resumed_mechanics`)."""
    real, cplx = real_dtype(precision), complex_dtype(precision)

    def one(state: RunState) -> tuple:
        q = np.asarray(state.fields[:2], dtype=np.float64)
        q_hat = state.solver.q_hat if state.solver.q_hat is not None else np.fft.rfft2(q)
        stats, c = state.solver.stats, state.counters
        on_host = int(c["fft_parts"].get("saves", 0))
        return (
            q,
            np.asarray(q_hat, dtype=np.complex128),
            np.asarray(state.fields[2], dtype=np.float64),
            state.t,
            state.solver.h,
            0,
            np.nan,
            state.solver.margin_min,
            stats["steps"],
            stats["rejected"],
            stats["stage_failures"],
            stats["rhs"],
            c["spin_iterations"],
            int(c["fft_count"]) - on_host,
        )

    rows = [one(state) for state in start]
    types = [real, cplx, real, np.float64, np.float64, np.int32]
    types += [np.float64, np.float64] + [np.int32] * 6
    columns: list[np.ndarray] = [
        np.stack([np.asarray(r[k], dtype=t) for r in rows]) for k, t in enumerate(types)
    ]
    state = SeedState(*(jax.device_put(a, dev) for a in columns))
    if fin is None:
        return state
    sym, c = fin
    saved = [
        jax.device_put(
            np.stack([np.asarray(st.mechanics[k]) for st in start]).astype(
                cplx if k.endswith("_hat") else real
            ),
            dev,
        )
        for k in finite_step.SAVED
    ]
    mech = jax.jit(
        jax.vmap(finite_step.resumed_mechanics, in_axes=(0, 0, 0, 0, None, None)),
        static_argnums=5,
    )(*saved, state.q, sym, c)
    cg = np.array([int(st.counters["cg_iterations"]) for st in start], dtype=np.int32)
    newton = np.array([int(st.solver.stats["newton"]) for st in start], dtype=np.int32)
    return state._replace(
        mech=mech._replace(
            newton=jax.device_put(newton, dev), cg_iterations=jax.device_put(cg, dev)
        )
    )


@functools.lru_cache(maxsize=8)
def _jitted(c: Constants | finite.FiniteConstants, ctl: Control, nshell: int, dt: float):
    """The batched, jitted functions of a run (kept per constants, so that JAX's cache of
    compiled code serves the next run of the same shape): the initial state ``(q, A,
    symbols)``, the advance to a time, the observables ``(state, shells)``."""
    if isinstance(c, Constants):
        start = jax.jit(
            jax.vmap(lambda q, A, sym: initial_state(q, A, dt=dt), in_axes=(0, 0, None))
        )
        stepper = advance
    else:
        start = jax.jit(
            jax.vmap(
                functools.partial(finite_step.initial_finite_state, c=c, dt=dt),
                in_axes=(0, 0, None),
            )
        )
        stepper = functools.partial(advance, step=finite_step.finite_step)
    c = dataclasses.replace(c, batch_axis=SEEDS)
    step = jax.jit(
        jax.vmap(functools.partial(stepper, c=c, ctl=ctl), in_axes=(0, None, None), axis_name=SEEDS)
    )
    amb = c.amb if isinstance(c, Constants) else c.alpha - c.B

    def observables(state: SeedState, shells: ShellData) -> jax.Array:
        values = observe(state.q, state.A, shells, nshell=nshell, alpha_minus_B=amb)
        if isinstance(c, Constants):
            return values
        # finite strain's margin: at the state's force balance (the tangent and E there)
        margin = finite_step.save_margin(state.q, state.mech, c)
        return values.at[-1].set(margin.astype(jnp.float64))

    look = jax.jit(jax.vmap(observables, in_axes=(0, None)))
    return start, step, look


def run_batch(
    params: Parameters,
    numerics: Numerics,
    seeds: Sequence[int],
    *,
    device: str = "cpu",
    initial: np.ndarray | None = None,
    start: Sequence[RunState] | None = None,
    on_save: Callable[[float, np.ndarray, SeedState], None] | None = None,
) -> BatchResult:
    """Run the seeds ``seeds`` of the point (``params``, ``numerics``) together on ``device``
    ("cpu", "gpu", "auto": :func:`nematic_solids.model.accelerated.device.select_device`), from
    their seeded textures or from the given fields ``initial`` (B, 3, N, N) (q1, q2, A per seed, as
    :func:`nematic_solids.model.simulate.run`'s ``initial``); see the module docstring.

    ``start``: one :class:`nematic_solids.model.checkpoint.RunState` per seed, all at one time
    t (a rolling checkpoint or a shorter run's end, of this backend or the compiled one): the
    seeds continue from their fields, spectra, next step size, counters and smallest margin, and
    ``times`` and ``series`` hold the saves after t only. From a state of this backend, a batch
    of the same seeds continues exactly as the batch that never stopped (tested bitwise).

    ``on_save(t, fields, state)`` is called at every save time with the seeds' fields
    (B, 3, N, N) copied to the host and their
    :class:`~nematic_solids.model.accelerated.etdrk4.SeedState` on the device (status codes,
    steps, step size: the host computes what the device does not and takes states:
    :func:`nematic_solids.model.accelerated.datasets.batch_datasets`); its time counts in
    ``wall``."""
    check_compatible(params, numerics)
    check_supported(params, numerics)
    seeds = tuple(seeds)
    if not seeds or any(
        isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds
    ):
        raise ParameterError("seeds", seeds, "one or more integers >= 0")
    dev = select_device(device)
    n = numerics.resolution
    linear = numerics.mechanics == "linear"
    symbols: Any
    c: Constants | finite.FiniteConstants
    symbols, c = setup(params, numerics) if linear else finite.setup(params, numerics)
    ctl = Control(numerics.tolerance, numerics.dt_max, numerics.adaptive, numerics.error_norm)
    shells, nshell = shell_data(n)
    begin, step, look = _jitted(c, ctl, nshell, float(numerics.dt))
    if start is not None and initial is not None:
        raise ParameterError("initial", "fields", "none with start (states)")
    if initial is None:
        fields0 = np.stack([np.stack(initial_fields(params, n, int(s))) for s in seeds])
    else:
        fields0 = np.asarray(initial, dtype=np.float64)
        if fields0.shape != (len(seeds), 3, n, n):
            raise ParameterError(
                "initial", fields0.shape, f"fields of shape ({len(seeds)}, 3, {n}, {n})"
            )
    precision = numerics.precision
    sym = (
        symbols_on(symbols, dev, precision)
        if linear
        else finite.symbols_on(symbols, dev, precision)
    )
    shell_dev = ShellData(*(jax.device_put(a, dev) for a in shells))
    times = save_times(numerics)
    if start is not None:
        t_start = _check_start(start, params, numerics, seeds)
        times = times[times > t_start + 1e-12 * max(1.0, t_start)]

    # the first calls compile (XLA, for this device and batch size; nothing when JAX has the
    # code already): an advance to t = 0 takes no step
    t0 = time.perf_counter()
    fields0 = fields0.astype(real_dtype(precision))
    q0, A0 = jax.device_put(fields0[:, :2], dev), jax.device_put(fields0[:, 2], dev)
    if start is None:
        state: SeedState = begin(q0, A0, sym)
    else:
        state = _resumed(start, dev, precision, None if linear else (sym, c))
    state = step(state, jax.device_put(jnp.float64(0.0), dev), sym)
    jax.block_until_ready(look(state, shell_dev))
    compile_s = time.perf_counter() - t0

    t1, cpu1 = time.perf_counter(), time.process_time()
    rows = []
    for t_save in times:
        if t_save > 0.0:
            state = step(state, jax.device_put(jnp.float64(t_save), dev), sym)
        values = np.array(look(state, shell_dev))
        codes = np.asarray(state.status)
        values[codes != 0] = np.nan
        rows.append(values)
        if on_save is not None:
            host = np.concatenate([np.asarray(state.q), np.asarray(state.A)[:, None]], axis=1)
            host = host.astype(np.float64)  # (exact from float32)
            on_save(float(t_save), host, state)
    jax.block_until_ready(state)
    wall, cpu = time.perf_counter() - t1, time.process_time() - cpu1

    status = np.asarray(state.status)
    series = np.stack(rows, axis=-1)  # (B, names, T)
    fields = np.concatenate([np.asarray(state.q), np.asarray(state.A)[:, None]], axis=1)
    fields = fields.astype(np.float64)
    return BatchResult(
        seeds=seeds,
        times=times,
        series={name: series[:, i] for i, name in enumerate(NAMES)},
        fields=fields,
        status=["ok" if s == 0 else "failed" for s in status],
        reason=[REASONS[int(s)] for s in status],
        t_failed=np.asarray(state.t_failed),
        work=_work(state),
        margin_min=np.asarray(state.margin_min),
        device=describe(dev),
        wall=wall,
        cpu=cpu,
        compile=compile_s,
        jax_version=jax.__version__,
    )
