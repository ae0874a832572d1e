"""A campaign page's incremental updates (``GET /api/campaigns/NAME?since=SEQ``, kept by
:mod:`nematic_solids.sweep.service.campaign_view` from the catalogue's change counter): a run
recorded after cursor c is in the update after c and in none after a later cursor; updates
applied one after the other give the page read whole; runs recorded every 50 ms by the
driver's recorder while a client follows them are all shown, none lost; a new layout (more
seeds) sends the whole page; the views kept are bounded."""

from __future__ import annotations

import math
import random
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("fastapi")
from fastapi.testclient import TestClient

from nematic_solids.sweep.campaign_copy import save_campaign_copy
from nematic_solids.sweep.catalogue.recorder import Recorder
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.service.api import ServiceContext, create_app
from nematic_solids.sweep.service.catalogue_link import open_service_database
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.store import CampaignStore

TOKEN = "0123456789abcdef" * 3
AUTH = {"Authorization": f"token {TOKEN}"}
CAMPAIGN = """\
name: grid
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: 0.5, mechanics: linear}}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2, 0.3]
    K: [1.0e-5, 1.0e-4]
    chi: [5.0, 10.0]
seeds: {seeds}
"""


class Folder:
    """A campaign's results folder whose runs the test finishes (records as a worker writes
    them), recorded in the catalogue by the driver's recorder."""

    def __init__(self, tmp: Path, seeds: int = 2):
        self.tmp, self.root = tmp, tmp / "results"
        self.layout(seeds)

    def layout(self, seeds: int) -> None:
        path = self.tmp / "grid.yaml"
        path.write_text(CAMPAIGN.format(seeds=seeds))
        campaign = load_campaign(path)
        self.store = CampaignStore(self.root, "grid")
        self.store.ensure()
        save_campaign_copy(self.store, campaign)
        self.expansion = expand(campaign)
        self.seeds = dict(
            zip(self.expansion.run_ids, [r.seed for r in self.expansion], strict=True)
        )

    def record(self, run_id: str, value: float, status: str = "ok") -> dict:
        rec = {
            "run_id": run_id,
            "status": status,
            "reason": "" if status == "ok" else "nan",
            "detail": "" if status == "ok" else "NaN in the field\nat t = 0.3",
            "t_failed": None if status == "ok" else 0.3,
            "seed": self.seeds[run_id],
            "wall_time": 1.5,
            "scalars": {"sigma2_S_final": value} if status == "ok" else {},
            "finished": "2026-01-01T00:00:00+00:00",
        }
        self.store.write_record(rec, sync_dir=False)
        return rec


def client_for(root: Path) -> tuple[TestClient, ServiceContext]:
    catalogue, queue = open_service_database(root)
    ctx = ServiceContext(root, TOKEN, "127.0.0.1", 8765, False, catalogue, queue)
    return TestClient(create_app(ctx), base_url="http://127.0.0.1:8765"), ctx


def get(client: TestClient, since: int | None = None) -> dict:
    url = "/api/campaigns/grid" + ("" if since is None else f"?since={since}")
    r = client.get(url, headers=AUTH)
    assert r.status_code == 200, r.text
    return r.json()


def merge(page: dict, delta: dict) -> dict:
    """What the dashboard's script does with an update."""
    if not delta["delta"]:
        return delta
    points = {p["index"]: p for p in page["points"]}
    points.update({p["index"]: p for p in delta["points"]})
    failures = {f["run_id"]: f for f in page["failures"]}
    for rid in delta["cleared"]:
        failures.pop(rid, None)
    failures.update({f["run_id"]: f for f in delta["failures"]})
    return {
        **delta,
        "points": sorted(points.values(), key=lambda p: p["index"]),
        "failures": list(failures.values()),
        "delta": False,
        "cleared": [],
    }


def comparable(page: dict) -> dict:
    drop = ("seq", "delta", "cleared", "queue", "estimate", "progress", "layout_seq")
    out = {k: v for k, v in page.items() if k not in drop}
    out["failures"] = sorted(({**f, "seq": 0} for f in page["failures"]), key=lambda f: f["run_id"])
    return out


def fresh(root: Path) -> dict:
    """The page as a service that just started reads it (from the folder alone)."""
    client, ctx = client_for(root)
    try:
        return get(client)
    finally:
        ctx.catalogue.close()


def point_of(page: dict, client: TestClient, run_id: str) -> int:
    for p in page["points"]:
        runs = client.get(f"/api/campaigns/grid/points/{p['index']}", headers=AUTH).json()
        if any(r["run_id"] == run_id for r in runs["runs"]):
            return p["index"]
    raise AssertionError(run_id)


