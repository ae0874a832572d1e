"""Kernel compilation on a fresh clone: ``python -m nematic_solids.model.warmup`` (bootstrap's
compile step) at a base commit and at a new one, alternating (a benchmark).

    .venv/bin/python benchmarks/compile_time.py [--base 289d2d7] [--new HEAD] [--repeats 3]

Clones this repository twice into a temporary folder (``git clone``, then the commit), and
in each runs ``python -m nematic_solids.model.warmup`` with this interpreter (its venv: only the
compilation is measured, not the install), the clone on ``PYTHONPATH``, ``NUMBA_CACHE_DIR`` unset
(so the cache is the clone's own ``model/compiled/__pycache__``), extra arguments from ``--args``.
Each repeat runs base then new (new then base in odd repeats), each with an empty cache (its
``__pycache__`` removed: "cold") and again right after ("warm", the idempotent second call). Reports
each run's wall time, CPU time (user + sys of the process and every process it waited for: the
compiling processes included), their ratio (the cores it kept busy on average), the load average
before it and the kernel signatures compiled (the work, from the command's own report); then medians
and the base/new ratio of each pair. The machine's speed and load drift, so only the pairs compare.

Prints a table and writes benchmarks/compile_time.json.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(
        ["git", *args], cwd=cwd, check=True, capture_output=True, text=True
    ).stdout.strip()


def clone(commit: str, dst: Path) -> str:
    """A fresh clone of this repository at ``commit`` (named here); returns its full hash."""
    full = git("rev-parse", "--verify", f"{commit}^{{commit}}")
    git("clone", "--quiet", "--no-checkout", str(ROOT), str(dst))
    git("checkout", "--quiet", full, cwd=dst)
    return full


def compiled_count(stdout: str) -> int:
    """Kernel signatures compiled, from ``python -m nematic_solids.model.warmup``'s report: those of
    the compiling processes ("N signatures compiled") and of its own process ("N compiled")."""
    return sum(int(n) for n in re.findall(r"\((\d+) (?:signatures )?compiled", stdout))


def warmup(folder: Path, python: str, extra: list[str]) -> dict[str, Any]:
    """Run ``python -m nematic_solids.model.warmup`` in ``folder``; its wall and CPU time and
    report."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(folder)
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [python, "-m", "nematic_solids.model.warmup", *extra],
        cwd=folder,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    assert proc.stdout is not None
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise RuntimeError(f"python -m nematic_solids.model.warmup failed in {folder}:\n{out}")
    cpu = usage.ru_utime + usage.ru_stime
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 2),
        "cores_used": round(cpu / wall, 2),
        "load_before": round(load, 2),
        "compiled": compiled_count(out),
        "output": out.strip().splitlines(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="289d2d7", help="the commit to compare against")
    parser.add_argument("--new", default="HEAD", help="the commit measured (committed code)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--python", default=sys.executable)
    parser.add_argument(
        "--args",
        default="",
        help="extra arguments for the new commit's python -m nematic_solids.model.warmup, "
        "e.g. '--jobs 4'",
    )
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "compile_time.json")
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="compile-time-"))
    try:
        folders = {"base": tmp / "base", "new": tmp / "new"}
        commits = {
            "base": clone(args.base, folders["base"]),
            "new": clone(args.new, folders["new"]),
        }
        extra = {"base": [], "new": args.args.split()}
        runs: list[dict[str, Any]] = []
        for repeat in range(args.repeats):
            for which in ("base", "new") if repeat % 2 == 0 else ("new", "base"):
                shutil.rmtree(
                    folders[which] / "model" / "compiled" / "__pycache__", ignore_errors=True
                )
                for state in ("cold", "warm"):
                    row = {
                        "repeat": repeat,
                        "commit": which,
                        "cache": state,
                        **warmup(folders[which], args.python, extra[which]),
                    }
                    runs.append(row)
                    print(
                        f"repeat {repeat} {which:4s} {state}: {row['wall_s']:7.1f} s wall "
                        f"{row['cpu_s']:7.1f} s CPU ({row['cores_used']:.2f} cores), "
                        f"{row['compiled']:3d} compiled (load {row['load_before']:.1f})",
                        flush=True,
                    )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    def pick(which: str, state: str, key: str) -> list[float]:
        return [r[key] for r in runs if r["commit"] == which and r["cache"] == state]

    summary: dict[str, Any] = {}
    for state in ("cold", "warm"):
        for which in ("base", "new"):
            summary[f"{which}_{state}"] = {
                key: statistics.median(pick(which, state, key))
                for key in ("wall_s", "cpu_s", "cores_used", "compiled")
            }
        summary[f"wall_ratio_base_over_new_{state}"] = [
            round(b / n, 2)
            for b, n in zip(
                pick("base", state, "wall_s"), pick("new", state, "wall_s"), strict=True
            )
        ]
    print("median      cold wall   cold CPU   cores   compiled   warm wall")
    for which in ("base", "new"):
        c, w = summary[f"{which}_cold"], summary[f"{which}_warm"]
        print(
            f"{which:4s} {commits[which][:7]}  {c['wall_s']:7.1f} s  {c['cpu_s']:7.1f} s  "
            f"{c['cores_used']:5.2f}  {c['compiled']:8.0f}   {w['wall_s']:7.1f} s"
        )
    print(f"cold wall base/new per pair: {summary['wall_ratio_base_over_new_cold']}")
    result = {
        "benchmark": "python -m nematic_solids.model.warmup on a fresh clone (empty kernel "
        "cache), base vs new",
        "command": " ".join([Path(args.python).name, "benchmarks/compile_time.py", *sys.argv[1:]]),
        "commits": commits,
        "new_args": extra["new"],
        "cpus": os.cpu_count(),
        "usable_cpus": len(os.sched_getaffinity(0)),
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "runs": runs,
        "summary": summary,
    }
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
