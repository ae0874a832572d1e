"""How long do phase.nc, the fits and status take for a 5,000-run campaign, and in how much
memory? (a benchmark, not a test)

Builds a synthetic results folder shaped like campaigns/fig4.yaml with 50 seeds: 4 chi x 5 K
x 5 eps x 50 seeds = 5,000 finished runs (2 % failed), in the real formats. One run is real:
the campaign's first run, simulated and written by the worker's own code
(:func:`nematic_solids.sweep.run.task.execute_run`: 128^2, finite strain, t/tau = 100, the
campaign's snapshot fields in float32). Every other run file is a copy of it with its own identity
(run_id, seed, parameters, status) and its own scalars and sigma2_S(t), patched in place with
netCDF4, and its record is the real run's record with those values and the file's own size, mtime
and SHA-256 (as the worker writes it). Then, each as a fresh process (wall, CPU and peak RSS from
the operating system, ``os.wait4``):

- ``nematic status`` cold (no manifest: every record is read) and warm;
- ``nematic aggregate`` (phase.nc from the records) over 1,000 of the runs (``--seeds 10``)
  and over all 5,000: the memory at the two sizes shows how it grows with the run count;
- the fits alone (``fits.nc``: the campaign's ``anisotropy``), and ``nematic figures`` (the
  fits and Fig. 4 with its four snapshots, read from run files);
- ``nematic report`` cold (the 100 points' run views drawn) and warm (cached).

    python benchmarks/aggregate_5k.py [--keep DIR] [--seeds 50]

With ``--keep DIR`` the folder stays, and a second call with it times the steps again
without rebuilding (the campaign's manifest, phase.nc, fits and report are removed first,
so the cold steps are cold again).

Prints a table and writes benchmarks/aggregate_5k.json. The build takes a few minutes (one
real run and 5,000 files of about 160 kB: 0.8 GiB on disk, removed after unless --keep).
Peak memory is as Linux counts it, which carries a process's peak across fork and exec: the
build runs in a child process, and the floor (this script's own peak) is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CAMPAIGN = """\
name: fig4big
description: synthetic 5,000-run campaign shaped like campaigns/fig4.yaml
parameters: {{S0: 0.1, A0: 0.1, gamma: 1.0, tau: 1.0, B: 0.5, alpha_minus_B: 1.0}}
numerics: {{resolution: 128, t_final: 100.0, save_every: 2.0, mechanics: finite}}
sweep:
  axes:
    chi: [0.0, 2.5, 5.0, 10.0]
    K: {{logspace: [-6, -2, 5]}}
    eps: [0.0, 0.01, 0.025, 0.05, 0.1]
