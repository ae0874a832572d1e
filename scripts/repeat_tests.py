"""Run tests again and again, each time in a fresh pytest process, and count how often each
passes: the check that a process-level test (killed drivers and workers, detached drivers,
SLURM jobs) does not race.

    .venv/bin/python scripts/repeat_tests.py [-n 10] [--json FILE] [NODE_ID ...]

Without node ids it repeats the default suite's process-level tests (:data:`PROCESS_TESTS`);
``-m slurm`` node ids need the one-node SLURM of scripts/slurm_local.sh (the tests start it).
Prints one line per test (passes of runs, the median seconds, the failures' last lines) and,
with ``--json``, writes the counts and the failures' last lines (:data:`KEPT_LINES`).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: the default suite's tests that kill, signal or detach real processes
PROCESS_TESTS = (
    "tests/sweep/test_execute.py::test_sigkill_of_the_driver_then_resume",
    "tests/sweep/test_execute.py::test_ctrl_c_stops_cleanly",
    "tests/sweep/test_continuation.py::test_a_worker_killed_at_random_points_resumes_exactly",
    "tests/sweep/test_continuation.py::test_sigkill_of_the_driver_and_its_workers_then_resume",
    "tests/sweep/test_detach.py::test_a_detached_driver_outlives_its_shell_and_completes",
    "tests/sweep/test_detach.py::test_stop_ends_the_driver_and_leaves_no_run_half_written",
    "tests/sweep/test_quiet_shutdown.py::test_a_campaign_that_succeeds_under_load_prints_no_traceback",
)


#: Lines of a failed run's output kept in ``--json`` (enough for its traceback).
KEPT_LINES = 80


def run_once(node: str, marker: str) -> tuple[bool, float, str]:
    """One pytest process for ``node``: (passed, seconds, its last :data:`KEPT_LINES` lines)."""
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-m", marker, node],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    tail = "\n".join((proc.stdout + proc.stderr).strip().splitlines()[-KEPT_LINES:])
    return proc.returncode == 0, time.monotonic() - t0, tail


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("nodes", nargs="*", help="pytest node ids (default: PROCESS_TESTS)")
    ap.add_argument("-n", type=int, default=10, help="runs of each (default 10)")
    ap.add_argument("--marker", default="", help="pytest -m expression ('' runs any marker)")
    ap.add_argument("--json", type=Path, help="write the counts here")
    args = ap.parse_args()
    nodes = args.nodes or list(PROCESS_TESTS)
    marker = args.marker or "slow or not slow"  # every test, whatever its marks
    out = {}
    failed_any = False
    for node in nodes:
        results = [run_once(node, marker) for _ in range(args.n)]
        passed = sum(ok for ok, _, _ in results)
        seconds = statistics.median(s for _, s, _ in results)
        failures = [tail for ok, _, tail in results if not ok]
        failed_any |= bool(failures)
        print(f"{passed}/{args.n} passed, median {seconds:.0f} s: {node}", flush=True)
        for tail in failures[:3]:
            last = "\n".join(tail.splitlines()[-3:])
            print("    " + last.replace("\n", "\n    "), flush=True)
        out[node] = {
            "runs": args.n,
            "passed": passed,
            "median_seconds": seconds,
            "failures": failures,
        }
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 1 if failed_any else 0


if __name__ == "__main__":
    sys.exit(main())
