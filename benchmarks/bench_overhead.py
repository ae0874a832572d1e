"""The machinery's own cost per run for tiny runs: a campaign of 200 runs at 16^2 to t = 0.5
(linear mechanics, 50 activities x 4 seeds) run by the driver on a local dask cluster of 2
workers, against the same 200 runs in a plain Python loop in one process (the model's
``simulate.run``, which builds each run's Dataset, and nothing else). Not a test: the numbers
depend on the machine and its load.

    .venv/bin/python benchmarks/bench_overhead.py                 # 3 rounds
    .venv/bin/python benchmarks/bench_overhead.py --rounds 5 --runs 400

Each round runs, one after the other, the plain loop, the campaign with its runs grouped into
tasks as ``execution.runs_per_task: auto`` groups them (the default), and the campaign with one
run per task (``runs_per_task: 1``), so that the machine's drift falls on all three alike; the
table gives each round's times and the ratios campaign / loop of the same round, then their
median, min and max. A campaign's time is ``run_campaign`` from its call to its return:
waiting for the workers, their warm-up (the kernels loaded), every run written (run file and
record) and every record in the catalogue; its runs' time (``runs_s``) from the submission of
the first run to the driver's taking of the last record; the cluster's start and close are
apart. The loop's
first run (the kernels loaded) is not timed. Work counted: runs, dask tasks (the driver's
grouping for the cluster's threads), run files and records on disk, catalogue rows. Writes
``benchmarks/bench_overhead.json`` (``--out``).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

from nematic_solids.model.simulate import run as simulate
from nematic_solids.sweep.catalogue.opening import open_catalogue
from nematic_solids.sweep.catalogue.recorder import known_runs
from nematic_solids.sweep.expand import Expansion, expand
from nematic_solids.sweep.run.clusters import open_cluster
from nematic_solids.sweep.run.driver import run_campaign
from nematic_solids.sweep.run.group import tasks_of
from nematic_solids.sweep.run.todo import plan_runs
from nematic_solids.sweep.spec import parse_campaign
from nematic_solids.sweep.store import CampaignStore

HERE = Path(__file__).resolve().parent

CAMPAIGN = """\
name: tiny
parameters: {{noise_modes: 4}}
numerics: {{mechanics: linear, resolution: 16, t_final: 0.5}}
sweep:
  axes:
    alpha_minus_B: {{linspace: [0.1, 1.0, {points}]}}
seeds: 4
execution: {{workers: {workers}, runs_per_task: {per_task}}}
"""


def campaign(points: int, workers: int, per_task: str) -> Expansion:
    text = CAMPAIGN.format(points=points, workers=workers, per_task=per_task)
    return expand(parse_campaign(text))


def plain_loop(expansion: Expansion) -> float:
    """The runs one after the other in this process (the first, untimed, loads the kernels)."""
    runs = [expansion.run(i) for i in range(len(expansion))]
    simulate(runs[0].point.parameters, runs[0].point.numerics, runs[0].seed)
    t0 = time.perf_counter()
    for r in runs:
        simulate(r.point.parameters, r.point.numerics, r.seed)
    return time.perf_counter() - t0


class Clock:
    """The driver's events, timed: the workers warmed, the runs submitted, the last record."""

    def __init__(self) -> None:
        self.t_started = self.t_last = self.warmed_s = 0.0

    def dashboard(self, link: str | None) -> None: ...

    def warming(self) -> None: ...

    def warmed(self, infos: list[dict[str, Any]], seconds: float) -> None:
        self.warmed_s = seconds

    def started(self, plan: Any, total: int, workers: int) -> None:
        self.t_started = time.perf_counter()

    def finished_run(self, run: Any, record: Any) -> None:
        self.t_last = time.perf_counter()


def driven(expansion: Expansion, workers: int) -> dict[str, Any]:
    """The campaign into a fresh results folder on a fresh local cluster."""
    with tempfile.TemporaryDirectory(prefix="bench-overhead-") as tmp:
        store = CampaignStore(tmp, expansion.campaign.name)
        store.ensure()
        plan = plan_runs(expansion, store)
        tasks = len(tasks_of(expansion, plan.todo, False, workers))
        t0 = time.perf_counter()
        with open_cluster(expansion.campaign.execution) as link:
            t1 = time.perf_counter()
            clock = Clock()
            summary = run_campaign(expansion, store, link, plan, clock)
            t2 = time.perf_counter()
        t3 = time.perf_counter()
        catalogue = open_catalogue(store.results_root)
        try:
            rows = len(known_runs(catalogue, expansion.campaign.name))
        finally:
            catalogue.close()
        return {
            "campaign_s": t2 - t1,
            "warm_up_s": clock.warmed_s,
            "runs_s": clock.t_last - clock.t_started,
            "cluster_start_s": t1 - t0,
            "cluster_close_s": t3 - t2,
            "runs_ok": summary.ok,
            "failed": len(summary.failed),
            "tasks": tasks,
            "run_files": len(list(store.runs_dir.glob("*.nc"))),
            "records": len(list(store.runs_dir.glob("*.json"))),
            "catalogue_rows": rows,
            "sum_of_run_times_s": summary.run_time,
        }


