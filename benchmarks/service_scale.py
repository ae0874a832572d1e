"""The service at scale: a results root whose catalogue holds 100,000 runs in 20 campaigns, one of
them a 100,000-run campaign (the worst case of a campaign page: a 2,000-point x 50-seed grid,
90 % ok, 2 % failed, the rest pending, as ``benchmarks/status_100k.py`` builds it; its 92,075
runs done are recorded, the other 19 campaigns' synthetic rows make up the rest), timed through
the service's own API in process (Starlette's test client: no network, no runner):

- the campaign list (``GET /api/campaigns``);
- the campaign's page (``GET /api/campaigns/big``), the first time (the service builds its view
  of the campaign: its layout, its runs' states from the catalogue, the failed runs' records;
  in three services started one after the other, the median reported) and again;
- 50 runs then recorded (their record files written and the catalogue told, as the driver's
  recorder does), and the page's update after the client's cursor
  (``GET /api/campaigns/big?since=SEQ``): how long, how many points and bytes it sends
  against the whole page's.

Prints the figures with the machine's load and writes ``benchmarks/service_scale.json``. Not a
test: the numbers depend on the machine and its load.

    python benchmarks/service_scale.py [--keep DIR]      # about 3 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from catalogue_scale import rows as other_rows  # noqa: E402
from status_100k import EMPTY_SHA256, build  # noqa: E402

from nematic_solids.sweep.catalogue import open_catalogue  # noqa: E402
from nematic_solids.sweep.catalogue.index import index_root, record_rows  # noqa: E402
from nematic_solids.sweep.files import dumps  # noqa: E402
from nematic_solids.sweep.spec import load_campaign  # noqa: E402
from nematic_solids.sweep.store import CampaignStore  # noqa: E402

TOKEN = "0123456789abcdef" * 3
#: services started, each opening the big campaign's page for the first time
FIRSTS = 3
AUTH = {"Authorization": f"token {TOKEN}"}


def write_small(folder: Path) -> Path:
    path = folder / "small.yaml"
    path.write_text(
        "name: small\nparameters: {noise_modes: 4}\nnumerics: {resolution: 16, t_final: 1}\n"
        "sweep:\n  axes:\n    chi: [1, 2]\nseeds: 2\n"
    )
    return path


def timed(client: Any, url: str) -> tuple[dict[str, Any], float, int]:
    t0 = time.perf_counter()
    r = client.get(url, headers=AUTH)
    seconds = time.perf_counter() - t0
    assert r.status_code == 200, r.text[:500]
    return r.json(), seconds, len(r.content)


def finish_pending(store: CampaignStore, campaign_path: Path, n: int) -> list[str]:
    """Record ``n`` pending runs as ok (their record files; stand-in run files)."""
    from nematic_solids.sweep.expand import expand

    expansion = expand(load_campaign(campaign_path))
    done = {p.stem for p in store.runs_dir.glob("*.json")}
    todo = [rid for rid in expansion.run_ids if rid not in done][:n]
    seeds = {
        rid: expansion.seeds[i % len(expansion.seeds)] for i, rid in enumerate(expansion.run_ids)
    }
    for rid in todo:
        nc = store.runs_dir / f"{rid}.nc"
        nc.touch()
        record = {
            "run_id": rid,
            "status": "ok",
            "reason": "",
            "seed": seeds[rid],
            "wall_time": 10.0,
            "nc_bytes": 0,
            "nc_mtime_ns": nc.stat().st_mtime_ns,
            "nc_sha256": EMPTY_SHA256,
            "scalars": {"sigma2_S_final": 0.5},
            "finished": "2026-01-02T00:00:00+00:00",
        }
        (store.runs_dir / f"{rid}.json").write_text(dumps(record))
    return todo


def main() -> None:
    from fastapi.testclient import TestClient

    from nematic_solids.sweep.campaign_copy import save_campaign_copy
    from nematic_solids.sweep.service.api import ServiceContext, create_app
    from nematic_solids.sweep.service.queue import QueueStore

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="build the folder here and keep it")
    parser.add_argument("--out", type=Path, default=HERE / "service_scale.json")
    args = parser.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="service-scale-"))
    folder.mkdir(parents=True, exist_ok=True)
    figures: dict[str, Any] = {}
    try:
        root = folder / "results"
        t0 = time.perf_counter()
        if not (root / "big" / "runs").is_dir():
            path, n = build(folder)
        else:
            path = folder / "big.yaml"
        store = CampaignStore(root, "big")
        save_campaign_copy(store, load_campaign(path))
        figures["build_s"] = time.perf_counter() - t0
        catalogue = open_catalogue(root)
        t0 = time.perf_counter()
        index_root(catalogue)
        figures["index_s"] = time.perf_counter() - t0
        big = int(catalogue.campaigns().set_index("name").loc["big", "runs"])
        # 19 other campaigns (synthetic rows, no folders) bring the catalogue to 100,000 runs
        extra = other_rows(100_000 - big, 19)
        for k in range(0, len(extra), 2000):
            catalogue.record(extra[k : k + 2000])
        figures["catalogue_runs"] = int(catalogue.campaigns()["runs"].sum())
        figures["campaign_runs_recorded"] = big
        ctx = ServiceContext(
            root, TOKEN, "127.0.0.1", 8765, False, catalogue, QueueStore(catalogue.engine)
        )
        client = TestClient(create_app(ctx), base_url="http://127.0.0.1:8765")
        # a service that has run a while: its modules imported (a small campaign's page)
        small = CampaignStore(root, "small")
        small.ensure()
        save_campaign_copy(small, load_campaign(write_small(folder)))
        timed(client, "/api/campaigns/small")
        import scipy.stats  # noqa: F401 - what a page with seed intervals imports once

        _, figures["campaign_list_s"], _ = timed(client, "/api/campaigns")
        _, figures["campaign_list_again_s"], _ = timed(client, "/api/campaigns")
        # the first open in three services that just started (each builds its view), then
        # the last one's page again: the median of the three, on a machine shared by others
        firsts = []
        for _ in range(FIRSTS):
            ctx = ServiceContext(
                root, TOKEN, "127.0.0.1", 8765, False, catalogue, QueueStore(catalogue.engine)
            )
            client = TestClient(create_app(ctx), base_url="http://127.0.0.1:8765")
            page, seconds, figures["campaign_page_bytes"] = timed(client, "/api/campaigns/big")
            firsts.append(seconds)
        figures["campaign_page_first_runs_s"] = firsts
        figures["campaign_page_first_s"] = statistics.median(firsts)
        figures["campaign_page_points"] = len(page["points"])
        page, figures["campaign_page_again_s"], _ = timed(client, "/api/campaigns/big")
        seq = int(page["seq"])
        todo = finish_pending(store, path, 50)
        catalogue.record(list(record_rows(store, todo)), {"big": "big"})
        delta, figures["campaign_delta_s"], figures["campaign_delta_bytes"] = timed(
            client, f"/api/campaigns/big?since={seq}"
        )
        figures["campaign_delta_points"] = len(delta["points"])
        figures["campaign_delta_is_delta"] = bool(delta.get("delta"))
        figures["runs_recorded_after_cursor"] = len(todo)
        catalogue.close()
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)
    figures["load_average_1min"] = os.getloadavg()[0]  # a shared machine: read with it
    figures["cores"] = os.cpu_count()
    figures["command"] = "python benchmarks/service_scale.py"
    for key, v in figures.items():
        text = f"{v:.4g}" if isinstance(v, float) else str(v)
        if isinstance(v, list):
            text = ", ".join(f"{x:.4g}" for x in v)
        print(f"{key}: {text}")
    args.out.write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
