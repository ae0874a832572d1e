"""The cost estimate of ``nematic run --dry-run`` against the wall time of the campaign then
run (a benchmark, not a test: the numbers depend on the machine and its load).

Two checks on campaigns/quickstart.yaml (128^2, finite strain, t = 40), each into a fresh
results folder:

- **own runs**: run it with ``--seeds 1`` (4 runs), estimate the full campaign
  (``--seeds SEEDS``: 2, then 6) from those runs, then run it and time the command;
- **cost model**: estimate a fresh campaign (no runs: the cost model), then run it and time
  the command.

    python benchmarks/estimate_check.py [--seeds 2 6] [--results /tmp/estres]

Prints a table and writes benchmarks/estimate_check.json (estimated wall time with its
10-90 % range, the command's wall time, estimated and measured CPU time, the load average).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from nematic_solids.sweep.cost.estimate import estimate
from nematic_solids.sweep.spec import Overrides, load_campaign
from nematic_solids.sweep.store import CampaignStore

ROOT = Path(__file__).resolve().parent.parent
QUICKSTART = ROOT / "campaigns" / "quickstart.yaml"


def nematic(*args: str) -> float:
    """Run ``nematic ARGS``; return its wall time (seconds)."""
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "nematic_solids.sweep", *args, "--no-dashboard", "-q"],
        check=True,
        cwd=ROOT,
    )
    return time.perf_counter() - t0


def run_times(store: CampaignStore, exclude: set[str]) -> float:
    return sum(
        float(r.get("wall_time") or 0.0)
        for rid, r in store.scan(save=False).items()
        if rid not in exclude
    )


def check(label: str, name: str, results: Path, seeds: int, partial: int | None) -> dict:
    shutil.rmtree(results / name, ignore_errors=True)
    common = ["--name", name, "--results", str(results)]
    if partial is not None:
        nematic("run", str(QUICKSTART), *common, "--seeds", str(partial))
    campaign = load_campaign(QUICKSTART, Overrides(name=name, seeds=seeds))
    store = CampaignStore(results, name)
    before = set(store.scan(save=False))
    e = estimate(campaign, store)
    wall = nematic("run", str(QUICKSTART), *common, "--seeds", str(seeds))
    out: dict[str, Any] = {
        "check": label,
        "runs": e.to_do,
        "basis": e.basis,
        "load_average": e.load,
        "stretch": e.stretch,
        "estimated_wall_s": [w + e.overhead for w in e.wall],
        "actual_wall_s": wall,
        "estimated_cpu_s": list(e.cpu),
        "actual_cpu_s": run_times(store, before),
    }
    out["wall_ratio"] = wall / out["estimated_wall_s"][0]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=[2, 6],
        help="seeds of the full campaign (each a pair of checks)",
    )
    ap.add_argument("--results", type=Path, default=Path("/tmp/estres"))
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "estimate_check.json"))
    args = ap.parse_args()
    rows = [
        row
        for seeds in args.seeds
        for row in (
            check("own runs", "est_check", args.results, seeds, 1),
            check("cost model", "est_model", args.results, seeds, None),
        )
    ]
    print(
        f"{'check':10s} {'runs':>4s} {'load':>5s} {'estimated wall (10-90 %)':>28s} "
        f"{'actual':>7s} {'ratio':>5s} {'est. CPU':>8s} {'CPU':>7s}"
    )
    for r in rows:
        w = r["estimated_wall_s"]
        print(
            f"{r['check']:10s} {r['runs']:4d} {r['load_average']:5.1f} "
            f"{w[0]:7.1f} s ({w[1]:6.1f}-{w[2]:6.1f} s) {r['actual_wall_s']:6.1f}s "
            f"{r['wall_ratio']:5.2f} {r['estimated_cpu_s'][0]:7.1f}s "
            f"{r['actual_cpu_s']:6.1f}s"
        )
    Path(args.out).write_text(
        json.dumps(
            {
                "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "cores": os.cpu_count(),
                "seeds": args.seeds,
                "rows": rows,
            },
            indent=1,
        )
        + "\n"
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
