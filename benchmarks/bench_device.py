"""The accelerated backend (model/accelerated/, JAX) on a device, side by side with today's
compiled path: B seeds of one point (Fig. 2's parameters at alpha - B = 1, band texture of 16
modes, default numerics but ``t_final``; small-strain mechanics, or finite strain with
``--mechanics finite``) at each grid size, as one batched run
on the device and as B runs of ``nematic_solids.model.simulate.run`` one after another on one CPU
core.

Prints a table and writes ``benchmarks/bench_device.json`` (finite strain:
``benchmarks/bench_device_finite.json``; ``--out``): per grid and batch
size the device, the seconds (wall and CPU of this process; the batched run's compile apart),
the steps and transforms per seed (the stepping's, without the saves'), the runs per hour
(wall) and per CPU hour (this process's CPU time, all its threads: the figure a loaded machine
distorts least), the
time of one transform on the device (a batched rfft2 + irfft2 pair, per field) and the
transform floor (transforms x that time, summed over the batch) against the wall time, and
the agreement with the CPU result: the largest relative difference of sigma2_S, mean_S and
lambda at the saves between each seed of the batch and the compiled run of that seed. Not a
test: the numbers depend on the machine and its load (``os.getloadavg`` is recorded).

    .venv/bin/python benchmarks/bench_device.py      # CPU, 64^2 and 128^2, B = 1, 8
    .venv/bin/python benchmarks/bench_device.py --device gpu --sizes 128,256,512 --batch 1,8,50 \\
        --t-final 300                                 # on a CUDA machine
    .venv/bin/python benchmarks/bench_device.py --mechanics finite ...   # finite strain

On a GPU machine install the extra first: ``pip install '.[accel]' 'jax[cuda12]'``. ``--device
gpu`` fails at once with the model's ``DeviceUnavailable`` where JAX sees no GPU.
``--no-compiled`` skips the compiled runs (then no agreement is measured).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from fftw_timing import fftw_transform_seconds

from nematic_solids.model.accelerated import run_batch, select_device
from nematic_solids.model.accelerated.device import describe
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run

HERE = Path(__file__).resolve().parent
OBSERVABLES = ("sigma2_S", "mean_S", "lambda")


def transform_seconds(n: int, batch: int, device: str) -> float:
    """Seconds of one real 2-D transform of an n x n field on the device: a jitted rfft2 +
    irfft2 of (batch, 2, n, n) float64, the median of repeats over 2 * batch * 2 transforms."""
    import jax
    import jax.numpy as jnp

    dev = select_device(device)
    x = jax.device_put(np.random.default_rng(0).standard_normal((batch, 2, n, n)), dev)
    pair = jax.jit(lambda a: jnp.fft.irfft2(jnp.fft.rfft2(a), s=(n, n)))
    jax.block_until_ready(pair(x))
    reps = max(3, int(4e6 / (batch * n * n)))
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(reps):
            x = pair(x)
        jax.block_until_ready(x)
        times.append((time.perf_counter() - t0) / reps)
    return float(np.median(times)) / (2 * batch * 2)


def compiled_runs(params: Parameters, numerics: Numerics, seeds: range) -> dict:
    """The compiled path: each seed a nematic_solids.model.simulate.run, one after another; its
    transform floor: every transform counted (the saves' too) x one FFTW transform's time."""
    run(params, numerics.replace(t_final=1.0, save_every=1.0), 0)  # kernels loaded, plans made
    wall0, cpu0 = time.perf_counter(), time.process_time()
    datasets = [run(params, numerics, seed) for seed in seeds]
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    per_transform = fftw_transform_seconds(numerics.resolution)
    every = sum(int(ds.attrs["fft_count"]) for ds in datasets)
    steps = [int(ds.attrs["solver_steps"]) for ds in datasets]
    ffts = [int(ds.attrs["fft_count"]) - int(ds.attrs["fft_saves"]) for ds in datasets]
    return {
        "datasets": datasets,
        "row": {
            "wall_s": wall,
            "cpu_s": cpu,
            "steps_per_seed": float(np.mean(steps)),
            "rejected_per_seed": float(np.mean([ds.attrs["solver_rejected"] for ds in datasets])),
            "transforms_per_seed": float(np.mean(ffts)),
            "transforms_per_step": float(np.sum(ffts) / np.sum(steps)),
            "runs_per_hour": len(seeds) * 3600.0 / wall,
            "runs_per_cpu_hour": len(seeds) * 3600.0 / cpu,
            "transform_s": per_transform,
            "wall_over_floor": wall / (every * per_transform),
        },
    }


def agreement(result, datasets) -> float:
    """The largest relative difference of :data:`OBSERVABLES` at the saves (relative to the
    largest value of each series) between the batch's seeds and the compiled runs."""
    worst = 0.0
    for i, ds in enumerate(datasets):
        for name in OBSERVABLES:
            want, got = ds[name].values, result.series[name][i]
            ok = np.isfinite(want) & np.isfinite(got)
            scale = float(np.abs(want[ok]).max()) or 1.0
            worst = max(worst, float(np.abs(got[ok] - want[ok]).max()) / scale)
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu", help="cpu, gpu or auto")
    ap.add_argument("--sizes", default="64,128", help="grid sizes N, comma separated")
    ap.add_argument("--batch", default="1,8", help="seeds per batch B, comma separated")
    ap.add_argument("--t-final", type=float, default=30.0)
    ap.add_argument("--amb", type=float, default=1.0, help="alpha - B")
    ap.add_argument("--no-compiled", action="store_true", help="skip today's compiled path")
    ap.add_argument(
        "--no-accelerated",
        action="store_true",
        help="skip the accelerated path (to time the compiled one as a process of its own)",
    )
    ap.add_argument("--mechanics", default="linear", choices=("linear", "finite"))
    ap.add_argument("--out", default=None, help="the JSON (default: by --mechanics, above)")
    args = ap.parse_args()
    if args.out is None:
        name = "bench_device.json" if args.mechanics == "linear" else "bench_device_finite.json"
        args.out = str(HERE / name)
    import jax

    dev = select_device(args.device)  # DeviceUnavailable here, before any run
    params = Parameters.from_dict({"alpha_minus_B": args.amb, "noise_modes": 16})
    rows: list[dict] = []

    def write(rows: list[dict]) -> None:
        """The JSON, after every row: a long benchmark keeps what it measured."""
        out = {
            "benchmark": "bench_device",
            "jax_version": jax.__version__,
            "device": describe(dev),
            "machine": platform.machine(),
            "cpu_count": os.cpu_count(),
            "loadavg_at_end": os.getloadavg(),
            "parameters": params.to_dict(),
            "mechanics": args.mechanics,
            "rows": rows,
        }
        Path(args.out).write_text(json.dumps(out, indent=1, default=str))

    for n in (int(s) for s in args.sizes.split(",")):
        numerics = Numerics(resolution=n, mechanics=args.mechanics, t_final=args.t_final)
        for batch in (int(b) for b in args.batch.split(",")):
            seeds = range(batch)
            if args.no_accelerated:
                compiled = compiled_runs(params, numerics, seeds)
                rows.append({"N": n, "B": batch, "t_final": args.t_final, **compiled["row"]})
                c = compiled["row"]
                print(
                    f"N={n:4d} B={batch:3d} compiled: {c['wall_s']:7.2f} s, "
                    f"{c['runs_per_hour']:9.0f} runs/h, wall/floor {c['wall_over_floor']:.1f}",
                    flush=True,
                )
                write(rows)
                continue
            result = run_batch(params, numerics, seeds, device=args.device)
            steps = result.work["steps"]
            per_transform = transform_seconds(n, batch, args.device)
            transforms = result.work["transforms"]
            row = {
                "N": n,
                "B": batch,
                "t_final": args.t_final,
                "device": result.device,
                "accelerated": {
                    "wall_s": result.wall,
                    "compile_s": result.compile,
                    "cpu_s": result.cpu,
                    "runs_per_cpu_hour": batch * 3600.0 / result.cpu,
                    "steps_per_seed": float(steps.mean()),
                    "rejected_per_seed": float(result.work["rejected"].mean()),
                    "transforms_per_seed": float(transforms.mean()),
                    "transforms_per_step": float(transforms.sum() / steps.sum()),
                    "spin_iterations_per_seed": float(result.work["spin_iterations"].mean()),
                    "runs_per_hour": batch * 3600.0 / result.wall,
                    "transform_s": per_transform,
                    "wall_over_floor": result.wall / (float(transforms.sum()) * per_transform),
                    "status": result.status,
                },
            }
            if not args.no_compiled:
                compiled = compiled_runs(params, numerics, seeds)
                row["compiled_cpu"] = compiled["row"]
                row["agreement_with_cpu"] = agreement(result, compiled["datasets"])
            rows.append(row)
            a, c = row["accelerated"], row.get("compiled_cpu", {})
            print(
                f"N={n:4d} B={batch:3d} {result.device}: {a['wall_s']:7.2f} s "
                f"(cpu {a['cpu_s']:.2f} s; +{a['compile_s']:.1f} s compile) "
                f"{a['runs_per_hour']:9.0f} runs/h, {a['runs_per_cpu_hour']:9.0f} runs/cpu-h, "
                f"{a['steps_per_seed']:.0f} steps, {a['transforms_per_step']:.1f} transforms/step, "
                f"wall/floor {a['wall_over_floor']:.1f}"
                + (
                    f" | compiled: {c['wall_s']:7.2f} s (cpu {c['cpu_s']:.2f} s) "
                    f"{c['runs_per_hour']:9.0f} runs/h, {c['runs_per_cpu_hour']:9.0f} runs/cpu-h, "
                    f"{c['steps_per_seed']:.0f} steps, {c['transforms_per_step']:.1f} "
                    f"transforms/step, wall/floor {c['wall_over_floor']:.1f} | agreement "
                    f"{row['agreement_with_cpu']:.1e}"
                    if c
                    else ""
                ),
                flush=True,
            )
            write(rows)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
