"""Dask overhead of a campaign: wall time vs the sum of the run times (a benchmark).

Runs a campaign (default: campaigns/quickstart.yaml) from scratch into a temporary results
folder on the local dask cluster and reports

- cluster start-up and shut-down time,
- campaign wall time (first submission to last result) and the sum of the runs' own wall
  times divided by the number of workers (the ideal),
- the efficiency ideal / wall and the overhead per run.

    python benchmarks/campaign_overhead.py [CAMPAIGN.yaml] [--workers N] [--set NAME=VALUE]

Prints a table and writes benchmarks/campaign_overhead.json.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.run.driver import dask_client, run_campaign
from nematic_solids.sweep.run.todo import plan_runs
from nematic_solids.sweep.spec import Overrides, load_campaign
from nematic_solids.sweep.spec.yaml_input import parse_assignments
from nematic_solids.sweep.store import CampaignStore

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "campaign", nargs="?", type=Path, default=ROOT / "campaigns" / "quickstart.yaml"
    )
    parser.add_argument("--workers", type=int)
    parser.add_argument("--set", dest="settings", action="append", default=[])
    args = parser.parse_args()
    campaign = load_campaign(
        args.campaign, Overrides(settings=parse_assignments(args.settings), workers=args.workers)
    )
    expansion = expand(campaign)
    with tempfile.TemporaryDirectory(prefix="overhead-") as tmp:
        store = CampaignStore(tmp, campaign.name)
        store.ensure()
        plan = plan_runs(expansion, store)
        t0 = time.perf_counter()
        with dask_client(campaign.execution) as client:
            t_started = time.perf_counter()
            workers = sum(client.nthreads().values())
            summary = run_campaign(expansion, store, client, plan)
            t_done = time.perf_counter()
        t_closed = time.perf_counter()
    ideal = summary.run_time / max(workers, 1)
    row = {
        "campaign": campaign.name,
        "runs": summary.completed,
        "failed": len(summary.failed),
        "workers": workers,
        "cluster_start_s": t_started - t0,
        "cluster_close_s": t_closed - t_done,
        "campaign_wall_s": summary.wall_time,
        "sum_of_run_times_s": summary.run_time,
        "ideal_wall_s": ideal,
        "efficiency": ideal / summary.wall_time if summary.wall_time else float("nan"),
        "overhead_per_run_s": (summary.wall_time - ideal) * workers / max(summary.completed, 1),
        "total_wall_s": t_closed - t0,
    }
    width = max(len(k) for k in row)
    for key, value in row.items():
        text = f"{value:.3g}" if isinstance(value, float) else str(value)
        print(f"{key:<{width}}  {text}")
    out = Path(__file__).with_suffix(".json")
    out.write_text(json.dumps(row, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
