"""The service's HTTP side (FastAPI): the JSON API under ``/api/`` (its OpenAPI description at
``/api/openapi.json``), the dashboard's two pages, the event stream the pages listen to (SSE),
and the security of :mod:`.security` applied to every request by :class:`Guard`."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlencode

import anyio
from fastapi import FastAPI, HTTPException, Request, Response
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse
from pydantic import BaseModel, Field
from sse_starlette.sse import EventSourceResponse

from ..catalogue import Catalogue
from ..errors import CampaignError
from ..files import now_iso
from .campaign_view import CampaignViews
from .dashboard import campaign_page, index_page
from .queue import Entry, QueueStore
from .runner import Changes, Runner
from .security import (
    COOKIE,
    csrf_problem,
    csrf_token,
    host_allowed,
    presented_token,
    token_matches,
)
from .views import (
    NotFound,
    campaign_names,
    campaign_store,
    not_started,
    run_detail,
)

log = logging.getLogger(__name__)

#: How often the event stream looks for changes (seconds): a finished run reaches the page
#: within this plus one fetch.
EVENT_POLL = 0.25
#: A comment line on an idle event stream (seconds), so proxies keep it open.
EVENT_PING = 15.0
#: Runs ``/api/changes`` returns at most at once (the client asks again from the last seq).
CHANGES_LIMIT = 10_000


@dataclass
class ServiceContext:
    """What the app serves: the results root, the token (``None``: none, loopback only),
    where it listens, the root's catalogue and the queue in it, the runner (``None`` in tests
    of the API alone)."""

    root: Path
    token: str | None
    host: str
    port: int
    tls: bool
    catalogue: Catalogue
    queue: QueueStore
    changes: Changes = field(default_factory=Changes)
    runner: Runner | None = None
    started: str = field(default_factory=now_iso)
    #: the campaign pages kept up to date (a few at most: :data:`.campaign_view.MAX_VIEWS`)
    views: CampaignViews = field(init=False)

    def __post_init__(self) -> None:
        self.views = CampaignViews(self.root, self.catalogue)

    def seq(self) -> int:
        """The catalogue's latest change (0 where it cannot be read)."""
        try:
            return self.catalogue.last_seq()
        except Exception:
            log.warning("catalogue not readable", exc_info=True)
            return 0

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls else 'http'}://{host}:{self.port}/"


class Submission(BaseModel):
    """A campaign to queue: its YAML text and file (relative paths in it are read from its
    folder), the overrides of ``nematic run`` and a priority (higher first)."""

    text: str = Field(max_length=1_000_000)
    source: str = Field(max_length=4096)
    priority: int = 0
    settings: dict[str, Any] = Field(default_factory=dict)
    seeds: int | list[int] | None = None
    name: str | None = None


class Guard:
    """Every request passes here (an ASGI middleware): a Host that is not the service's is
    refused (400); without the token (header or cookie) a request is refused (401), but for a
    page opened with ``?token=``, which sets the cookie and redirects to the page without it;
    a request that changes something must pass :func:`.security.csrf_problem` (403)."""

    def __init__(self, app: Any, context: ServiceContext):
        self.app, self.context = app, context

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request = Request(scope)
        response = self.check(request)
        if response is not None:
            await response(scope, receive, send)
            return
        await self.app(scope, receive, send)

    def check(self, request: Request) -> Response | None:
        ctx = self.context
        api = request.url.path.startswith("/api/")
        if not host_allowed(request.headers.get("host", ""), ctx.host):
            return _refuse(400, "this service answers to its own address only", api)
        token = ctx.token
        how = "none"
        if token is not None:
            given, how = presented_token(request.headers, request.cookies)
            if not token_matches(given, token):
                query = request.query_params.get("token")
                if request.method == "GET" and not api and token_matches(query, token):
                    rest = urlencode(
                        [(k, v) for k, v in parse_qsl(request.url.query) if k != "token"]
                    )
                    target = request.url.path + (f"?{rest}" if rest else "")
                    response = RedirectResponse(target, status_code=303)
                    response.set_cookie(
                        COOKIE, token, httponly=True, samesite="strict", secure=ctx.tls, path="/"
                    )
                    return response
                return _refuse(
                    401,
                    "this service needs its token: open the URL that 'nematic serve' printed "
                    "(with ?token=...), or send 'Authorization: token ...'",
                    api,
                )
        problem = csrf_problem(
            request.method, request.headers, how, token or "", "https" if ctx.tls else "http"
        )
        if problem is not None:
            return _refuse(403, problem, api)
        return None


