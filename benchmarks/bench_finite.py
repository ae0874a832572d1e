"""Finite strain against linear mechanics, side by side: CPU time, steps and transforms per step
by part of the work, for the finite-strain schemes (``displacement`` "integrated", the default,
and "equilibrium", Newton at every stage) and the linear run, at the Fig. 2 parameters. Not a
test: the numbers depend on the machine and its load, so each finite run is timed at the same
time as a linear run (two processes, one per core) and the ratio is of CPU times. This machine's
speed drifts (single ratios between 2.6x and 3.5x for the same code were seen), so ``--repeat``
runs each pair several times and reports the median ratio (and the range). The linear side runs
its simulation ``--linear-runs`` times in a row (mean CPU time), so that it shares the machine
with the finite run for all of the finite run's time, not only its first part.

    .venv/bin/python benchmarks/bench_finite.py                      # 128^2, alpha - B = 1, 0.6
    .venv/bin/python benchmarks/bench_finite.py --amb 0.6 --schemes integrated --repeat 5
    .venv/bin/python benchmarks/bench_finite.py --sizes 64 --t-final 100   # quick

Writes benchmarks/bench_finite.json (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, sys, time
cfg = json.loads(sys.argv[1])
from nematic_solids.model.parameters import Parameters, Numerics
from nematic_solids.model.simulate import run
# a fixed workload (texture band 16, zeta = 1, kappa = 10), so its figures stay comparable when
# the model's defaults change; band 16 also runs at 64^2
params = Parameters.from_dict({"alpha_minus_B": cfg["amb"], "noise_modes": 16, "zeta": 1.0,
                               "kappa": 10.0})
extra = {"displacement": cfg["displacement"]} if cfg["mechanics"] == "finite" else {}
num = Numerics(resolution=cfg["N"], t_final=cfg["t_final"], mechanics=cfg["mechanics"],
               save_every=cfg["t_final"] / 10, **extra)
run(params, num.replace(t_final=1.0, save_every=1.0), 0)  # load the cached kernels, plan
cpu = []
t0 = time.perf_counter()
for _ in range(cfg.get("runs", 1)):  # the same run again: the mean CPU time over the runs
    c0 = time.process_time()
    ds = run(params, num, 0)
    cpu.append(time.process_time() - c0)
a = ds.attrs
out = {"wall_s": (time.perf_counter() - t0) / len(cpu), "cpu_s": sum(cpu) / len(cpu),
       "cpu_runs": cpu,
       "status": a["status"], "steps": int(a["solver_steps"]),
       "rejected": int(a["solver_rejected"]), "rhs": int(a["solver_rhs"]),
       "newton": int(a["solver_newton"]), "spin_iterations": int(a["solver_spin_iterations"]),
       "cg_iterations": int(a["solver_cg_iterations"]), "ffts": int(a["fft_count"]),
       "parts": {k[4:]: int(v) for k, v in a.items()
                 if k.startswith("fft_") and k not in ("fft_count", "fft_backend", "fft_plans")},
       **{k: float(ds[k].values[-1]) for k in ("sigma2_S", "cos2theta", "lambda")}}
print("RESULT " + json.dumps(out))
"""


def start(cfg: dict) -> subprocess.Popen:
    env = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    import os

    return subprocess.Popen(
        [sys.executable, "-c", CHILD, json.dumps(cfg)],
        cwd=HERE.parent,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **env},
    )


def result(proc: subprocess.Popen, cfg: dict) -> dict:
    stdout, stderr = proc.communicate()
    for line in stdout.splitlines():
        if line.startswith("RESULT "):
            return {**cfg, **json.loads(line[7:])}
    raise RuntimeError(f"benchmark child failed:\n{stdout}\n{stderr}")


def side_by_side(a: dict, b: dict) -> tuple[dict, dict]:
    pa, pb = start(a), start(b)
    return result(pa, a), result(pb, b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="128")
    ap.add_argument("--amb", default="1.0,0.6", help="alpha - B values")
    ap.add_argument("--t-final", type=float, default=300.0)
    ap.add_argument(
        "--schemes", default="integrated,equilibrium", help="finite-strain displacement schemes"
    )
    ap.add_argument(
        "--repeat",
        type=int,
        default=1,
        help="side-by-side pairs per configuration (the median ratio is reported)",
    )
    ap.add_argument(
        "--linear-runs",
        type=int,
        default=3,
        help="linear runs in a row beside each finite run (about the CPU ratio)",
    )
    ap.add_argument("--out", default=str(HERE / "bench_finite.json"))
    args = ap.parse_args()
    rows = []
    print(
        f"{'N':>4s} {'a-B':>4s} {'run':12s} {'cpu s':>7s} {'steps':>6s} {'FFT/step':>8s} "
        f"{'rate':>6s} {'N-CG':>6s} {'N-res':>6s} {'saves':>6s} {'rest':>6s} "
        f"{'x linear':>8s} {'sigma2_S':>9s}"
    )
    for n in (int(s) for s in args.sizes.split(",")):
        for amb in (float(s) for s in args.amb.split(",")):
            base = {"N": n, "amb": amb, "t_final": args.t_final}
            for disp in args.schemes.split(","):
                ratios = []
                for _ in range(args.repeat):
                    fin, lin = side_by_side(
                        {**base, "mechanics": "finite", "displacement": disp},
                        {
                            **base,
                            "mechanics": "linear",
                            "displacement": "",
                            "runs": args.linear_runs,
                        },
                    )
                    fin["ratio_cpu"] = fin["cpu_s"] / lin["cpu_s"]
                    ratios.append(fin["ratio_cpu"])
                    for r, label in ((fin, disp), (lin, "linear")):
                        steps = max(r["steps"], 1)
                        parts = {k: v / steps for k, v in r["parts"].items()}
                        rest = r["ffts"] / steps - sum(parts.values())
                        ratio = f"{r['ratio_cpu']:8.2f}" if "ratio_cpu" in r else f"{'':8s}"
                        print(
                            f"{n:4d} {amb:4.1f} {label:12s} {r['cpu_s']:7.1f} {r['steps']:6d} "
                            f"{r['ffts'] / steps:8.1f} {parts.get('rate_solve', 0):6.1f} "
                            f"{parts.get('newton_cg', 0):6.1f} "
                            f"{parts.get('force_balance', 0):6.1f} {parts['saves']:6.1f} "
                            f"{rest:6.1f} {ratio} {r['sigma2_S']:9.5f}",
                            flush=True,
                        )
                        rows.append(r)
                if args.repeat > 1:
                    print(
                        f"{n:4d} {amb:4.1f} {disp:12s} median ratio "
                        f"{statistics.median(ratios):.2f} (range {min(ratios):.2f}-"
                        f"{max(ratios):.2f}, {len(ratios)} pairs)",
                        flush=True,
                    )
    meta = {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "rows": rows,
    }
    Path(args.out).write_text(json.dumps(meta, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
