"""A campaign's page kept in memory and brought up to date incrementally: :class:`CampaignView`
is built once, from the campaign's layout (its copy of the campaign file, its rounds) and the
state of its runs (the catalogue's, in one query, for the runs done ok; the record file of a
run that failed or that the catalogue lacks, the run records being the source of truth), then
follows the catalogue's change counter (``runs.seq``): on each request it asks the catalogue
which runs of the campaign changed since the ``seq`` it has seen
(:meth:`~nematic_solids.sweep.catalogue.Catalogue.campaign_changes`, an indexed query whose
cost follows the number of changes), reads those runs' records, and moves their points'
seed means, the counts, the cost and the failures. It is built again when the campaign's
layout changes: its copy of the campaign file (more seeds, a resubmission) or its plan of
rounds (``refine.json``, ``precision.json``: new points).

Each point carries the ``seq`` of its latest change, so a client that has seen everything up
to ``seq`` c receives only the points changed after c (:meth:`CampaignView.page`); a cursor
from before the latest layout gets the whole page.

:class:`CampaignViews` holds the views of the campaigns last asked for, at most
:data:`MAX_VIEWS` (least recently used dropped): the service's memory does not grow with the
number of campaigns it has shown.
"""

from __future__ import annotations

import logging
import math
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..catalogue import Catalogue
from ..models.interface import Observable
from ..store import CampaignStore, Record
from .views import (
    CONFIDENCE,
    campaign_store,
    expansion_of,
    failure_entry,
    interval,
    load_stored,
    not_started,
    plain,
    point_key,
    point_marks,
    rounds,
    shown,
    verification,
)

log = logging.getLogger(__name__)

#: The campaign views kept at once (the least recently asked for is dropped beyond).
MAX_VIEWS = 4
#: The files whose change means a new layout (the campaign copy, the plans of rounds).
LAYOUT_FILES = ("campaign.yaml", "refine.json", "precision.json")


def _stamp(folder: Path, names: tuple[str, ...]) -> tuple[tuple[int, int] | None, ...]:
    out: list[tuple[int, int] | None] = []
    for name in names:
        try:
            st = (folder / name).stat()
        except OSError:
            out.append(None)
            continue
        out.append((st.st_mtime_ns, st.st_size))
    return tuple(out)


@dataclass
class _Point:
    index: int
    coords: dict[str, Any]
    run_ids: list[str] = field(default_factory=list)
    seeds: list[int] = field(default_factory=list)
    seq: int = 0
    summary: dict[str, Any] = field(default_factory=dict)


@dataclass
class _Run:
    point: int
    seed: int
    status: str = "pending"
    value: float | None = None
    wall: float = 0.0


