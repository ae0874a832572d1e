"""The run files of a batch: one Dataset per seed of
:func:`nematic_solids.model.accelerated.run.run_batch`, in the layout of
:func:`nematic_solids.model.simulate.run` (:mod:`nematic_solids.model.run_dataset`), so that a
campaign stores, aggregates and reads a batched seed like any run.

The device integrates; the host computes every save's observables from each seed's fields with
the functions :func:`nematic_solids.model.simulate.run` uses
(:func:`nematic_solids.model.simulate.observe_state` and
:func:`nematic_solids.model.simulate.snapshot_fields`: one implementation of each observable, the
small-strain displacement and stress solved on the host at every save). So a seed's file has every
series, snapshot and scalar of a compiled run's file, with values that agree to the backends'
tolerance (tested: 1e-10 relative, measured about 1e-14).

Work and time per seed: its own accepted and rejected steps, right-hand sides, spin iterations
and transforms on the device (``solver_*``, ``fft_count``) plus the host's transforms of its saves
(``fft_saves``); ``wall_time`` is the batch's time (compilation included) divided by its size,
and the attributes ``batch_size``, ``batch_seeds``, ``batch_wall_time``,
``batch_compile_time``, ``device`` and ``jax_version`` say how it ran (``run_backend``:
``accelerated``). A failed seed's file ends at its last save before the failure, with the
reason the device reports (:data:`nematic_solids.model.accelerated.etdrk4.REASONS`) and its
time.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from typing import Literal, overload

import numpy as np
import xarray as xr

from ..checkpoint import RunState, Schedule
from ..parameters import Numerics, Parameters
from ..pde import ActiveNematicPDE
from ..run_dataset import RunWork, to_dataset
from ..simulate import ends_non_finite, observe_state, snapshot_fields, snapshot_set
from ..solver_base import SolverState
from . import finite_step
from .etdrk4 import SeedState
from .run import run_batch

#: what made the files (their ``source`` and ``history`` attributes)
ENTRY = "nematic_solids.model.accelerated.datasets.batch_datasets"


@overload
def batch_datasets(
    params: Parameters,
    numerics: Numerics,
    seeds: Sequence[int],
    *,
    device: str = ...,
    initial: np.ndarray | None = ...,
    start: Sequence[RunState] | None = ...,
    checkpoint: Callable[[int, RunState], None] | None = ...,
    schedule: Schedule = ...,
    keep_state: Literal[False] = ...,
) -> list[xr.Dataset]: ...


@overload
def batch_datasets(
    params: Parameters,
    numerics: Numerics,
    seeds: Sequence[int],
    *,
    device: str = ...,
    initial: np.ndarray | None = ...,
    start: Sequence[RunState] | None = ...,
    checkpoint: Callable[[int, RunState], None] | None = ...,
    schedule: Schedule = ...,
    keep_state: Literal[True],
) -> list[tuple[xr.Dataset, RunState | None]]: ...


def batch_datasets(
    params: Parameters,
    numerics: Numerics,
    seeds: Sequence[int],
    *,
    device: str = "cpu",
    initial: np.ndarray | None = None,
    start: Sequence[RunState] | None = None,
    checkpoint: Callable[[int, RunState], None] | None = None,
    schedule: Schedule = Schedule(),
    keep_state: bool = False,
) -> list[xr.Dataset] | list[tuple[xr.Dataset, RunState | None]]:
    """Run the seeds ``seeds`` of one point together on ``device``
    (:func:`~nematic_solids.model.accelerated.run.run_batch`, whose
    checks and errors it shares) and return one Dataset per seed, in the order of ``seeds``
    (see the module docstring).

    As :func:`nematic_solids.model.simulate.run` does for one run: ``start`` continues the seeds
    from their states (one :class:`~nematic_solids.model.checkpoint.RunState` each, at one time;
    their rows, snapshots, counters and wall time carried on); ``checkpoint(b, state)`` is handed
    seed ``b``'s state at the saves ``schedule`` makes due (never at the end); with
    ``keep_state`` each item is ``(Dataset, end state)``, the state None for a failed seed."""
    seeds = tuple(seeds)
    eq = ActiveNematicPDE(params, numerics)  # the host's: the saves' mechanics and transforms
    snap_set = snapshot_set(numerics)
    rows: list[list[dict[str, float]]] = [[] for _ in seeds]
    snaps: list[list[tuple[float, np.ndarray]]] = [[] for _ in seeds]
    save_ffts = [0] * len(seeds)
    walls = [0.0] * len(seeds)
    origin = [""] * len(seeds)
    lineage: list[list[str]] = [[] for _ in seeds]
    t_start = 0.0
    if start is not None:
        for b, state in enumerate(start):
            rows[b] = [dict(r) for r in state.rows]
            snaps[b] = [s for s in state.snaps if float(np.round(s[0], 12)) in snap_set]
            save_ffts[b] = int(state.counters["fft_parts"].get("saves", 0))
            walls[b], origin[b], lineage[b] = state.wall, state.initial_from, list(state.lineage)
            t_start = state.t
    last = [[t_start, time.perf_counter()] for _ in seeds]  # of the last state handed out
    ends: list[RunState | None] = [None] * len(seeds)
    clock0 = time.perf_counter()

    finite = numerics.mechanics == "finite"

    def mechanics_of(b: int, state: SeedState) -> dict[str, np.ndarray]:
        """Seed ``b``'s mechanics as a state saves them
        (:meth:`nematic_solids.model.mechanics.FiniteMechanics.saved_state`; none in small
        strain)."""
        if not finite:
            return {}
        m = state.mech
        return {k: np.asarray(getattr(m, k)[b]).copy() for k in finite_step.SAVED}

    def capture(b: int, t: float, fields: np.ndarray, state: SeedState, share: float) -> RunState:
        def at(name: str) -> int:
            return int(np.asarray(getattr(state, name))[b])

        def mech_at(name: str) -> int:
            return int(np.asarray(getattr(state.mech, name))[b]) if finite else 0

        return RunState(
            t=float(t),
            fields=fields[b].copy(),
            solver=SolverState(
                float(np.asarray(state.h)[b]),
                np.asarray(state.q_hat[b]).copy(),
                {
                    "steps": at("steps"),
                    "rejected": at("rejected"),
                    "stage_failures": at("stage_failures"),
                    "rhs": at("rhs"),
                    "newton": mech_at("newton"),
                    "projections": at("steps") if finite else 0,
                },
                float(np.asarray(state.margin_min)[b]),
            ),
            mechanics=mechanics_of(b, state),
            counters={
                "fft_count": at("transforms") + save_ffts[b],
                "fft_parts": {"saves": save_ffts[b]},
                "spin_iterations": at("spin_iterations"),
                "cg_iterations": mech_at("cg_iterations"),
            },
            rows=[dict(r) for r in rows[b]],
            snaps=list(snaps[b]),
            parameters=params.to_dict(),
            numerics=numerics.to_dict(),
            seed=int(seeds[b]),
            wall=walls[b] + share,
            lineage=list(lineage[b]),
            initial_from=origin[b],
        )

    def on_save(t: float, fields: np.ndarray, state: SeedState) -> None:
        codes, steps = np.asarray(state.status), np.asarray(state.steps)
        final = t >= numerics.t_final - 1e-9 * max(numerics.t_final, 1.0)
        share = (time.perf_counter() - clock0) / len(seeds)
        for b in range(len(fields)):
            if codes[b] != 0:  # failed before this save: its series ends at the last one
                continue
            count = eq.spectral.fft.count
            if finite:
                # the save's force balance starts from the seed's, already balanced; the
                # first save of a run solves from the homogeneous state, as the reference's
                u = np.asarray(state.mech.u_hat[b])
                eq.mechanics.u_hat = u if t > t_start else np.zeros_like(u)
            obs, mech = observe_state(eq, fields[b], t, steps=int(steps[b]))
            rows[b].append(obs)
            if float(np.round(t, 12)) in snap_set:
                snaps[b].append((t, snapshot_fields(eq, fields[b], mech)))
            save_ffts[b] += eq.spectral.fft.count - count
            if final and keep_state:
                ends[b] = capture(b, t, fields, state, share)
            elif not final and checkpoint is not None:
                now = time.perf_counter()
                if schedule.due(t - last[b][0], now - last[b][1]):
                    checkpoint(b, capture(b, t, fields, state, share))
                    last[b] = [t, time.perf_counter()]

    result = run_batch(
        params, numerics, seeds, device=device, initial=initial, start=start, on_save=on_save
    )
    share = (result.wall + result.compile) / len(seeds)
    extra = {
        "batch_size": len(seeds),
        "batch_seeds": json.dumps(list(seeds)),
        "batch_wall_time": result.wall,
        "batch_compile_time": result.compile,
        "device": result.device,
        "jax_version": result.jax_version,
    }
    out = []
    for b, seed in enumerate(seeds):
        w = {name: int(values[b]) for name, values in result.work.items()}
        work = RunWork(
            margin_min=float(result.margin_min[b]),
            stats={
                "steps": w["steps"],
                "rejected": w["rejected"],
                "stage_failures": w["stage_failures"],
                "rhs": w["rhs"],
                "newton": w.get("newton", 0),
                "projections": w["steps"] if finite else 0,
            },
            spin_iterations=w["spin_iterations"],
            cg_iterations=w.get("cg_iterations", 0),
            fft_count=w["transforms"] + save_ffts[b],
            fft_parts={"saves": save_ffts[b]},
            fft_backend=f"jax (XLA) on {result.device}",
            fft_plans="XLA",
            backend="accelerated",
            extra=extra,
        )
        status, reason, detail = result.status[b], result.reason[b], ""
        t_failed = float(result.t_failed[b]) if status == "failed" else math.nan
        if status == "failed":
            detail = f"{reason} at t = {t_failed:.6g} (the accelerated backend's reason)"
        elif ends_non_finite(rows[b]):
            status, reason, detail = "failed", "nan", "non-finite observables at the end"
        ds = to_dataset(
            rows[b],
            snaps[b],
            eq.spectral.x,
            params,
            numerics,
            int(seed),
            work,
            status=status,
            reason=reason,
            detail=detail,
            t_failed=t_failed,
            wall=walls[b] + share,
            entry=ENTRY,
        )
        ds.attrs["initial_from"] = origin[b]
        out.append(ds)
    if keep_state:
        return [(ds, ends[b] if ds.attrs["status"] == "ok" else None) for b, ds in enumerate(out)]
    return out