seeds: {seeds}
store: {{snapshot_fields: [q1, q2, A, I1bar], snapshot_dtype: float32}}
fits: [anisotropy]
figures: [fig4]
execution: {{workers: 2}}
"""
FAILED_FRACTION = 0.02


def real_run(campaign: Any, expansion: Any, store: Any) -> Any:
    """The campaign's first run, simulated and stored by the worker's code."""
    from nematic_solids.sweep.run.task import RunTask, execute_run

    task = RunTask.from_spec(expansion.run(0), store, campaign.name, campaign.store)
    record = execute_run(task)
    assert record["status"] == "ok", record
    return record


def synthetic_values(
    rng: np.random.Generator, coords: dict[str, float], t: np.ndarray
) -> tuple[dict[str, float], np.ndarray]:
    """Plausible scalars of a run at ``coords`` and its sigma2_S(t) (not physics: values
    that vary over the grid and the seeds, so phase.nc and the fits have work to do)."""
    chi, eps = coords["chi"], coords["eps"]
    final = 10 ** rng.normal(-6 + 0.4 * chi, 0.5)
    series = final * np.exp(0.05 * (t - t[-1])) * (1 + 0.05 * rng.standard_normal(t.size))
    cos2 = float(np.tanh(40 * eps) + 0.05 * rng.standard_normal())
    lam = float(0.05 + 0.02 * rng.random())
    return {
        "sigma2_S_final": float(final),
        "cos2theta_final": cos2,
        "lambda_final": lam,
        "lambda_peak": lam * 0.9,
        "lambda_mean_final": lam * 0.8,
        "t_peak": 20.0,
        "mean_S_final": float(0.1 + 0.01 * rng.random()),
        "wall_time": float(rng.uniform(20, 40)),
    }, np.abs(series)


def build(folder: Path, seeds: int) -> tuple[Path, int, dict[str, float]]:
    import netCDF4

    from nematic_solids.sweep.expand import expand
    from nematic_solids.sweep.files import dumps, file_stamp
    from nematic_solids.sweep.spec import load_campaign
    from nematic_solids.sweep.store import CampaignStore

    path = folder / "fig4big.yaml"
    path.write_text(CAMPAIGN.format(seeds=seeds))
    campaign = load_campaign(path)
    expansion = expand(campaign)
    store = CampaignStore(folder / "results", campaign.name)
    store.ensure()
    store.save_campaign_text(campaign.text)
    t0 = time.perf_counter()
    template = real_run(campaign, expansion, store)
    t_real = time.perf_counter() - t0
    source = store.nc_path(template["run_id"])
    with netCDF4.Dataset(source) as nc:
        t = np.asarray(nc["t"][:])
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for i, rid in enumerate(expansion.run_ids):
        if i == 0:
            continue
        run = expansion.run(i)
        coords = dict(run.point.coords)
        failed = rng.random() < FAILED_FRACTION
        scalars, series = synthetic_values(rng, coords, t)
        target = store.nc_path(rid)
        shutil.copyfile(source, target)
        with netCDF4.Dataset(target, "a") as nc:
            nc.setncatts(
                {
                    "run_id": rid,
                    "seed": run.seed,
                    "status": "failed" if failed else "ok",
                    "reason": "ellipticity_lost" if failed else "",
                    **{f"param_{k}": v for k, v in coords.items()},
                }
            )
            nc["sigma2_S"][:] = series
            for name, value in scalars.items():
                if name in nc.variables:
                    nc[name].assignValue(value)
        record = dict(template)
        record.update(
            run_id=rid,
            seed=run.seed,
            scalars=scalars,
            wall_time=scalars["wall_time"],
            coords=coords,
            parameters=run.point.parameters.to_dict(),
            status="failed" if failed else "ok",
            reason="ellipticity_lost" if failed else "",
            t_failed=50.0 if failed else None,
            **file_stamp(target),
        )
        # the worker's format (store.write_record), without its fsync per file
        (store.runs_dir / f"{rid}.json").write_text(dumps(record))
    return path, len(expansion), {"real_run_s": t_real, "copies_s": time.perf_counter() - t0}


def timed(label: str, argv: list[str]) -> dict[str, Any]:
    """One fresh process: wall, CPU (user + system) and peak RSS, as the OS accounts them."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t = time.perf_counter()
    proc = subprocess.Popen(
        argv, env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    assert proc.stdout is not None
    out = proc.stdout.read()  # to its end, then reaped here: os.wait4 gives its own usage
    proc.stdout.close()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    proc.returncode = os.waitstatus_to_exitcode(status)
    text = out.decode(errors="replace").strip()
    if proc.returncode not in (0, 1):
        raise SystemExit(f"{label}: {' '.join(argv)} exited {proc.returncode}:\n{text}")
    row = {
        "wall_s": wall,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "peak_mib": usage.ru_maxrss / 1024,
        "exit": proc.returncode,
        "output": text.splitlines()[:2],
    }
    print(f"{label:<34}{wall:>8.2f}{row['cpu_s']:>8.2f}{row['peak_mib']:>10.0f}", flush=True)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="build the folder here and keep it")
    parser.add_argument("--seeds", type=int, default=50, help="seeds per grid point")
    parser.add_argument("--build", type=Path, help=argparse.SUPPRESS)  # the child's job
    args = parser.parse_args()
    if args.build is not None:
        _, n, build_times = build(args.build, args.seeds)
        (args.build / "built.json").write_text(json.dumps([n, build_times]))
        return
    folder = (args.keep or Path(tempfile.mkdtemp(prefix="aggregate5k-"))).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    try:
        built = folder / "built.json"  # a folder kept by --keep is timed again, not rebuilt
        if not built.is_file():
            # built by a child process: the real run's memory (the model, numba) would
            # otherwise count in every timed process's peak (Linux carries a process's peak
            # RSS across fork and exec)
            subprocess.run(
                [sys.executable, __file__, "--build", str(folder), "--seeds", str(args.seeds)],
                check=True,
                env={**os.environ, "PYTHONPATH": str(ROOT)},
            )
        path = folder / "fig4big.yaml"
        n, build_times = json.loads(built.read_text())
        results = folder / "results"
        root = results / "fig4big"
        for stale in ("manifest.json", "phase.nc", "fits.nc", "report.html"):
            (root / stale).unlink(missing_ok=True)
        shutil.rmtree(root / "report_cache", ignore_errors=True)
        shutil.rmtree(root / "figures", ignore_errors=True)
        disk = sum(p.stat().st_size for p in (root / "runs").iterdir())
        print(
            f"{n:,} runs built (the real run {build_times['real_run_s']:.0f} s, the copies "
            f"{build_times['copies_s']:.0f} s), {disk / 2**30:.2f} GiB; load average "
            f"{os.getloadavg()[0]:.1f}; peak memory floor (this process) "
            f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB"
        )
        print(f"{'step (a fresh process each)':<34}{'wall s':>8}{'cpu s':>8}{'peak MiB':>10}")
        py = [sys.executable, "-m", "nematic_solids.sweep"]
        common = [str(path), "--results", str(results)]
        fits = (
            "from pathlib import Path; "
            "from nematic_solids.sweep.analysis.fits_file import write_fits; "
            f"write_fits(Path({str(root)!r}), [('anisotropy', {{}})])"
        )
        rows = {
            "status, cold (no manifest)": timed(
                "status, cold (no manifest)", [*py, "status", *common]
            ),
            "status, warm": timed("status, warm", [*py, "status", *common]),
            "aggregate, 1,000 runs": timed(
                "aggregate, 1,000 runs (--seeds 10)",
                [*py, "aggregate", *common, "--seeds", str(max(1, args.seeds // 5))],
            ),
            "aggregate, all runs": timed(f"aggregate, {n:,} runs", [*py, "aggregate", *common]),
            "fits only": timed("fits only (fits.nc: anisotropy)", [sys.executable, "-c", fits]),
            "figures (fits + fig4)": timed("figures (fits + fig4)", [*py, "figures", *common]),
            "report, cold": timed(
                "report, cold (run views drawn)",
                [*py, "report", "fig4big", "--results", str(results)],
            ),
            "report, warm": timed(
                "report, warm (run views cached)",
                [*py, "report", "fig4big", "--results", str(results)],
            ),
        }
        out = Path(__file__).with_suffix(".json")
        out.write_text(
            json.dumps(
                {
                    "runs": n,
                    "seeds": args.seeds,
                    **build_times,
                    "peak_floor_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                    "run_files_gib": disk / 2**30,
                    "cpus": os.cpu_count(),
                    "load_average_after": round(os.getloadavg()[0], 2),
                    "results": rows,
                },
                indent=2,
            )
            + "\n"
        )
        print(f"wrote {out}")
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