def _refuse(status: int, message: str, api: bool) -> Response:
    if api:
        return JSONResponse({"detail": message}, status_code=status)
    return HTMLResponse(
        f"<!doctype html><title>nematic service</title><p>{message}</p>", status_code=status
    )


def _not_found(e: Exception) -> HTTPException:
    return HTTPException(404, str(e))


def create_app(context: ServiceContext) -> FastAPI:
    """The service's application (routes below; security by :class:`Guard`)."""
    app = FastAPI(
        title="nematic service",
        summary="Campaigns of one results root: the queue, their phase diagrams as they fill "
        "in, failures, cost, runs.",
        openapi_url="/api/openapi.json",
        docs_url=None,  # the interactive pages load scripts from a CDN: not served
        redoc_url=None,
    )
    ctx = context
    csrf = csrf_token(ctx.token) if ctx.token else ""

    # ---------------------------------------------------------------- pages
    @app.get("/", response_class=HTMLResponse, include_in_schema=False)
    def index() -> str:
        return index_page(csrf)

    def queued(name: str) -> list[Entry]:
        return [e for e in ctx.queue.entries() if e.name == name]

    @app.get("/campaigns/{name}", response_class=HTMLResponse, include_in_schema=False)
    def campaign_html(name: str) -> str:
        try:
            campaign_store(ctx.root, name)
        except NotFound as e:
            if not queued(name):
                raise _not_found(e) from None
        return campaign_page(name, csrf)

    # ---------------------------------------------------------------- the service, the queue
    @app.get("/api/service")
    def service() -> dict[str, Any]:
        """The service: its results root, start, URL, cluster, the campaign it runs."""
        runner = ctx.runner
        return {
            "root": str(ctx.root),
            "started": ctx.started,
            "url": ctx.url,
            "cluster": runner.pool.state if runner is not None else {"open": False},
            "running": runner.progress.as_dict() if runner and runner.progress else None,
            "seq": ctx.seq(),
            "queue_version": ctx.queue.version(),
        }

    @app.get("/api/queue")
    def queue(since: int = 0) -> dict[str, Any]:
        """The queue's campaigns changed after queue version ``since`` (all with 0), in the
        order they run, and the queue's version now."""
        return {
            "version": ctx.queue.version(),
            "entries": [e.public() for e in ctx.queue.entries(since=since)],
        }

    @app.post("/api/queue", status_code=201)
    def submit(body: Submission) -> dict[str, Any]:
        """Queue a campaign (validated first: 422 with its problems when it is not valid)."""
        from ..spec import Overrides, parse_campaign

        overrides = {"settings": body.settings, "seeds": body.seeds, "name": body.name}
        try:
            campaign = parse_campaign(
                body.text,
                body.source,
                Overrides(settings=body.settings, seeds=body.seeds, name=body.name),
                default_name=Path(body.source).stem,
            )
        except CampaignError as e:
            raise HTTPException(422, str(e)) from None
        entry = ctx.queue.submit(campaign.name, body.source, body.text, overrides, body.priority)
        ctx.changes.bump()
        if ctx.runner is not None:
            ctx.runner.wake()
        return entry.public()

    @app.post("/api/queue/{entry_id}/cancel")
    def cancel(entry_id: int) -> dict[str, Any]:
        """Cancel a queued campaign, or stop a running one (its runs not finished stay
        pending; a later submission resumes them). 404 unknown, 409 already ended."""
        try:
            entry = ctx.queue.cancel(entry_id)
        except KeyError:
            raise HTTPException(404, f"no campaign {entry_id} in the queue") from None
        except ValueError as e:
            raise HTTPException(409, str(e)) from None
        if ctx.runner is not None:
            ctx.runner.cancel(entry_id)
        ctx.changes.bump()
        return entry.public()

    # ---------------------------------------------------------------- campaigns and runs
    @app.get("/api/campaigns")
    def campaigns() -> dict[str, Any]:
        """Every campaign of the root (its folder, the catalogue) and of the queue: its runs
        in the catalogue (ok, failed), its latest queue entry and, for the running one, its
        progress."""
        latest: dict[str, dict[str, Any]] = {}
        for e in ctx.queue.entries():
            if e.name not in latest or e.id > latest[e.name]["id"]:
                latest[e.name] = e.public()
        counts: dict[str, dict[str, int]] = {}
        with contextlib.suppress(Exception):  # a catalogue problem shows no counts
            for row in ctx.catalogue.campaigns().to_dict("records"):
                counts[str(row["name"])] = {k: int(row[k]) for k in ("runs", "ok", "failed")}
        runner = ctx.runner
        progress = runner.progress if runner is not None else None
        names = sorted(set(campaign_names(ctx.root)) | set(latest) | set(counts))
        return {
            "seq": ctx.seq(),
            "campaigns": [
                {
                    "name": n,
                    "queue": latest.get(n),
                    "state": (latest.get(n) or {}).get("state", "done"),
                    "runs": counts.get(n),
                    "progress": progress.as_dict()
                    if progress is not None and progress.name == n
                    else None,
                }
                for n in names
            ],
        }

    @app.get("/api/campaigns/{name}")
    def campaign(name: str, since: int | None = None) -> dict[str, Any]:
        """A campaign's page: its points (seed means with intervals, each marked with its
        round, decision and verification verdict), failures with reasons, cost so far
        against the estimate made at launch, rounds and verification. With ``since`` (the
        ``seq`` of an earlier answer): ``delta`` true and only the points and failures
        changed after it (``cleared``: failures since resolved); the whole page (``delta``
        false) when the campaign's layout changed after it."""
        entries = queued(name)
        try:
            out = ctx.views.get(name).page(since)
        except NotFound as e:
            if not entries:  # nor in the queue
                raise _not_found(e) from None
            out = {**not_started(name), "delta": False, "seq": ctx.seq(), "cleared": []}
        last = max(entries, key=lambda e: e.id) if entries else None
        out["queue"] = last.public() if last is not None else None
        out["estimate"] = last.estimate if last is not None else None
        runner = ctx.runner
        progress = runner.progress if runner is not None else None
        out["progress"] = progress.as_dict() if progress and progress.name == name else None
        return out

    @app.get("/api/campaigns/{name}/points/{index}")
    def point(name: str, index: int) -> dict[str, Any]:
        """The runs of one point of a campaign's page (``index``: the point's): run id,
        seed, status and the shown observable's value."""
        try:
            return {"index": index, "runs": ctx.views.get(name).point_runs(index)}
        except NotFound as e:
            raise _not_found(e) from None
        except IndexError:
            raise HTTPException(404, f"no point {index} in campaign {name}") from None

    @app.get("/api/campaigns/{name}/runs/{run_id}")
    def run(name: str, run_id: str) -> dict[str, Any]:
        """One run: its record and its time series."""
        try:
            return run_detail(campaign_store(ctx.root, name), run_id)
        except NotFound as e:
            raise _not_found(e) from None

    @app.get("/api/changes")
    def changes(since: int = 0, limit: int = CHANGES_LIMIT) -> dict[str, Any]:
        """The runs the catalogue recorded (or changed) after ``since`` (the ``seq`` of an
        earlier answer; 0: all), at most ``limit`` in ``seq`` order, and the campaigns they
        belong to; ``complete`` false when more follow (ask again from ``seq``)."""
        limit = max(1, min(limit, CHANGES_LIMIT))
        frame = ctx.catalogue.changes(since, limit + 1)  # one more: whether more follow
        rows = frame.head(limit).to_dict("records") if len(frame) else []
        runs: list[dict[str, Any]] = [
            {
                "seq": int(r["seq"]),
                "run_id": str(r["run_id"]),
                "status": str(r["status"]),
                # the catalogue's frame holds them comma-separated
                "campaigns": [c for c in str(r["campaigns"] or "").split(",") if c],
            }
            for r in rows
        ]
        return {
            "seq": int(runs[-1]["seq"]) if runs else max(since, ctx.seq()),
            "runs": runs,
            "campaigns": sorted({str(c) for r in runs for c in r["campaigns"]}),
            "complete": len(frame) <= limit,
            "queue_version": ctx.queue.version(),
        }

    @app.get("/api/events")
    async def events(request: Request) -> EventSourceResponse:
        """Server-sent events: ``change`` with ``{"seq", "changes"}`` whenever the catalogue
        records a run (from this service or any driver of the root) or the service's state
        moves (the queue, a campaign's phase); a campaign's page then asks for what changed after
        its ``seq`` (``/api/campaigns/{name}?since=``)."""

        async def stream() -> AsyncIterator[dict[str, str]]:
            last: tuple[int, int] | None = None
            while not await request.is_disconnected():
                now = (ctx.changes.value, await anyio.to_thread.run_sync(ctx.seq))
                if now != last:
                    last = now
                    yield {
                        "event": "change",
                        "data": json.dumps({"changes": now[0], "seq": now[1]}),
                    }
                await asyncio.sleep(EVENT_POLL)

        return EventSourceResponse(stream(), ping=int(EVENT_PING))

    app.add_middleware(Guard, context=ctx)
    return app
