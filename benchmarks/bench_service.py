"""How soon the dashboard hears of a finished run: a real ``nematic serve`` runs a campaign of
tiny runs while this script listens to its event stream (``/api/events``, as the page does)
and watches the campaign's run records appear. For each run: the delay from its record file
(written by the worker) to the first event whose catalogue ``seq`` covers it, and to the answer
of ``/api/changes`` that lists it. Prints the figures and writes them to
``benchmarks/bench_service.json``. Not a test: the numbers depend on the machine and its load.

    .venv/bin/python benchmarks/bench_service.py --points 3 --seeds 2   # about two minutes
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx

from nematic_solids.sweep.service.paths import ServicePaths

HERE = Path(__file__).resolve().parent
CAMPAIGN = """\
name: latency
description: the service's event latency
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: {t_final}, save_every: 0.25, mechanics: linear}}
sweep:
  axes:
    alpha_minus_B: {values}
seeds: {seeds}
execution: {{workers: {workers}}}
"""


def start_service(root: Path, log_path: Path) -> tuple[subprocess.Popen[bytes], Any, str, dict]:
    """``nematic serve ROOT`` in its own session, its output in ``log_path``; waits until it
    answers and returns the process, the open log, its URL and the token's header."""
    log = open(log_path, "wb")  # noqa: SIM115 - open while the service runs
    proc = subprocess.Popen(
        [sys.executable, "-m", "nematic_solids.sweep", "serve", str(root), "--port", "0"],
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    paths = ServicePaths(root)
    while paths.running() is None:
        if proc.poll() is not None:
            raise SystemExit(log_path.read_text())
        time.sleep(0.05)
    info = paths.running()
    assert info is not None
    return proc, log, info["url"], {"Authorization": f"token {paths.read_token()}"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=6)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--t-final", type=float, default=2.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=HERE / "bench_service.json")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench-service-"))
    root = folder / "results"
    values = [round(0.1 + 0.1 * i, 3) for i in range(args.points)]
    path = folder / "latency.yaml"
    path.write_text(
        CAMPAIGN.format(t_final=args.t_final, values=values, seeds=args.seeds, workers=args.workers)
    )
    proc, log, url, headers = start_service(root, folder / "serve.log")
    events: list[tuple[float, int]] = []
    stop = threading.Event()

    def listen() -> None:
        with httpx.stream("GET", url + "api/events", headers=headers, timeout=None) as r:
            for line in r.iter_lines():
                if line.startswith("data:"):
                    events.append((time.monotonic(), int(json.loads(line[5:])["seq"])))
                if stop.is_set():
                    return

    threading.Thread(target=listen, daemon=True).start()
    seen: dict[str, float] = {}
    listed: dict[str, float] = {}
    runs = root / "latency" / "runs"
    try:
        # a new connection per request: the delays measured include no pooled connection
        client = httpx.Client(
            base_url=url,
            headers=headers,
            timeout=30,
            limits=httpx.Limits(max_keepalive_connections=0),
        )
        body = {"text": path.read_text(), "source": str(path)}
        entry = client.post("/api/queue", json=body).json()
        total = args.points * args.seeds
        since = 0
        while len(listed) < total:
            now = time.monotonic()
            if runs.is_dir():
                for p in runs.glob("*.json"):
                    seen.setdefault(p.stem, now)
            page = client.get(f"/api/changes?since={since}").json()
            for r in page["runs"]:
                listed.setdefault(r["run_id"], time.monotonic())
            since = page["seq"]
            time.sleep(0.01)
        seqs = {r["run_id"]: r["seq"] for r in client.get("/api/changes?since=0").json()["runs"]}
        while client.get("/api/queue").json()["entries"][0]["state"] == "running":
            time.sleep(0.2)
        state = next(
            e for e in client.get("/api/queue").json()["entries"] if e["id"] == entry["id"]
        )
    finally:
        stop.set()
        os.kill(proc.pid, signal.SIGTERM)
        proc.wait(timeout=120)
    event_delay = []
    for run_id, t0 in seen.items():
        t_event = next((t for t, s in events if s >= seqs[run_id]), None)
        if t_event is not None:
            event_delay.append(t_event - t0)
    listed_delay = [listed[r] - seen[r] for r in seen if r in listed]

    def summary(xs: list[float]) -> dict[str, float]:
        xs = sorted(xs)
        return {
            "n": len(xs),
            "median_s": statistics.median(xs),
            "p90_s": xs[int(0.9 * (len(xs) - 1))],
            "max_s": xs[-1],
        }

    out: dict[str, Any] = {
        "what": "delay from a run's record file to the service's event and to /api/changes",
        "command": f"python benchmarks/bench_service.py --points {args.points} "
        f"--seeds {args.seeds}",
        "runs": total,
        "campaign": {
            "points": args.points,
            "seeds": args.seeds,
            "t_final": args.t_final,
            "resolution": 16,
            "workers": args.workers,
        },
        "state": state["state"],
        "record_to_event": summary(event_delay),
        "record_to_changes": summary(listed_delay),
        "machine": {
            "cpus": os.cpu_count(),
            "load_1min": os.getloadavg()[0],
            "python": platform.python_version(),
        },
    }
    print(json.dumps(out, indent=1))
    args.out.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
