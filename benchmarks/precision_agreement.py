"""float32 against float64 on the accelerated backend (JAX, here on the CPU): the observables
sigma2_S, lambda and <cos 2theta> of the same seeds run in both precisions, both mechanics,
small grids; prints a table and writes JSON (docs/guide/precision.md quotes it).

    .venv/bin/python benchmarks/precision_agreement.py                  # 32^2 and 64^2
    .venv/bin/python benchmarks/precision_agreement.py --sizes 32 --t-final 10 --out /tmp/p.json

For every (mechanics, N, alpha - B) the seeds run as one batch per precision; the JSON holds per
seed the final values, the largest relative difference over the saved times (where the float64
value is not below 1e-12 in size), the steps and the rejected steps of each precision.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from nematic_solids.model.accelerated import run_batch
from nematic_solids.model.parameters import Numerics, Parameters

OBSERVABLES = ("sigma2_S", "lambda", "cos2theta")


def relative(a: np.ndarray, b: np.ndarray) -> float:
    """The largest |b - a| / |a| over the entries where a is not ~0 (NaN-safe)."""
    ok = np.isfinite(a) & np.isfinite(b) & (np.abs(a) > 1e-12)
    return float(np.max(np.abs(b[ok] - a[ok]) / np.abs(a[ok]))) if ok.any() else 0.0


def compare(mechanics: str, n: int, amb: float, t_final: float, seeds: list[int]) -> dict:
    params = Parameters.from_dict({"alpha_minus_B": amb, "noise_modes": min(8, n // 2 - 1)})
    runs = {}
    for precision in ("float64", "float32"):
        num = Numerics(
            resolution=n,
            t_final=t_final,
            save_every=t_final / 10,
            mechanics=mechanics,
            precision=precision,
        )
        runs[precision] = run_batch(params, num, seeds, device="cpu")
    a, b = runs["float64"], runs["float32"]
    out: dict = {
        "mechanics": mechanics,
        "resolution": n,
        "alpha_minus_B": amb,
        "t_final": t_final,
        "seeds": seeds,
        "status": {p: r.status for p, r in runs.items()},
        "steps": {p: r.work["steps"].tolist() for p, r in runs.items()},
        "rejected": {p: r.work["rejected"].tolist() for p, r in runs.items()},
        "wall_s": {p: r.wall for p, r in runs.items()},
    }
    for name in OBSERVABLES:
        out[name] = {
            "float64_final": a.series[name][:, -1].tolist(),
            "float32_final": b.series[name][:, -1].tolist(),
            "max_relative_difference": [
                relative(a.series[name][i], b.series[name][i]) for i in range(len(seeds))
            ],
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--values", type=float, nargs="+", default=[0.3, 0.6])
    ap.add_argument("--mechanics", nargs="+", default=["linear", "finite"])
    ap.add_argument("--t-final", type=float, default=50.0)
    ap.add_argument("--seeds", type=int, default=4)
    default_out = Path(__file__).with_name("precision_agreement.json")
    ap.add_argument("--out", type=Path, default=default_out)
    args = ap.parse_args()
    rows: list[dict] = []
    start = time.time()
    command = "benchmarks/precision_agreement.py " + " ".join(
        f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k != "out"
    )
    for mech in args.mechanics:
        for n in args.sizes:
            for amb in args.values:
                r = compare(mech, n, amb, args.t_final, list(range(args.seeds)))
                rows.append(r)
                worst = {k: max(r[k]["max_relative_difference"]) for k in OBSERVABLES}
                print(
                    f"{mech:7s} {n:4d}^2 alpha-B={amb:4.2f} steps64={r['steps']['float64']} "
                    f"steps32={r['steps']['float32']} "
                    + " ".join(f"{k}={v:.2e}" for k, v in worst.items()),
                    flush=True,
                )
                # written after every row (atomically), so a run cut short keeps its rows
                record = {
                    "what": "float32 vs float64, accelerated backend on the CPU",
                    "command": command,
                    "machine": platform.processor() or platform.machine(),
                    "total_s": time.time() - start,
                    "complete": False,
                    "runs": rows,
                }
                tmp = args.out.with_suffix(".json.tmp")
                tmp.write_text(json.dumps(record, indent=1))
                tmp.replace(args.out)
    record["complete"] = True
    args.out.write_text(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