def _finite(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


class CampaignView:
    """One campaign's page (see the module's docstring); thread-safe."""

    def __init__(self, store: CampaignStore, catalogue: Catalogue):
        self.store, self.catalogue = store, catalogue
        self.name = store.root.name
        self._lock = threading.Lock()
        self._layout: tuple[tuple[int, int] | None, ...] | None = None
        #: the catalogue's seq the view is up to date with, and that of its layout
        self.seq = 0
        self.layout_seq = 0
        self._head: dict[str, Any] = not_started(self.name)
        #: the observable the diagram shows (the campaign's model's classifying one)
        self._shown: Observable = shown()
        self._points: list[_Point] = []
        self._runs: dict[str, _Run] = {}
        self._failures: dict[str, dict[str, Any]] = {}
        self._cleared: dict[str, int] = {}
        self._counts = {"ok": 0, "failed": 0, "pending": 0}
        self._cost = 0.0
        self._extras: dict[str, tuple[Any, Any]] = {}
        self.builds = 0

    # ------------------------------------------------------------------ reading
    def _last_seq(self) -> int | None:
        try:
            return self.catalogue.last_seq()
        except Exception:  # noqa: BLE001 - the folder is the truth: rebuild from it
            log.warning("catalogue not readable: the page of %s is read again", self.name)
            return None

    def _build(self, seq: int) -> None:
        """Everything from the folder (its records read after ``seq`` was: a run recorded in
        between is read again by the next refresh, which changes nothing)."""
        self.builds += 1
        self._layout = _stamp(self.store.root, LAYOUT_FILES)
        self.seq = self.layout_seq = seq
        self._points, self._runs, self._failures, self._cleared = [], {}, {}, {}
        self._counts = {"ok": 0, "failed": 0, "pending": 0}
        self._cost = 0.0
        campaign = load_stored(self.store)
        if campaign is None:
            self._head = not_started(self.name)
            return
        expansion = expansion_of(campaign, self.store)
        self._shown = shown(campaign.model)
        states, on_disk = self._states(seq)
        by_index: dict[tuple[int, ...], _Point] = {}
        counts, cost = self._counts, 0.0
        for run in expansion:
            rid, seed, where = run.run_id, int(run.seed), run.point
            point = by_index.get(where.index)
            if point is None:
                point = _Point(len(self._points), {k: plain(v) for k, v in where.coords.items()})
                point.seq = seq
                by_index[where.index] = point
                self._points.append(point)
            point.run_ids.append(rid)
            point.seeds.append(seed)
            state = states.get(rid) if rid in on_disk else None
            if state is not None and state[0] == "ok":  # what the catalogue holds is enough
                wall = _finite(state[1]) or 0.0
                self._runs[rid] = _Run(point.index, seed, "ok", _finite(state[2]), wall)
                counts["ok"] += 1
                cost += wall
                continue
            self._runs[rid] = _Run(point.index, seed)
            counts["pending"] += 1
            if rid in on_disk:  # failed, or not in the catalogue: its record
                self._apply(rid, self.store.read_record(rid), seq, coords=run.coords)
        self._cost += cost
        for point in self._points:
            self._summarise(point)
        self._head = {
            "name": campaign.name,
            "readable": True,
            "description": campaign.description,
            "dims": [d.name for d in campaign.dims],
            "shown": self._shown.name,
            "confidence": CONFIDENCE,
            "total": len(expansion),
        }

    def _states(
        self, seq: int
    ) -> tuple[dict[str, tuple[str, float | None, float | None]], set[str]]:
        """What the build reads of the runs: the catalogue's state of every run of the
        campaign in one query (status, wall time, the shown value: enough for a run done ok),
        and the run ids with a record file (none: not run). A run that failed, or that the
        catalogue lacks (a driver that ran without it), is read from its record file."""
        try:
            states = self.catalogue.campaign_states(self.name, self._shown.scalar) if seq else {}
        except Exception:  # noqa: BLE001 - the folder is the truth
            log.warning("catalogue not readable: %s read from its folder", self.name)
            states = {}
        try:
            with os.scandir(self.store.runs_dir) as entries:
                on_disk = {
                    e.name[:-5] for e in entries if e.name.endswith(".json") and e.name[0] != "."
                }
        except OSError:
            on_disk = set()
        return states, on_disk

    def _apply(
        self, run_id: str, record: Record | None, seq: int, coords: dict[str, Any] | None = None
    ) -> None:
        """A run's record (None: not run) moves its point, the counts, the cost, the failures."""
        run = self._runs[run_id]
        status = "pending" if record is None else str(record.get("status"))
        kind = status if status in ("ok", "failed") else "pending"
        old = run.status if run.status in ("ok", "failed") else "pending"
        self._counts[old] -= 1
        self._counts[kind] += 1
        wall = _finite(None if record is None else record.get("wall_time")) or 0.0
        self._cost += wall - run.wall
        run.status, run.wall = status, wall
        scalars = (record or {}).get("scalars") or {}
        run.value = _finite(scalars.get(self._shown.scalar))
        point = self._points[run.point]
        point.seq = max(point.seq, seq)
        if record is not None and status != "ok":
            entry = failure_entry(run_id, coords or point.coords, record)
            self._failures[run_id] = {**entry, "point": point.index, "seq": seq}
            self._cleared.pop(run_id, None)
        elif run_id in self._failures:
            del self._failures[run_id]
            self._cleared[run_id] = seq

    def _summarise(self, point: _Point) -> None:
        runs = [self._runs[r] for r in point.run_ids]
        values = [r.value for r in runs if r.status == "ok" and r.value is not None]
        mean, low, high = interval(values)
        kinds = [r.status if r.status in ("ok", "failed") else "pending" for r in runs]
        point.summary = {
            "index": point.index,
            "coords": point.coords,
            "mean": _finite(mean),
            "low": _finite(low),
            "high": _finite(high),
            "n": len(values),
            "ok": kinds.count("ok"),
            "failed": kinds.count("failed"),
            "pending": kinds.count("pending"),
        }

    def refresh(self) -> None:
        """Bring the view up to the catalogue's latest ``seq`` (see the module's docstring)."""
        upto = self._last_seq()
        if upto is None or self._layout != _stamp(self.store.root, LAYOUT_FILES):
            self._build(upto or 0)
            return
        if upto <= self.seq:
            return
        changed = self.catalogue.campaign_changes(self.name, self.seq, upto)
        touched: set[int] = set()
        for run_id, seq in changed:
            if run_id not in self._runs:
                continue  # not a run of its layout (another folder's of the same name)
            self._apply(run_id, self.store.read_record(run_id), seq)
            touched.add(self._runs[run_id].point)
        for index in touched:
            self._summarise(self._points[index])
        self.seq = upto

    def _extra(self, name: str, stamp_of: tuple[str, ...], make: Any) -> Any:
        """``make()`` again only when the files ``stamp_of`` changed."""
        stamp = _stamp(self.store.root, stamp_of)
        cached = self._extras.get(name)
        if cached is None or cached[0] != stamp:
            cached = (stamp, make())
            self._extras[name] = cached
        return cached[1]

    # ------------------------------------------------------------------ answers
    def page(self, since: int | None = None) -> dict[str, Any]:
        """The page (everything but the queue's view of it) or, with the ``seq`` of an
        earlier answer, what changed after it: ``delta`` true, the points and failures
        changed, ``cleared``: the failures since resolved (a run done again)."""
        with self._lock:
            self.refresh()
            full = since is None or since < self.layout_seq
            plan = self._extra("rounds", LAYOUT_FILES, lambda: rounds(self.store))
            marks = self._extra(
                "marks", LAYOUT_FILES + ("verify.nc",), lambda: point_marks(self.store)
            )
            out = dict(self._head)
            out.update(
                delta=not full,
                seq=self.seq,
                layout_seq=self.layout_seq,
                counts=dict(self._counts),
                cost={
                    "runs": sum(1 for r in self._runs.values() if r.status != "pending"),
                    "cpu_seconds": float(self._cost),
                },
                points=[
                    {**p.summary, **marks.get(point_key(p.coords), {})}
                    for p in self._points
                    if full or p.seq > (since or 0)
                ],
                failures=[f for f in self._failures.values() if full or f["seq"] > (since or 0)],
                cleared=[] if full else [r for r, s in self._cleared.items() if s > (since or 0)],
                rounds=plan,
                verification=self._extra(
                    "verification", ("verify.nc",), lambda: verification(self.store)
                ),
            )
            return out

    def point_runs(self, index: int) -> list[dict[str, Any]]:
        """The runs of point ``index`` (IndexError: none such): id, seed, status, value."""
        with self._lock:
            self.refresh()
            if not 0 <= index < len(self._points):
                raise IndexError(index)
            point = self._points[index]
            return [
                {
                    "run_id": rid,
                    "seed": seed,
                    "status": self._runs[rid].status,
                    "value": self._runs[rid].value,
                }
                for rid, seed in zip(point.run_ids, point.seeds, strict=True)
            ]


class CampaignViews:
    """The views of the campaigns last asked for, :data:`MAX_VIEWS` at most."""

    def __init__(self, root: Path, catalogue: Catalogue, size: int = MAX_VIEWS):
        self.root, self.catalogue, self.size = root, catalogue, size
        self._views: OrderedDict[str, CampaignView] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, name: str) -> CampaignView:
        """The view of campaign ``name``; :class:`~.views.NotFound` for a name refused or
        without a folder."""
        store = campaign_store(self.root, name)
        with self._lock:
            view = self._views.pop(name, None)
            if view is None:
                view = CampaignView(store, self.catalogue)
            self._views[name] = view
            while len(self._views) > self.size:
                self._views.popitem(last=False)
            return view

    def __len__(self) -> int:
        return len(self._views)


__all__ = ["MAX_VIEWS", "CampaignView", "CampaignViews"]
