"""Calibration of the cost model of ``nematic run --dry-run`` / ``nematic validate --estimate``
(``sweep/cost/estimate.py``): runs a set of model runs one after the other in this process (warm:
the kernels compiled first), fits the model's constants and writes them with every row to
``benchmarks/cost_model.json``. Not a test: the numbers depend on the machine and its load.

    .venv/bin/python benchmarks/bench_cost.py            # about 2 minutes on a quiet 2-core VM

The model (per mechanics; X = N^2 log2 N / (128^2 * 7), 1 at 128^2):

    CPU time = steps * (step0 + step1 * X) + saves * (save0 + save1 * X) + (setup0 + setup1 * X)

with ``saves = t_final / save_every + 1`` and, for an adaptive run, ``steps`` read off the
step curve: the median over the activity rows (Fig. 2's parameters at 128^2, alpha - B = 0.1
... 1.0, t = 300) of the accepted steps by time t. The six cost constants are a least-squares
fit (non-negative, relative errors) to the size and activity rows with their measured steps;
the activity rows also give the spread: the 10 % and 90 % quantiles of measured / model over
them (the activity decides the step count: 1 to 4 steps per tau). The variant rows (other
numerics at alpha - B = 0.5) give each variant's run time and steps against the default's.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
REFERENCE = 128**2 * 7
#: Fig. 2's activities (the model's other defaults): the step count's main driver
ACTIVITIES = (0.1, 0.3, 0.5, 0.7, 1.0)


#: numerics other than the defaults, each run against the default at alpha - B = 0.5, t = 100
VARIANTS: dict[str, list[tuple[str, dict[str, Any]]]] = {
    "linear": [
        ("default", {}),
        ("tolerance=1e-4", {"tolerance": 1e-4}),
        ("scheme=etdrk2", {"scheme": "etdrk2"}),
        ("error_norm=rms", {"error_norm": "rms"}),
        ("incompressible", {"incompressible": True}),
        ("fixed dt=0.2", {"adaptive": False, "dt": 0.2}),
    ],
    "finite": [
        ("default", {}),
        ("tolerance=1e-4", {"tolerance": 1e-4}),
        ("scheme=etdrk2", {"scheme": "etdrk2"}),
        ("displacement=equilibrium", {"displacement": "equilibrium"}),
    ],
}


#: times at which the activity runs' step counts are kept (the model's step curve)
CURVE_TIMES = (0, 5, 10, 20, 40, 60, 100, 150, 200, 250, 300)


def scale(n: int) -> float:
    return n * n * math.log2(n) / REFERENCE


def configs() -> list[dict[str, Any]]:
    """(kind, parameters, numerics) of every row."""
    out: list[dict[str, Any]] = []
    for mech in ("linear", "finite"):
        for n in (32, 64, 128, 256):  # per-step and per-save cost against the resolution
            for save in (1.0, 10.0):
                out.append(
                    {
                        "kind": "size",
                        "mechanics": mech,
                        "parameters": {"alpha_minus_B": 0.5, "noise_modes": 8},
                        "numerics": {
                            "resolution": n,
                            "t_final": 20.0,
                            "save_every": save,
                            "mechanics": mech,
                        },
                    }
                )
        for amb in ACTIVITIES:  # the step count against the activity (the spread)
            out.append(
                {
                    "kind": "activity",
                    "mechanics": mech,
                    "parameters": {"alpha_minus_B": amb},
                    "numerics": {
                        "resolution": 128,
                        "t_final": 300.0,
                        "save_every": 1.0,
                        "mechanics": mech,
                    },
                }
            )
        for name, extra in VARIANTS[mech]:  # other numerics against the default (amb 0.5)
            out.append(
                {
                    "kind": "variant",
                    "variant": name,
                    "mechanics": mech,
                    "parameters": {"alpha_minus_B": 0.5},
                    "numerics": {
                        "resolution": 128,
                        "t_final": 100.0,
                        "save_every": 1.0,
                        "mechanics": mech,
                        **extra,
                    },
                }
            )
    return out


def measure(cfg: dict[str, Any], repeats: int) -> dict[str, Any]:
    """One row: the run's CPU time (the least of ``repeats`` runs: other work on the machine
    only ever adds to it), its accepted steps (the step curve) and saves."""
    from nematic_solids.model.parameters import Numerics, Parameters
    from nematic_solids.model.simulate import run

    p = Parameters.from_dict(cfg["parameters"])
    n = Numerics.from_dict(cfg["numerics"])
    cpu, wall = [], []
    for _ in range(repeats):
        t0 = time.process_time()
        ds = run(p, n, 0)
        cpu.append(time.process_time() - t0)
        wall.append(float(ds["wall_time"]))
    t = ds["t"].values
    steps = ds["steps"].values
    return {
        **cfg,
        "status": ds.attrs["status"],
        "cpu_s": min(cpu),
        "wall_s": min(wall),
        "steps": int(steps[-1]),
        "saves": len(t),
        "steps_at": {
            str(int(x)): int(steps[np.argmin(abs(t - x))]) for x in CURVE_TIMES if x <= t[-1]
        },
    }


def nnls_relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    from scipy.optimize import nnls

    w = 1.0 / b
    x, _ = nnls(a * w[:, None], b * w)
    return x


def model_seconds(const: dict[str, Any], n: int, steps: float, saves: int) -> float:
    x = scale(n)
    return (
        steps * (const["step"][0] + const["step"][1] * x)
        + saves * (const["save"][0] + const["save"][1] * x)
        + const["setup"][0]
        + const["setup"][1] * x
    )


def fit(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for mech in ("linear", "finite"):
        mine = [
            r
            for r in rows
            if r["mechanics"] == mech and r["status"] == "ok" and r["kind"] != "variant"
        ]
        a = np.array(
            [
                [
                    r["steps"],
                    r["steps"] * scale(r["numerics"]["resolution"]),
                    r["saves"],
                    r["saves"] * scale(r["numerics"]["resolution"]),
                    1.0,
                    scale(r["numerics"]["resolution"]),
                ]
                for r in mine
            ]
        )
        b = np.array([r["cpu_s"] for r in mine])
        x = nnls_relative(a, b)
        const: dict[str, Any] = {
            "step": [float(x[0]), float(x[1])],
            "save": [float(x[2]), float(x[3])],
            "setup": [float(x[4]), float(x[5])],
            "fit_residual_max": float(np.max(np.abs(a @ x / b - 1))),
        }
        # the median over the activities of the accepted steps by time t
        act = [r for r in mine if r["kind"] == "activity"]
        const["steps_curve"] = [
            [float(t), float(np.median([r["steps_at"][str(t)] for r in act]))] for t in CURVE_TIMES
        ]
        ratios = []
        for r in act:
            steps = const["steps_curve"][-1][1]
            model = model_seconds(const, r["numerics"]["resolution"], steps, r["saves"])
            ratios.append(r["cpu_s"] / model)
        const["activity_ratios"] = ratios
        # each variant's run time and steps against the default's
        var = {
            r["variant"]: r
            for r in rows
            if r["mechanics"] == mech and r["kind"] == "variant" and r["status"] == "ok"
        }
        base = var.pop("default", None)
        if base is not None:
            const["variants"] = {
                k: {"time": v["cpu_s"] / base["cpu_s"], "steps": v["steps"] / base["steps"]}
                for k, v in var.items()
            }
        out[mech] = const
    ratios = [q for m in ("linear", "finite") for q in out[m]["activity_ratios"]]
    out["spread"] = [float(np.quantile(ratios, 0.1)), float(np.quantile(ratios, 0.9))]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "cost_model.json"))
    ap.add_argument(
        "--repeats",
        type=int,
        default=2,
        help="runs of each size and variant row (the least CPU time is kept)",
    )
    args = ap.parse_args()
    from nematic_solids.model.warmup import warm_up

    warm_up()
    rows = []
    for cfg in configs():
        r = measure(cfg, 1 if cfg["kind"] == "activity" else args.repeats)
        rows.append(r)
        num = r["numerics"]
        print(
            f"{r['kind']:8s} {r['mechanics']:6s} N={num['resolution']:<4d} "
            f"t={num['t_final']:<5g} save={num['save_every']:<4g} "
            f"amb={r['parameters']['alpha_minus_B']:<4g} {r.get('variant', ''):24s} "
            f"{r['cpu_s']:7.2f} s CPU "
            f"{r['steps']:5d} steps {r['status']}",
            flush=True,
        )
    result = {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cores": os.cpu_count(),
        "load_average": os.getloadavg(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "fit": fit(rows),
        "rows": rows,
    }
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["fit"], indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
