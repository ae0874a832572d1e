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
from collections.abc import Sequence

import numpy as np
import xarray as xr

from ..parameters import Numerics, Parameters
from ..pde import ActiveNematicPDE
from ..run_dataset import RunWork, to_dataset
from ..simulate import ends_non_finite, observe_state, snapshot_fields, snapshot_set
from .run import run_batch

#: what made the files (their ``source`` and ``history`` attributes)
ENTRY = "nematic_solids.model.accelerated.datasets.batch_datasets"


def batch_datasets(
    params: Parameters,
    numerics: Numerics,
    seeds: Sequence[int],
    *,
    device: str = "cpu",
    initial: np.ndarray | None = None,
) -> list[xr.Dataset]:
    """Run the seeds ``seeds`` of one point together on ``device`` (:func:`run_batch`, whose
    checks and errors it shares) and return one Dataset per seed, in the order of ``seeds``
    (see the module docstring)."""
    seeds = tuple(seeds)
    eq = ActiveNematicPDE(params, numerics)  # the host's: the saves' mechanics and transforms
    snap_set = snapshot_set(numerics)
    rows: list[list[dict[str, float]]] = [[] for _ in seeds]
    snaps: list[list[tuple[float, np.ndarray]]] = [[] for _ in seeds]
    save_ffts = [0] * len(seeds)

    def on_save(t: float, fields: np.ndarray, codes: np.ndarray, steps: np.ndarray) -> None:
        for b in range(len(fields)):
            if codes[b] != 0:  # failed before this save: its series ends at the last one
                continue
            count = eq.spectral.fft.count
            obs, mech = observe_state(eq, fields[b], t, steps=int(steps[b]))
            rows[b].append(obs)
            if float(np.round(t, 12)) in snap_set:
                snaps[b].append((t, snapshot_fields(eq, fields[b], mech)))
            save_ffts[b] += eq.spectral.fft.count - count

    result = run_batch(params, numerics, seeds, device=device, initial=initial, on_save=on_save)
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
                "newton": 0,
                "projections": 0,
            },
            spin_iterations=w["spin_iterations"],
            cg_iterations=0,
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
            wall=share,
            entry=ENTRY,
        )
        ds.attrs["initial_from"] = ""
        out.append(ds)
    return out