def test_a_run_recorded_after_a_cursor_is_in_the_update_after_it_and_no_other(tmp_path):
    folder = Folder(tmp_path)
    client, ctx = client_for(folder.root)
    ids = folder.expansion.run_ids
    first = get(client)
    assert not first["delta"]
    assert first["counts"] == {"ok": 0, "failed": 0, "pending": len(ids)}
    assert len(first["points"]) == 12
    c0 = first["seq"]
    assert get(client, c0)["points"] == []  # nothing changed
    a, b = ids[0], ids[-1]
    ctx.catalogue.record([_row(folder, folder.record(a, 0.25))])
    after_a = get(client, c0)
    assert after_a["delta"]
    c1 = after_a["seq"]
    assert c1 > c0
    pa = point_of(first, client, a)
    assert [p["index"] for p in after_a["points"]] == [pa]
    assert after_a["points"][0]["mean"] == 0.25
    assert after_a["counts"]["ok"] == 1
    ctx.catalogue.record([_row(folder, folder.record(b, 0.5, status="failed"))])
    after_b = get(client, c1)
    pb = point_of(first, client, b)
    assert [p["index"] for p in after_b["points"]] == [pb] != [pa]  # a is before c1: not sent
    assert [f["run_id"] for f in after_b["failures"]] == [b]
    assert after_b["failures"][0]["reason"] == "nan"
    assert after_b["failures"][0]["t_failed"] == 0.3
    assert sorted(p["index"] for p in get(client, c0)["points"]) == sorted({pa, pb})
    assert get(client, after_b["seq"])["points"] == []
    # b done again, ok: its failure is cleared
    ctx.catalogue.record([_row(folder, folder.record(b, 0.75))])
    again = get(client, after_b["seq"])
    assert again["cleared"] == [b]
    assert again["failures"] == []
    assert comparable(merge(merge(merge(first, after_a), after_b), again)) == comparable(
        fresh(folder.root)
    )
    ctx.catalogue.close()


def _row(folder: Folder, record: dict):
    from nematic_solids.sweep.catalogue.rows import row_from_record

    return row_from_record(record, "grid", None)


def test_runs_recorded_every_50_ms_are_all_shown_none_lost(tmp_path):
    folder = Folder(tmp_path)
    client, ctx = client_for(folder.root)
    page = get(client)
    ids = folder.expansion.run_ids
    values = {rid: 0.01 * (k + 1) for k, rid in enumerate(ids)}

    def finish() -> None:  # as the driver: the worker's record, then the recorder
        with Recorder(folder.store, catch_up=False) as recorder:
            for rid in ids:
                recorder.add(folder.record(rid, values[rid]))
                time.sleep(0.05)

    worker = threading.Thread(target=finish)
    worker.start()
    updates = 0
    while worker.is_alive() or page["counts"]["ok"] < len(ids):
        delta = get(client, page["seq"])
        assert delta["delta"]
        updates += 1
        page = merge(page, delta)
        assert page["counts"]["ok"] + page["counts"]["pending"] == len(ids)
        if not worker.is_alive() and page["counts"]["ok"] < len(ids):
            time.sleep(0.05)  # the recorder's last batch
        assert updates < 10_000
    worker.join()
    assert updates > 3  # followed as it went, not read once at the end
    assert page["counts"] == {"ok": len(ids), "failed": 0, "pending": 0}
    assert comparable(page) == comparable(fresh(folder.root))
    for p in page["points"]:
        runs = client.get(f"/api/campaigns/grid/points/{p['index']}", headers=AUTH).json()["runs"]
        mean = sum(values[r["run_id"]] for r in runs) / len(runs)
        assert p["mean"] == pytest.approx(mean, rel=1e-12)
        assert p["n"] == 2
    assert ctx.views.get("grid").builds == 1  # built once, then followed
    ctx.catalogue.close()


def test_a_new_layout_sends_the_whole_page(tmp_path):
    folder = Folder(tmp_path)
    client, ctx = client_for(folder.root)
    first = get(client)
    folder.layout(seeds=3)  # resubmitted with more seeds
    ctx.catalogue.record([_row(folder, folder.record(folder.expansion.run_ids[0], 0.5))])
    later = get(client, first["seq"])
    assert not later["delta"]
    assert later["total"] == 36
    assert len(later["points"]) == 12
    assert get(client, later["seq"])["delta"]
    ctx.catalogue.close()


def test_the_views_kept_are_bounded(tmp_path):
    from nematic_solids.sweep.service.campaign_view import MAX_VIEWS

    folder = Folder(tmp_path)
    client, ctx = client_for(folder.root)
    for k in range(MAX_VIEWS + 3):
        (folder.root / f"c{k}" / "runs").mkdir(parents=True)
        assert client.get(f"/api/campaigns/c{k}", headers=AUTH).status_code == 200
    assert len(ctx.views) == MAX_VIEWS
    assert client.get("/api/campaigns/grid/points/99", headers=AUTH).status_code == 404
    ctx.catalogue.close()


