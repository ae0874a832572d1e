"""The service's API and its security, in process (Starlette's test client; no cluster, no
runner): the token (401 without it, the ``?token=`` exchange for an HttpOnly cookie), CSRF
(a forged Origin, a cookie without the page's header), the Host check, path traversal, the
refused bind, the queue's order and cancel, and what the API shows of a real campaign's
folder (points with seed means and intervals, failures with reasons, a run's series)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

pytest.importorskip("fastapi")
from fastapi.testclient import TestClient

from nematic_solids.sweep.service import ServiceError
from nematic_solids.sweep.service.api import ServiceContext, create_app
from nematic_solids.sweep.service.catalogue_link import open_service_database
from nematic_solids.sweep.service.queue import CANCELLED, RUNNING
from nematic_solids.sweep.service.security import (
    COOKIE,
    CSRF_HEADER,
    bind_problem,
    csrf_token,
)
from nematic_solids.sweep.service.server import ServeOptions, serve

TOKEN = "0123456789abcdef" * 3
BASE = "http://127.0.0.1:8765"
AUTH = {"Authorization": f"token {TOKEN}"}
CAMPAIGN = """\
name: {name}
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: 0.5, save_every: 0.25, mechanics: linear}}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2]
seeds: 1
"""


def make_client(root: Path, token: str | None = TOKEN) -> tuple[TestClient, ServiceContext]:
    catalogue, queue = open_service_database(root)
    ctx = ServiceContext(root, token, "127.0.0.1", 8765, False, catalogue, queue)
    return TestClient(create_app(ctx), base_url=BASE), ctx


def body(name: str = "tiny", priority: int = 0) -> dict:
    return {
        "text": CAMPAIGN.format(name=name),
        "source": f"/nowhere/{name}.yaml",
        "priority": priority,
    }


@pytest.fixture
def client(tmp_path):
    c, _ = make_client(tmp_path)
    return c


# ------------------------------------------------------------------- the token
@pytest.mark.parametrize(
    "path", ["/api/queue", "/api/campaigns", "/api/service", "/api/events", "/api/openapi.json"]
)
def test_without_the_token_the_api_is_closed(client, path):
    assert client.get(path).status_code == 401
    assert client.get(path, headers={"Authorization": "token wrong"}).status_code == 401
    client.cookies.set(COOKIE, "wrong")
    assert client.get(path).status_code == 401


def test_without_the_token_the_pages_are_closed_and_submit_refused(client):
    page = client.get("/")
    assert page.status_code == 401
    assert "token" in page.text
    assert "<script" not in page.text
    assert client.post("/api/queue", json=body()).status_code == 401
    assert client.get("/api/queue", headers=AUTH).json()["entries"] == []


def test_the_query_token_becomes_an_http_only_cookie(client):
    r = client.get(f"/?token={TOKEN}&x=1", follow_redirects=False)
    assert r.status_code == 303
    assert r.headers["location"] == "/?x=1"  # the token leaves the address bar
    cookie = r.headers["set-cookie"]
    assert f"{COOKIE}={TOKEN}" in cookie
    assert "HttpOnly" in cookie
    assert "samesite=strict" in cookie.lower()
    page = client.get("/")  # the client keeps the cookie
    assert page.status_code == 200
    assert csrf_token(TOKEN) in page.text
    assert client.get("/api/queue").status_code == 200
    # the query token opens a page, never the API
    assert TestClient(client.app, base_url=BASE).get(f"/api/queue?token={TOKEN}").status_code == 401


# ------------------------------------------------------------------- CSRF and Host
def test_a_forged_origin_is_refused(client):
    forged = {"Origin": "http://evil.example", **AUTH}
    r = client.post("/api/queue", json=body(), headers=forged)
    assert r.status_code == 403
    assert "Origin" in r.json()["detail"]
    r = client.post("/api/queue", json=body(), headers={"Referer": "http://evil.example/x", **AUTH})
    assert r.status_code == 403
    assert client.get("/api/queue", headers=AUTH).json()["entries"] == []
    assert (
        client.post("/api/queue", json=body(), headers={"Origin": BASE, **AUTH}).status_code == 201
    )


def test_a_cookie_post_needs_the_page_csrf_header_and_an_origin(client):
    client.cookies.set(COOKIE, TOKEN)
    same = {"Origin": BASE}
    assert client.post("/api/queue", json=body(), headers=same).status_code == 403
    assert (
        client.post("/api/queue", json=body(), headers={CSRF_HEADER: csrf_token(TOKEN)}).status_code
        == 403
    )
    wrong = {**same, CSRF_HEADER: csrf_token("another token")}
    assert client.post("/api/queue", json=body(), headers=wrong).status_code == 403
    forged = {"Origin": "http://evil.example", CSRF_HEADER: csrf_token(TOKEN)}
    assert client.post("/api/queue", json=body(), headers=forged).status_code == 403
    ok = {**same, CSRF_HEADER: csrf_token(TOKEN)}
    assert client.post("/api/queue", json=body(), headers=ok).status_code == 201


def test_a_foreign_host_header_is_refused(client):
    """DNS rebinding: a name that resolves to 127.0.0.1 in a browser is not the service's."""
    r = client.get("/api/queue", headers={**AUTH, "Host": "evil.example:8765"})
    assert r.status_code == 400
    assert client.get("/api/queue", headers={**AUTH, "Host": "localhost:8765"}).status_code == 200


