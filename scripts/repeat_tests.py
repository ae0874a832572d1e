"""Run tests again and again, each time in a fresh pytest process, and count how often each
passes: the check that a process-level test (killed drivers and workers, detached drivers,
corrupt files, full disks, SLURM jobs) does not race.

    .venv/bin/python scripts/repeat_tests.py [-n 10] [--json FILE] [--no-table] [NODE_ID ...]
    .venv/bin/python scripts/repeat_tests.py --faults -n 3     # the fault tests (FAULT_TESTS)

Without node ids it repeats the default suite's process-level tests (:data:`PROCESS_TESTS`);
``--faults`` the fault tests of issue classes SIGKILL during chains, corrupt checkpoints, a full
disk, two drivers (:data:`FAULT_TESTS`); ``-m slurm`` node ids need the one-node SLURM of
scripts/slurm_local.sh (the tests start it). Prints one line per test (passes of runs, the median
seconds, the failures' last lines); with ``--json``, writes the counts and the failures' last
lines (:data:`KEPT_LINES`). Unless ``--no-table``, the counts go into the repository's repeat
table, :data:`TABLE` (one row per test: its latest counts, with the date, the commit, and the
machine's load and cores when they were taken; rows of other tests kept), rendered as
:data:`TABLE_MD`.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the repeat table: the latest counts of each test repeated (written by this tool only)
TABLE = ROOT / "tests" / "repeats.json"
#: the same table for reading (Markdown, rendered from :data:`TABLE`)
TABLE_MD = ROOT / "tests" / "repeats.md"

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


#: the fault tests: random SIGKILL during chains (and of drivers and workers), corrupt
#: checkpoints and run files, a full disk, two drivers on one folder, memory exhausted under an
#: address-space limit (while a campaign file is read, in a run)
FAULT_TESTS = (
    "tests/sweep/test_chains.py::test_a_chain_driver_killed_at_random_moments_ends_as_an_uninterrupted_one",
    "tests/sweep/test_chains.py::test_a_chain_driver_killed_half_way_resumes",
    "tests/sweep/test_continuation.py::test_a_worker_killed_at_random_points_resumes_exactly",
    "tests/sweep/test_continuation.py::test_a_corrupt_or_foreign_checkpoint_is_ignored_with_a_warning",
    "tests/sweep/test_identity_coverage.py::test_a_parent_state_that_cannot_be_used_fails_the_run_with_its_reason",
    "tests/sweep/test_faults.py::test_a_corrupt_run_file_is_reported_and_redone",
    "tests/sweep/test_faults.py::test_a_full_disk_keeps_the_result_elsewhere_and_a_rerun_moves_it_in",
    "tests/sweep/test_execute.py::test_a_second_driver_is_refused",
    "tests/sweep/test_execute.py::test_two_driver_processes_on_one_folder",
    "tests/sweep/test_hostile_limits.py::test_a_real_memory_error_while_reading_a_campaign_names_the_file",
    "tests/sweep/test_hostile_limits.py::test_a_real_memory_error_in_a_run_is_recorded_with_the_run_and_what_it_needed",
)

#: Lines of a failed run's output kept in ``--json`` (enough for its traceback).
KEPT_LINES = 80


def run_once(node: str, marker: str) -> tuple[bool | None, float, str]:
    """One pytest process for ``node``: (passed, or None when it was skipped; seconds; its
    last :data:`KEPT_LINES` lines)."""
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-m", marker, node],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    lines = (proc.stdout + proc.stderr).strip().splitlines()
    tail = "\n".join(lines[-KEPT_LINES:])
    summary = lines[-1] if lines else ""
    if proc.returncode == 0 and "skipped" in summary and "passed" not in summary:
        return None, time.monotonic() - t0, tail  # not run here: no pass
    return proc.returncode == 0, time.monotonic() - t0, tail


def machine() -> dict[str, object]:
    """The date, the commit and the machine's state for the table's rows."""
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    dirty = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    ).stdout.strip()
    return {
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit + ("+changes" if dirty else ""),
        "load": round(os.getloadavg()[0], 2),
        "cores": os.cpu_count() or 1,
    }


def write_table(rows: dict[str, dict[str, object]]) -> None:
    """Merge ``rows`` (node -> counts) into :data:`TABLE` and render :data:`TABLE_MD`."""
    table = json.loads(TABLE.read_text()) if TABLE.exists() else {}
    table.update(rows)
    table = dict(sorted(table.items()))
    TABLE.write_text(json.dumps(table, indent=1) + "\n")
    lines = [
        "# Repeated process-level tests",
        "",
        "Written by `scripts/repeat_tests.py` (do not edit): each test run again and again in a",
        "fresh pytest process; its latest counts, when and where they were taken (the 1-minute",
        "load average at the start, and the cores).",
        "",
        "| test | passed / runs | skipped | median s | date | commit | load / cores |",
        "|---|---|---|---|---|---|---|",
    ]
    for node, r in table.items():
        lines.append(
            f"| `{node}` | {r['passed']} / {r['runs']} | {r.get('skipped', 0)} "
            f"| {float(str(r['median_seconds'])):.0f} "
            f"| {r['date']} | {r['commit']} | {r['load']} / {r['cores']} |"
        )
    TABLE_MD.write_text("\n".join(lines) + "\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("nodes", nargs="*", help="pytest node ids (default: PROCESS_TESTS)")
    ap.add_argument("-n", type=int, default=10, help="runs of each (default 10)")
    ap.add_argument("--marker", default="", help="pytest -m expression ('' runs any marker)")
    ap.add_argument("--json", type=Path, help="write the counts here")
    ap.add_argument("--faults", action="store_true", help="repeat FAULT_TESTS")
    ap.add_argument("--no-table", action="store_true", help=f"leave {TABLE.name} as it is")
    args = ap.parse_args()
    nodes = args.nodes or list(FAULT_TESTS if args.faults else PROCESS_TESTS)
    marker = args.marker or "slow or not slow"  # every test, whatever its marks
    out = {}
    failed_any = False
    for node in nodes:
        where = machine()
        results = [run_once(node, marker) for _ in range(args.n)]
        passed = sum(ok is True for ok, _, _ in results)
        skipped = sum(ok is None for ok, _, _ in results)
        seconds = statistics.median(s for _, s, _ in results)
        failures = [tail for ok, _, tail in results if ok is False]
        failed_any |= bool(failures)
        extra = f", {skipped} skipped" if skipped else ""
        print(f"{passed}/{args.n} passed{extra}, median {seconds:.0f} s: {node}", flush=True)
        for tail in failures[:3]:
            last = "\n".join(tail.splitlines()[-3:])
            print("    " + last.replace("\n", "\n    "), flush=True)
        out[node] = {
            "runs": args.n,
            "passed": passed,
            "skipped": skipped,
            "median_seconds": seconds,
            "failures": failures,
            **where,
        }
        if not args.no_table:  # after each test: a long session keeps what it measured
            write_table({node: {k: v for k, v in out[node].items() if k != "failures"}})
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 1 if failed_any else 0


if __name__ == "__main__":
    sys.exit(main())
