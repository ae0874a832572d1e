"""Speed of one model run (Fig. 2 parameters, alpha - B = 1), printed as a table and written as
JSON. Not a test: numbers depend on the machine and its load.

    .venv/bin/python benchmarks/bench_model.py                 # the full issue table
    .venv/bin/python benchmarks/bench_model.py --quick         # 64^2 only, t_final = 50

Each configuration runs in a fresh subprocess (so peak memory is its own) and runs twice there:
the first run pays imports/plans, the second shows the steady cost (no recompilation). Reported:
wall time, accepted steps, FFTs per step, the FFT floor (measured time of one 2-D real FFT at this
size x FFTs performed), peak RSS, sigma2_S at t_final; and, optionally (--pypde), py-pde's own
adaptive explicit Runge-Kutta on the same PDE class for comparison at equal sigma2_S.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, resource, sys, time
import numpy as np
cfg = json.loads(sys.argv[1])
t_import = time.perf_counter()
from nematic_solids.model.parameters import Parameters, Numerics
from nematic_solids.model.simulate import run
from nematic_solids.model.fourier import SpectralGrid
t_import = time.perf_counter() - t_import
# a fixed workload (texture band 16, zeta = 1, kappa = 10), so its figures stay comparable when
# the model's defaults change; band 16 also runs at 64^2
params = Parameters.from_dict({"alpha_minus_B": 1.0, "noise_modes": 16, "zeta": 1.0, "kappa": 10.0})
num = Numerics(resolution=cfg["N"], t_final=cfg["t_final"], mechanics=cfg["mechanics"],
               save_every=cfg["t_final"])
out = {"import_s": t_import}
if cfg.get("pypde"):
    from nematic_solids.model.pde import ActiveNematicPDE, make_state
    from nematic_solids.model.initial import initial_fields
    from nematic_solids.model.observables import order_parameter
    eq = ActiveNematicPDE(params, num)
    state = make_state(*initial_fields(params, cfg["N"], 0))
    t0 = time.perf_counter()
    final, info = eq.solve(state, t_range=cfg["t_final"], dt=1e-3, solver="runge-kutta",
                           adaptive=True, tolerance=cfg.get("rk_tol", 1e-4), backend="numpy",
                           tracker=None, ret_info=True)
    S = order_parameter(final.data[0], final.data[1])
    out["pypde"] = {"wall_s": time.perf_counter() - t0, "sigma2_S": float(S.var()),
                    "steps": int(info["solver"].get("steps", -1))}
for label in ("first", "second")[:cfg.get("runs", 2)]:
    grid_fft = None
    t0 = time.perf_counter()
    ds = run(params, num, 0)
    wall = time.perf_counter() - t0
    out[label] = {"wall_s": wall, "steps": int(ds.attrs["solver_steps"]),
                  "rhs": int(ds.attrs["solver_rhs"]), "status": ds.attrs["status"],
                  "sigma2_S": float(ds["sigma2_S"].values[-1]),
                  "ffts": int(ds.attrs.get("fft_count", -1))}
# FFT floor: one forward + one inverse 2-D real FFT at this size
g = SpectralGrid(cfg["N"])
a = np.random.default_rng(0).standard_normal((cfg["N"], cfg["N"]))
for _ in range(20):
    g.inverse(g.forward(a))
n = 400
t0 = time.perf_counter()
for _ in range(n):
    g.inverse(g.forward(a))
out["fft_s"] = (time.perf_counter() - t0) / (2 * n)
out["fft_backend"] = g.fft.backend
out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
out.setdefault("second", out["first"])
print("RESULT " + json.dumps(out))
"""


def run_config(cfg: dict) -> dict:
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, json.dumps(cfg)],
        capture_output=True,
        text=True,
        cwd=HERE.parent,
    )
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return {**cfg, **json.loads(line[7:])}
    raise RuntimeError(f"benchmark child failed:\n{proc.stdout}\n{proc.stderr}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="64^2, t_final = 50 only")
    ap.add_argument("--t-final", type=float, default=300.0)
    ap.add_argument("--sizes", default="64,128,256")
    ap.add_argument("--finite-sizes", default="64,128")
    ap.add_argument(
        "--pypde",
        action="store_true",
        help="also time py-pde's adaptive explicit solver (slow) at 128^2",
    )
    ap.add_argument(
        "--pypde-t",
        type=float,
        default=20.0,
        help="t_final of the py-pde comparison (its explicit solver is slow)",
    )
    ap.add_argument(
        "--runs",
        type=int,
        default=2,
        choices=(1, 2),
        help="runs per configuration in one process (2 shows the warm cost)",
    )
    ap.add_argument("--out", default=str(HERE / "bench_model.json"))
    args = ap.parse_args()
    if args.quick:
        sizes, fsizes, t_final = [64], [64], 50.0
    else:
        sizes = [int(s) for s in args.sizes.split(",") if s]
        fsizes = [int(s) for s in args.finite_sizes.split(",") if s]
        t_final = args.t_final
    configs = [
        {"N": n, "mechanics": "linear", "t_final": t_final, "runs": args.runs} for n in sizes
    ]
    configs += [
        {"N": n, "mechanics": "finite", "t_final": t_final, "runs": args.runs} for n in fsizes
    ]
    if args.pypde:
        configs.append({"N": 128, "mechanics": "linear", "t_final": args.pypde_t, "pypde": True})
    rows = []
    hdr = (
        f"{'mech':7s} {'N':>4s} {'t':>5s} {'wall1 s':>8s} {'wall2 s':>8s} {'steps':>6s} "
        f"{'FFT/step':>8s} {'floor s':>8s} {'wall/floor':>10s} {'RSS MB':>7s} {'sigma2_S':>10s}"
    )
    print(hdr)
    for cfg in configs:
        r = run_config(cfg)
        s = r["second"]
        ffts_per_step = s["ffts"] / max(s["steps"], 1)
        floor = r["fft_s"] * s["ffts"]
        r["ffts_per_step"] = ffts_per_step
        r["fft_floor_s"] = floor
        r["ratio_to_floor"] = s["wall_s"] / floor if floor > 0 else float("nan")
        rows.append(r)
        print(
            f"{cfg['mechanics']:7s} {cfg['N']:4d} {cfg['t_final']:5.0f} "
            f"{r['first']['wall_s']:8.2f} {s['wall_s']:8.2f} {s['steps']:6d} "
            f"{ffts_per_step:8.1f} {floor:8.2f} {r['ratio_to_floor']:10.1f} "
            f"{r['peak_rss_mb']:7.0f} {s['sigma2_S']:10.4g}",
            flush=True,
        )
        if "pypde" in r:
            p = r["pypde"]
            print(
                f"  py-pde runge-kutta adaptive: {p['wall_s']:.2f} s, sigma2_S = "
                f"{p['sigma2_S']:.4g} (ours {s['sigma2_S']:.4g}, "
                f"{100 * abs(p['sigma2_S'] / s['sigma2_S'] - 1):.2f}% apart); "
                f"speed-up {p['wall_s'] / s['wall_s']:.1f}x"
            )
    lin = {r["N"]: r for r in rows if r["mechanics"] == "linear" and "pypde" not in r}
    fin = {r["N"]: r for r in rows if r["mechanics"] == "finite"}
    for n in sorted(set(lin) & set(fin)):
        print(
            f"finite / linear at {n}^2: "
            f"{fin[n]['second']['wall_s'] / lin[n]['second']['wall_s']:.1f}x"
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
