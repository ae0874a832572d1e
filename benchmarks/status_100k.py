"""How fast is ``nematic status`` on a 100,000-run campaign? (a benchmark, not a test)

Builds a synthetic results folder for a 2,000-point x 50-seed campaign: per-run records
(90 % ok, 2 % failed, the rest pending) and empty stand-ins for the run files (status never
opens them), then times the status computation cold (no manifest: every record is read) and
warm (the manifest written by the first call is used), plus the CLI end to end.

    python benchmarks/status_100k.py [--keep DIR]

Prints a table and writes benchmarks/status_100k.json.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.files import dumps
from nematic_solids.sweep.outputs.status import campaign_status
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.store import CampaignStore

CAMPAIGN = """\
name: big
description: synthetic 100,000-run campaign for the status benchmark
numerics: {resolution: 128, t_final: 300}
sweep:
  axes:
    chi: {linspace: [1, 20, 20]}
    K: {logspace: [-5, -2, 10]}
    eps: {linspace: [0, 0.2, 10]}
seeds: 50
"""


#: The checksum of the (empty) stand-in run files.
EMPTY_SHA256 = hashlib.sha256(b"").hexdigest()


def build(folder: Path) -> tuple[Path, int]:
    path = folder / "big.yaml"
    path.write_text(CAMPAIGN)
    campaign = load_campaign(path)
    expansion = expand(campaign)
    store = CampaignStore(folder / "results", campaign.name)
    store.ensure()
    rng = np.random.default_rng(0)
    draw = rng.random(len(expansion))
    for i, rid in enumerate(expansion.run_ids):
        if draw[i] > 0.92:
            continue  # pending
        ok = draw[i] < 0.90
        record = {
            "run_id": rid,
            "status": "ok" if ok else "failed",
            "reason": "" if ok else "ellipticity_lost",
            "detail": "",
            "t_failed": None,
            "traceback": "",
            "seed": expansion.seeds[i % len(expansion.seeds)],
            "wall_time": float(rng.uniform(5, 15)),
            "nc_bytes": 0,
            "scalars": {"sigma2_S_final": float(rng.random())},
            "code_version": "0.1.0",
            "git_commit": "synthetic",
            "finished": "2026-01-01T00:00:00+00:00",
        }
        nc = store.runs_dir / f"{rid}.nc"
        nc.touch()
        record.update(nc_mtime_ns=nc.stat().st_mtime_ns, nc_sha256=EMPTY_SHA256)
        (store.runs_dir / f"{rid}.json").write_text(dumps(record))
    return path, len(expansion)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="build the folder here and keep it")
    args = parser.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="status100k-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        t = time.perf_counter()
        path, n = build(folder)
        t_build = time.perf_counter() - t
        rows = {}
        for label in ("cold (no manifest)", "warm (manifest)"):
            t = time.perf_counter()
            campaign = load_campaign(path)
            expansion = expand(campaign)
            t_expand = time.perf_counter() - t
            report = campaign_status(expansion, CampaignStore(folder / "results", "big"))
            rows[label] = {
                "total_s": time.perf_counter() - t,
                "expand_s": t_expand,
                "done": report.done,
                "failed": report.failed,
                "pending": report.pending,
            }
        t = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "nematic_solids.sweep",
                "status",
                str(path),
                "--results",
                str(folder / "results"),
            ],
            check=True,
            capture_output=True,
        )
        rows["CLI end to end (warm)"] = {"total_s": time.perf_counter() - t}
        print(f"status of a {n:,}-run campaign (synthetic folder built in {t_build:.0f} s)")
        print(f"{'case':<24}{'seconds':>10}{'expand+hash':>14}")
        for label, row in rows.items():
            print(f"{label:<24}{row['total_s']:>10.2f}{row.get('expand_s', float('nan')):>14.2f}")
        out = Path(__file__).with_suffix(".json")
        out.write_text(json.dumps({"runs": n, "results": rows}, indent=2) + "\n")
        print(f"wrote {out}")
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