def test_without_a_token_on_loopback_posts_still_check_the_origin(tmp_path):
    c, _ = make_client(tmp_path, token=None)
    assert c.get("/api/queue").status_code == 200
    assert (
        c.post("/api/queue", json=body(), headers={"Origin": "http://evil.example"}).status_code
        == 403
    )
    assert c.post("/api/queue", json=body(), headers={"Origin": BASE}).status_code == 201


# ------------------------------------------------------------------- binding
@pytest.mark.parametrize(
    ("host", "token", "tls", "refused"),
    [
        ("127.0.0.1", None, False, False),
        ("::1", None, False, False),
        ("localhost", "t", False, False),
        ("0.0.0.0", "t", False, True),
        ("0.0.0.0", None, True, True),
        ("192.168.1.5", "t", True, False),
    ],
)
def test_binding_another_address_needs_a_token_and_tls(host, token, tls, refused):
    assert (bind_problem(host, token, tls) is not None) == refused


def test_serve_refuses_a_public_address_without_tls_before_anything(tmp_path):
    with pytest.raises(ServiceError, match="refusing to listen on 0.0.0.0"):
        serve(tmp_path, ServeOptions(host="0.0.0.0", port=0), say=lambda _: None)
    assert not (tmp_path / ".service").exists()


# ------------------------------------------------------------------- traversal
@pytest.mark.parametrize(
    "path",
    [
        "/api/campaigns/..",
        "/api/campaigns/%2e%2e",
        "/api/campaigns/..%2F..%2Fetc",
        "/api/campaigns/.service",
        "/api/campaigns/outside",
        "/api/campaigns/outside/runs/secret",
        "/api/campaigns/inside/runs/..%2F..%2Foutside%2Fsecret",
        "/api/campaigns/inside/runs/%2e%2e",
        "/campaigns/..%2F..",
        "/campaigns/outside",
    ],
)
def test_no_path_reaches_a_file_outside_the_root(tmp_path, path):
    root = tmp_path / "root"
    (root / "inside" / "runs").mkdir(parents=True)
    secret = tmp_path / "elsewhere"
    (secret / "runs").mkdir(parents=True)
    (secret / "runs" / "secret.json").write_text('{"run_id": "secret", "status": "ok"}')
    (secret / "secret.json").write_text('{"run_id": "secret", "status": "ok"}')
    os.symlink(secret, root / "outside")  # a link out of the root
    c, _ = make_client(root)
    r = c.get(path, headers=AUTH)
    assert r.status_code == 404, r.text
    assert "secret" not in r.text or "no " in r.text


# ------------------------------------------------------------------- the queue
def test_submit_validates_the_campaign(client):
    r = client.post(
        "/api/queue", headers=AUTH, json={"text": "name: x\nsweep: 3\n", "source": "/a/x.yaml"}
    )
    assert r.status_code == 422
    assert "sweep" in r.json()["detail"]
    assert client.get("/api/queue", headers=AUTH).json()["entries"] == []