def recomputed(folder: Folder) -> dict:
    """The page's content computed from the run records alone, run by run (what the view
    must show however it came to it): each point's counts and seed mean with its interval,
    the failures, the cost."""
    from nematic_solids.sweep.service.views import interval, plain

    points: dict[tuple, dict] = {}
    failures, walls, done = [], [], 0
    for run in folder.expansion:
        rec = folder.store.read_record(run.run_id)
        p = points.setdefault(
            run.point.index,
            {
                "index": len(points),
                "coords": {k: plain(v) for k, v in run.point.coords.items()},
                "values": [],
                "ok": 0,
                "failed": 0,
                "pending": 0,
            },
        )
        status = "pending" if rec is None else rec["status"]
        p[status] += 1
        if rec is None:
            continue
        done += 1
        walls.append(rec["wall_time"])
        if status == "ok":
            p["values"].append(rec["scalars"]["sigma2_S_final"])
        else:
            failures.append(
                {
                    "run_id": run.run_id,
                    "coords": {**p["coords"], "seed": run.seed},
                    "reason": rec["reason"],
                    "t_failed": rec["t_failed"],
                    "detail": rec["detail"].splitlines()[-1],
                    "point": p["index"],
                    "seq": 0,
                }
            )
    out = []
    for p in points.values():
        mean, low, high = interval(p.pop("values"))
        n = p["ok"]
        finite = [None if math.isnan(x) else x for x in (mean, low, high)]
        out.append({**p, "mean": finite[0], "low": finite[1], "high": finite[2], "n": n})
    counts = {k: sum(p[k] for p in out) for k in ("ok", "failed", "pending")}
    return {
        "points": out,
        "failures": sorted(failures, key=lambda f: f["run_id"]),
        "counts": counts,
        "cost": {"runs": done, "cpu_seconds": pytest.approx(sum(walls), rel=1e-12)},
    }


def shown_of(page: dict) -> dict:
    out = comparable(page)
    return {k: out[k] for k in ("points", "failures", "counts", "cost")}


def test_the_page_is_the_one_recomputed_from_the_records_built_followed_or_reindexed(tmp_path):
    from nematic_solids.sweep.catalogue.index import index_root
    from nematic_solids.sweep.catalogue.opening import open_catalogue

    folder = Folder(tmp_path, seeds=4)
    ids = folder.expansion.run_ids
    rng = random.Random(7)
    with Recorder(folder.store, catch_up=False) as recorder:
        for rid in ids[:10]:  # done before the service starts
            recorder.add(folder.record(rid, rng.uniform(0, 1)))
    client, ctx = client_for(folder.root)
    page = get(client)
    assert shown_of(page) == recomputed(folder)  # built at once
    # then runs recorded a few at a time, some failed, a failed one done again ok
    later = ids[10:]
    rng.shuffle(later)
    batches = [later[k : k + 7] for k in range(0, len(later), 7)]
    for b, batch in enumerate(batches):
        rows = []
        for k, rid in enumerate(batch):
            failed = (b + k) % 5 == 0
            rows.append(
                _row(folder, folder.record(rid, rng.uniform(0, 1), "failed" if failed else "ok"))
            )
        if b == 3:
            redone = next(f["run_id"] for f in page["failures"])
            rows.append(_row(folder, folder.record(redone, 0.5)))
        ctx.catalogue.record(rows)
        page = merge(page, get(client, page["seq"]))
        assert shown_of(page) == recomputed(folder)
    assert page["counts"]["failed"] > 3
    assert page["counts"]["pending"] == 0
    assert ctx.views.get("grid").builds == 1  # followed, not built again
    ctx.catalogue.close()
    # the catalogue rebuilt from the folder: a service that starts shows the same
    (folder.root / "catalogue.sqlite").unlink()
    catalogue = open_catalogue(folder.root)
    index_root(catalogue)
    catalogue.close()
    assert shown_of(fresh(folder.root)) == recomputed(folder)


def test_runs_the_catalogue_lacks_are_read_from_their_records(tmp_path):
    folder = Folder(tmp_path)
    ids = folder.expansion.run_ids
    client, ctx = client_for(folder.root)
    with Recorder(folder.store, catch_up=False) as recorder:
        for rid in ids[:6]:
            recorder.add(folder.record(rid, 0.1 * len(rid)))
    for k, rid in enumerate(ids[6:12]):  # a driver that ran without the catalogue
        folder.record(rid, 0.3, "failed" if k % 2 else "ok")
    (folder.store.runs_dir / f"{ids[0]}.json").unlink()  # the records are the truth
    ctx.catalogue.close()
    assert shown_of(fresh(folder.root)) == recomputed(folder)


def test_a_copy_whose_point_the_model_refuses_is_shown_unreadable(tmp_path):
    # a copy this code no longer accepts at one grid point (written by another version):
    # the page says it cannot be read, no error
    folder = Folder(tmp_path)
    text = folder.store.campaign_copy.read_text()
    folder.store.campaign_copy.write_text(text.replace("chi: [5.0, 10.0]", "chi: [5.0, -10.0]"))
    client, ctx = client_for(folder.root)
    page = get(client)
    assert page["readable"] is False
    assert page["points"] == []
    ctx.catalogue.close()
