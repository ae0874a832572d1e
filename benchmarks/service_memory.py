"""Does the service's memory stay bounded over a day's campaigns? A real ``nematic serve`` (a
subprocess) is driven through many small campaigns, each under its own name (so each leaves its
own folder, queue entry and page behind), as a lab's day would: per campaign, a submission it
runs (2 points x 2 seeds of 16^2 to t = 0.5 on the warm workers), submissions cancelled while
queued, event streams (``/api/events``) opened and dropped, and the pages a dashboard asks
for (the campaign list, the campaign's page and its updates, a point's runs, a run). After
each campaign the service process's resident memory (``VmRSS``), its threads and open file
descriptors are sampled (the workers are other processes: not counted).

Prints the samples and writes ``benchmarks/service_memory.json`` with the growth per campaign
over the second half (the first half warms imports, caches and the cluster). Not a test: the
numbers depend on the machine and its load.

    python benchmarks/service_memory.py [--campaigns 60]     # about 10 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_service import start_service  # noqa: E402

CAMPAIGN = """\
name: {name}
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: 0.5, save_every: 0.25, mechanics: linear}}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2]
seeds: 2
execution: {{workers: 2}}
"""


def proc_status(pid: int) -> dict[str, float]:
    out: dict[str, float] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            out[key] = int(value.split()[0]) / 1024  # MiB
        elif key == "Threads":
            out[key] = int(value)
    out["fds"] = len(os.listdir(f"/proc/{pid}/fd"))
    return out


def growth(samples: list[dict[str, Any]]) -> dict[str, Any]:
    """RSS at the start, half way and the end; over the second half (the first warms imports,
    caches and the cluster): the least-squares slope per campaign and the range."""
    import numpy as np

    half = samples[len(samples) // 2 :]
    x = np.array([s["campaigns"] for s in half], dtype=float)
    y = np.array([s["VmRSS"] for s in half], dtype=float)
    slope = float(np.polyfit(x, y, 1)[0]) if len(half) > 1 else float("nan")
    return {
        "rss_start_mib": samples[0]["VmRSS"],
        "rss_half_mib": half[0]["VmRSS"],
        "rss_end_mib": half[-1]["VmRSS"],
        "rss_peak_mib": max(s["VmHWM"] for s in samples),
        "rss_second_half_range_mib": [float(y.min()), float(y.max())],
        "rss_slope_second_half_kib_per_campaign": 1024 * slope,
        "threads_half_end": [half[0]["Threads"], half[-1]["Threads"]],
        "fds_half_end": [half[0]["fds"], half[-1]["fds"]],
    }


def events(url: str, headers: dict[str, str], n: int) -> None:
    """Open ``n`` event streams, read each one's first event, drop them."""
    for _ in range(n):
        with httpx.stream("GET", url + "api/events", headers=headers, timeout=30) as r:
            for line in r.iter_lines():
                if line.startswith("data:"):
                    break


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=60)
    parser.add_argument("--cancelled", type=int, default=3, help="per campaign")
    parser.add_argument("--streams", type=int, default=5, help="per campaign")
    parser.add_argument("--out", type=Path, default=HERE / "service_memory.json")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="service-memory-"))
    root = folder / "results"
    proc, log, url, headers = start_service(root, folder / "serve.log")
    client = httpx.Client(base_url=url, headers=headers, timeout=60)
    samples: list[dict[str, Any]] = [{"campaigns": 0, "t_s": 0.0, **proc_status(proc.pid)}]
    t0 = time.monotonic()
    states: dict[str, int] = {}
    try:
        for k in range(args.campaigns):
            name = f"day{k:03d}"
            source = str(folder / f"{name}.yaml")
            body = {"text": CAMPAIGN.format(name=name), "source": source}
            entry = client.post("/api/queue", json=body).json()
            for j in range(args.cancelled):  # queued behind it, then cancelled
                other = {"text": CAMPAIGN.format(name=f"{name}_x{j}"), "source": source}
                queued = client.post("/api/queue", json=other).json()
                client.post(f"/api/queue/{queued['id']}/cancel")
            seq: int | None = None
            while True:
                state = next(
                    e["state"]
                    for e in client.get("/api/queue").json()["entries"]
                    if e["id"] == entry["id"]
                )
                client.get("/api/campaigns")
                if (root / name / "campaign.yaml").exists():
                    page = client.get(
                        f"/api/campaigns/{name}" + ("" if seq is None else f"?since={seq}")
                    ).json()
                    seq = page["seq"]
                if state in ("done", "failed", "cancelled"):
                    break
                time.sleep(0.2)
            states[state] = states.get(state, 0) + 1
            events(url, headers, args.streams)
            page = client.get(f"/api/campaigns/{name}").json()
            runs = client.get(f"/api/campaigns/{name}/points/0").json()["runs"]
            done = [r for r in runs if r["status"] != "pending"]
            if done:
                client.get(f"/api/campaigns/{name}/runs/{done[0]['run_id']}")
            sample = {
                "campaigns": k + 1,
                "t_s": time.monotonic() - t0,
                **proc_status(proc.pid),
            }
            samples.append(sample)
            print(
                f"{sample['campaigns']:4d} {sample['t_s']:7.1f} s  RSS {sample['VmRSS']:7.1f} MiB"
                f"  threads {sample['Threads']:3.0f}  fds {sample['fds']:4.0f}",
                flush=True,
            )
    finally:
        client.close()
        os.kill(proc.pid, signal.SIGTERM)
        proc.wait(timeout=120)
    out = {
        "what": "the service process's memory over many small campaigns, streams and pages",
        "command": f"python benchmarks/service_memory.py --campaigns {args.campaigns}",
        "campaigns": args.campaigns,
        "per_campaign": {
            "cancelled_submissions": args.cancelled,
            "event_streams": args.streams,
            "runs": 4,
        },
        "states": states,
        **growth(samples),
        "samples": samples,
        "machine": {
            "cpus": os.cpu_count(),
            "load_1min": os.getloadavg()[0],
            "python": platform.python_version(),
        },
    }
    print(json.dumps({k: v for k, v in out.items() if k != "samples"}, indent=1))
    args.out.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