def test_the_queue_runs_priority_then_submission_and_a_stopped_campaign_first(tmp_path):
    c, ctx = make_client(tmp_path)
    ids = {}
    for name, priority in (("a", 0), ("b", 5), ("c", 0), ("d", 5)):
        r = c.post("/api/queue", headers=AUTH, json=body(name, priority))
        assert r.status_code == 201
        ids[name] = r.json()["id"]
    order = [e["name"] for e in c.get("/api/queue", headers=AUTH).json()["entries"]]
    assert order == ["b", "d", "a", "c"]
    first = ctx.queue.next()
    assert first is not None
    assert first.name == "b"
    ctx.queue.start(ctx.queue.get(ids["c"]), None)  # c was running when the service stopped
    first = ctx.queue.next()
    assert first is not None
    assert first.name == "c"
    assert ctx.queue.get(ids["c"]).state == RUNNING
    # cancel: a queued one at once; a running one is marked for the runner; unknown: 404
    r = c.post(f"/api/queue/{ids['a']}/cancel", headers=AUTH)
    assert r.status_code == 200
    assert r.json()["state"] == CANCELLED
    assert c.post(f"/api/queue/{ids['a']}/cancel", headers=AUTH).status_code == 409
    r = c.post(f"/api/queue/{ids['c']}/cancel", headers=AUTH)
    assert r.json()["state"] == RUNNING
    assert r.json()["cancel_requested"]
    assert c.post("/api/queue/999/cancel", headers=AUTH).status_code == 404
    version = c.get("/api/queue", headers=AUTH).json()["version"]
    assert c.get(f"/api/queue?since={version}", headers=AUTH).json()["entries"] == []


def test_the_openapi_description_lists_the_endpoints(client):
    spec = client.get("/api/openapi.json", headers=AUTH).json()
    assert {
        "/api/queue",
        "/api/queue/{entry_id}/cancel",
        "/api/campaigns",
        "/api/campaigns/{name}",
        "/api/campaigns/{name}/runs/{run_id}",
        "/api/campaigns/{name}/points/{index}",
        "/api/changes",
        "/api/events",
        "/api/service",
    } <= set(spec["paths"])


# ------------------------------------------------------------------- a campaign's content
def test_a_campaign_shows_its_points_failures_and_runs(copy_of_small):
    from sweep_helpers import records

    c, ctx = make_client(copy_of_small.results)
    data = c.get("/api/campaigns/small", headers=AUTH).json()
    recs = records(copy_of_small.runs)
    assert data["total"] == len(copy_of_small.ids) == 6
    assert data["counts"] == {"ok": 4, "failed": 2, "pending": 0}
    for p in data["points"]:
        runs = c.get(f"/api/campaigns/small/points/{p['index']}", headers=AUTH).json()["runs"]
        assert len(runs) == 2
        values = [
            recs[r["run_id"]]["scalars"]["sigma2_S_final"] for r in runs if r["status"] == "ok"
        ]
        if not values:
            assert p["mean"] is None
            assert p["failed"] == 2
            continue
        mean, sd = np.mean(values), np.std(values, ddof=1)
        half = stats.t.ppf(0.975, len(values) - 1) * sd / math.sqrt(len(values))
        assert p["mean"] == pytest.approx(mean, rel=1e-12)
        assert (p["low"], p["high"]) == pytest.approx((mean - half, mean + half), rel=1e-9)
    reasons = {f["run_id"]: f["reason"] for f in data["failures"]}
    assert reasons == {r: recs[r]["reason"] for r in recs if recs[r]["status"] == "failed"}
    assert all(f["coords"]["alpha_minus_B"] == 20.0 for f in data["failures"])
    assert data["cost"]["cpu_seconds"] == pytest.approx(
        sum(r["wall_time"] for r in recs.values() if r.get("wall_time") is not None)
    )
    ok = next(r for r in recs if recs[r]["status"] == "ok")
    run = c.get(f"/api/campaigns/small/runs/{ok}", headers=AUTH).json()
    assert run["record"]["seed"] == recs[ok]["seed"]
    assert len(run["t"]) == len(run["series"]["sigma2_S"]) > 2
    assert run["series"]["sigma2_S"][-1] == pytest.approx(recs[ok]["scalars"]["sigma2_S_final"])
    names = [x["name"] for x in c.get("/api/campaigns", headers=AUTH).json()["campaigns"]]
    assert names == ["small"]


def test_changes_are_incremental_from_the_catalogue_seq(copy_of_small):
    c, _ = make_client(copy_of_small.results)
    every = c.get("/api/changes?since=0", headers=AUTH).json()
    assert {r["run_id"] for r in every["runs"]} == set(copy_of_small.ids)
    assert every["campaigns"] == ["small"]
    assert every["complete"]
    assert c.get(f"/api/changes?since={every['seq']}", headers=AUTH).json()["runs"] == []
    # in pages: each answer's seq is where the next one starts, nothing lost or repeated
    seen, since = [], 0
    while True:
        page = c.get(f"/api/changes?since={since}&limit=4", headers=AUTH).json()
        seen += [r["run_id"] for r in page["runs"]]
        since = page["seq"]
        if page["complete"]:
            break
    assert sorted(seen) == sorted(copy_of_small.ids)