def spread(values: list[float]) -> dict[str, float]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--runs", type=int, default=200, help="a multiple of 4 (seeds)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=HERE / "bench_overhead.json")
    args = parser.parse_args()
    points = max(1, args.runs // 4)
    grouped = campaign(points, args.workers, "auto")
    alone = campaign(points, args.workers, "1")
    rounds = []
    for k in range(args.rounds):
        row: dict[str, Any] = {"round": k + 1, "loop_s": plain_loop(grouped)}
        row["grouped"] = driven(grouped, args.workers)
        row["one_per_task"] = driven(alone, args.workers)
        row["ratio_grouped"] = row["grouped"]["campaign_s"] / row["loop_s"]
        row["ratio_one_per_task"] = row["one_per_task"]["campaign_s"] / row["loop_s"]
        row["runs_ratio_grouped"] = row["grouped"]["runs_s"] / row["loop_s"]
        row["runs_ratio_one_per_task"] = row["one_per_task"]["runs_s"] / row["loop_s"]
        rounds.append(row)
        print(
            f"round {k + 1}: loop {row['loop_s']:.2f} s, grouped "
            f"{row['grouped']['campaign_s']:.2f} s ({row['grouped']['tasks']} tasks, "
            f"x{row['ratio_grouped']:.2f}), one per task "
            f"{row['one_per_task']['campaign_s']:.2f} s ({row['one_per_task']['tasks']} tasks, "
            f"x{row['ratio_one_per_task']:.2f})",
            flush=True,
        )
    summary = {
        "loop_s": spread([r["loop_s"] for r in rounds]),
        "grouped_s": spread([r["grouped"]["campaign_s"] for r in rounds]),
        "one_per_task_s": spread([r["one_per_task"]["campaign_s"] for r in rounds]),
        "ratio_grouped": spread([r["ratio_grouped"] for r in rounds]),
        "ratio_one_per_task": spread([r["ratio_one_per_task"] for r in rounds]),
        "grouped_runs_s": spread([r["grouped"]["runs_s"] for r in rounds]),
        "one_per_task_runs_s": spread([r["one_per_task"]["runs_s"] for r in rounds]),
        "runs_ratio_grouped": spread([r["runs_ratio_grouped"] for r in rounds]),
        "runs_ratio_one_per_task": spread([r["runs_ratio_one_per_task"] for r in rounds]),
        "grouped_warm_up_s": spread([r["grouped"]["warm_up_s"] for r in rounds]),
    }
    n = len(grouped)
    print()
    print(f"{n} runs, 16^2 linear to t = 0.5, {args.workers} workers, {args.rounds} rounds")
    print(f"{'':<28}{'median':>9}{'min':>9}{'max':>9}")
    for key, value in summary.items():
        unit = "" if "ratio" in key else " s"
        print(f"{key + unit:<28}{value['median']:>9.2f}{value['min']:>9.2f}{value['max']:>9.2f}")
    g, o = rounds[-1]["grouped"], rounds[-1]["one_per_task"]
    for name, w in (("grouped", g), ("one per task", o)):
        print(
            f"{name}: {w['runs_ok']} runs ok, {w['tasks']} tasks, {w['run_files']} run files, "
            f"{w['records']} records, {w['catalogue_rows']} catalogue rows; cluster start "
            f"{w['cluster_start_s']:.1f} s, close {w['cluster_close_s']:.1f} s"
        )
    per_run = {
        "grouped_ms": 1000 * (summary["grouped_s"]["median"] * args.workers) / n,
        "one_per_task_ms": 1000 * (summary["one_per_task_s"]["median"] * args.workers) / n,
        "loop_ms": 1000 * summary["loop_s"]["median"] / n,
    }
    print(
        "per run (campaign time x workers / runs): grouped {grouped_ms:.0f} ms, one per task "
        "{one_per_task_ms:.0f} ms; loop {loop_ms:.0f} ms".format(**per_run)
    )
    commit = subprocess.run(
        ["git", "-C", str(HERE), "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    out = {
        "command": "python benchmarks/bench_overhead.py "
        f"--rounds {args.rounds} --runs {args.runs} --workers {args.workers}",
        "machine": platform.node(),
        "git_commit": commit,
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "load_average": list(__import__("os").getloadavg()),
        "runs": n,
        "summary": summary,
        "per_run": per_run,
        "rounds": rounds,
    }
    args.out.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
