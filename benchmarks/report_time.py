"""How long does ``nematic report quickstart`` take as a fresh process? (a benchmark, not a
test)

Times N fresh processes of ``python -m nematic_solids.sweep report CAMPAIGN`` (wall, CPU = user +
system, peak RSS: the operating system's accounting of each child, ``os.wait4``), and of ``nematic
--help`` and ``nematic status`` beside it; then one run under ``-X importtime`` gives the import
time by top-level package and which heavy libraries the report imports. It needs a results folder
with the campaign in it (make one with ``nematic run campaigns/quickstart.yaml --results DIR``; that
run's report fills the report's cache of run views, as a user's run does).

The machine's speed drifts (up to 2x on a shared machine): quote medians, look at the load
average printed with them, and compare two versions side by side with ``--compare`` (another
checkout, e.g. ``git worktree add /tmp/old HEAD~3``): the two are run in turn, A B A B, and
the ratio is taken pair by pair.

    python benchmarks/report_time.py --results DIR [--campaign quickstart] [-n 7]
        [--compare OTHER_CHECKOUT]

Prints a table and writes benchmarks/report_time.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Libraries whose import the report's fast path avoids (checked in tests/sweep/test_report.py).
HEAVY = (
    "numba",
    "distributed",
    "dask.array",
    "matplotlib",
    "nematic_solids.model.compiled",
    "scipy",
)


def timed(argv: list[str], checkout: Path) -> dict[str, float]:
    """One fresh process: wall seconds, CPU seconds (user + system), peak RSS in MiB."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    t = time.perf_counter()
    proc = subprocess.Popen(
        argv, env=env, cwd=checkout, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    stderr = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if proc.stderr:
        proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode}):\n{stderr}")
    return {
        "wall_s": wall,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "peak_mib": usage.ru_maxrss / 1024,
    }


def summary(rows: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    return {
        k: {
            "median": statistics.median(r[k] for r in rows),
            "min": min(r[k] for r in rows),
            "max": max(r[k] for r in rows),
        }
        for k in rows[0]
    }


def import_breakdown(argv: list[str], checkout: Path) -> dict[str, object]:
    """One run under ``-X importtime``: the self time of the imports by top-level package
    (seconds, the largest first), their sum, how many modules, and which of :data:`HEAVY`."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    done = subprocess.run(
        [argv[0], "-X", "importtime", *argv[1:]],
        env=env,
        cwd=checkout,
        capture_output=True,
        text=True,
        check=True,
    )
    by_package: Counter[str] = Counter()
    names = set()
    for line in done.stderr.splitlines():
        if not line.startswith("import time:") or "self [us]" in line:
            continue
        self_us, _, name = line.split(":", 1)[1].split("|")
        name = name.strip()
        names.add(name)
        by_package[name.split(".")[0]] += int(self_us)
    return {
        "total_s": sum(by_package.values()) / 1e6,
        "modules": len(names),
        "heavy_imported": [h for h in HEAVY if h in names],
        "by_package_s": {k: v / 1e6 for k, v in by_package.most_common(15)},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--results", type=Path, required=True, help="the results folder holding the campaign"
    )
    parser.add_argument("--campaign", default="quickstart")
    parser.add_argument("-n", type=int, default=7, help="fresh processes per command")
    parser.add_argument("--compare", type=Path, help="another checkout, timed in turn")
    args = parser.parse_args()
    results = args.results.resolve()
    out_html = Path(tempfile.mkdtemp(prefix="report-time-")) / "report.html"
    python = sys.executable
    report = [
        python,
        "-m",
        "nematic_solids.sweep",
        "report",
        args.campaign,
        "--results",
        str(results),
        "--output",
        str(out_html),
    ]
    yaml = results / args.campaign / "campaign.yaml"
    commands = {
        "report": report,
        "--help": [python, "-m", "nematic_solids.sweep", "--help"],
        "status": [
            python,
            "-m",
            "nematic_solids.sweep",
            "status",
            str(yaml),
            "--results",
            str(results),
        ],
    }
    checkouts = {"this": ROOT} | ({"compare": args.compare.resolve()} if args.compare else {})
    load_before = os.getloadavg()
    rows: dict[str, dict[str, list[dict[str, float]]]] = {
        c: {k: [] for k in commands} for c in checkouts
    }
    for command, argv in commands.items():
        for checkout in checkouts.values():
            timed(argv, checkout)  # warm-up: .pyc files, the page cache, the report's cache
        for _ in range(args.n):
            for label, checkout in checkouts.items():  # in turn: A B A B ...
                rows[label][command].append(timed(argv, checkout))
    load_after = os.getloadavg()
    result: dict[str, object] = {
        "campaign": args.campaign,
        "runs_per_command": args.n,
        "load_average_before_after": [round(load_before[0], 2), round(load_after[0], 2)],
        "cpus": os.cpu_count(),
        "this": {k: summary(v) for k, v in rows["this"].items()},
        "imports_of_the_report": import_breakdown(report, ROOT),
    }
    print(
        f"fresh processes, {args.n} each after a warm-up; load average "
        f"{load_before[0]:.1f} -> {load_after[0]:.1f} on {os.cpu_count()} CPUs"
    )
    print(f"{'command':<10}{'checkout':<10}{'wall s':>20}{'cpu s':>8}{'peak MiB':>10}")
    for label in checkouts:
        for command, runs in rows[label].items():
            s = summary(runs)
            print(
                f"{command:<10}{label:<10}{s['wall_s']['median']:>8.2f} "
                f"[{s['wall_s']['min']:.2f}, {s['wall_s']['max']:.2f}]"
                f"{s['cpu_s']['median']:>8.2f}{s['peak_mib']['median']:>10.0f}"
            )
    if args.compare:
        result["compare"] = {
            "checkout": str(args.compare),
            **{k: summary(v) for k, v in rows["compare"].items()},
        }
        ratios = {
            command: {
                k: statistics.median(
                    a[k] / b[k]
                    for a, b in zip(rows["this"][command], rows["compare"][command], strict=True)
                )
                for k in ("wall_s", "cpu_s")
            }
            for command in commands
        }
        result["ratio_this_over_compare"] = ratios
        for command, ratio in ratios.items():
            print(
                f"{command:<10}this / compare, median of pairs: wall {ratio['wall_s']:.2f}, "
                f"cpu {ratio['cpu_s']:.2f}"
            )
    imports = result["imports_of_the_report"]
    assert isinstance(imports, dict)
    print(
        f"the report's imports: {imports['total_s']:.2f} s (self times, one run), "
        f"{imports['modules']} modules; heavy ones imported: "
        f"{', '.join(imports['heavy_imported']) or 'none'}"
    )
    for package, seconds in list(imports["by_package_s"].items())[:10]:
        print(f"  {package:<16}{seconds:>6.2f}")
    out = Path(__file__).with_suffix(".json")
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
