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

import gc
import logging
import math
import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..catalogue import Catalogue
from ..expand import Expansion
from ..models.interface import Observable
from ..store import CampaignStore, Record
from .views import (
    CONFIDENCE,
    campaign_store,
    failure_entry,
    interval,
    not_started,
    plain,
    point_key,
    point_marks,
    rounds,
    shown,
    stored_layout,
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


class _CollectorPaused:
    """Python's cycle collector paused while a view is built (``with _CollectorPaused():``):
    a build allocates some 10^5 objects (a big campaign's rows and lists) that hold no
    cycles, and each full pass of the collector that they trigger walks the service's whole
    heap and frees nothing. Concurrent builds are counted: the collector runs again when the
    last one ends, and only if it ran before the first began."""

    _lock = threading.Lock()
    _holds = 0
    _was_enabled = True

    def __enter__(self) -> None:
        with self._lock:
            if _CollectorPaused._holds == 0:
                _CollectorPaused._was_enabled = gc.isenabled()
                gc.disable()
            _CollectorPaused._holds += 1

    def __exit__(self, *exc: object) -> None:
        with self._lock:
            _CollectorPaused._holds -= 1
            if _CollectorPaused._holds == 0 and _CollectorPaused._was_enabled:
                gc.enable()


@dataclass
class _Point:
    index: int
    coords: dict[str, Any]
    #: :func:`~.views.point_key` of its coords (what its marks are found by)
    key: str
    #: the positions of its runs in the view's per-run lists
    runs: list[int] = field(default_factory=list)
    seq: int = 0
    summary: dict[str, Any] = field(default_factory=dict)


def _finite(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


class CampaignView:
    """One campaign's page (see the module's docstring); thread-safe.

    The runs' state is kept in lists by position (the layout's run order): ``_ids``,
    ``_seeds``, ``_point_of`` (the point's index), ``_status``, ``_value`` (the shown
    scalar), ``_wall``; ``_where`` maps a run id to its position."""

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
        self._clear_runs()
        self._extras: dict[str, tuple[Any, Any]] = {}
        self.builds = 0

    def _clear_runs(self) -> None:
        self._ids: list[str] = []
        self._seeds: list[int] = []
        self._point_of: list[int] = []
        self._status: list[str] = []
        self._value: list[float | None] = []
        self._wall: list[float] = []
        self._where: dict[str, int] = {}
        self._failures: dict[str, dict[str, Any]] = {}
        self._cleared: dict[str, int] = {}
        self._counts = {"ok": 0, "failed": 0, "pending": 0}
        self._cost = 0.0

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
        self._points = []
        self._clear_runs()
        layout = stored_layout(self.store)
        if layout is None:
            self._head = not_started(self.name)
            return
        campaign, expansion = layout
        self._shown = shown(campaign.model)
        self._lay_out(expansion, seq)
        n = len(self._ids)
        self._status, self._value, self._wall = ["pending"] * n, [None] * n, [0.0] * n
        done, on_disk = self._states(seq)
        where, status, value, wall = self._where, self._status, self._value, self._wall
        isfinite = math.isfinite
        ok: list[str] = []
        for rid, w, x in done:  # done ok: what the catalogue holds is enough
            i = where.get(rid)
            if i is None or rid not in on_disk:
                continue
            status[i] = "ok"
            wall[i] = float(w) if w is not None and isfinite(w) else 0.0
            value[i] = float(x) if x is not None and isfinite(x) else None
            ok.append(rid)
        self._counts = {"ok": len(ok), "failed": 0, "pending": n - len(ok)}
        # failed, or not in the catalogue: its record (in the layout's order)
        for i in sorted(map(where.__getitem__, on_disk.difference(ok).intersection(where))):
            self._apply(self._ids[i], self.store.read_record(self._ids[i]), seq)
        self._cost = math.fsum(wall)
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

    def _lay_out(self, expansion: Expansion, seq: int) -> None:
        """The points and the runs' positions of the campaign's layout (a point's runs
        together, in the expansion's order)."""
        by_index: dict[tuple[int, ...], _Point] = {}
        ids, seeds, point_of = self._ids, self._seeds, self._point_of
        for where, run_ids, run_seeds in expansion.by_point():
            point = by_index.get(where.index)
            if point is None:
                coords = {k: plain(v) for k, v in where.coords.items()}
                point = _Point(len(self._points), coords, point_key(coords), seq=seq)
                by_index[where.index] = point
                self._points.append(point)
            point.runs.extend(range(len(ids), len(ids) + len(run_ids)))
            ids.extend(run_ids)
            seeds.extend(int(s) for s in run_seeds)
            point_of.extend([point.index] * len(run_ids))
        self._where = {rid: i for i, rid in enumerate(ids)}

    def _states(self, seq: int) -> tuple[Sequence[Any], set[str]]:
        """What the build reads of the runs: the catalogue's runs of the campaign done ok
        (run id, wall time, the shown value), in one query, and the run ids with a record
        file (none: not run). A run that failed, or that the catalogue lacks (a driver that
        ran without it), is read from its record file."""
        try:
            done: Sequence[Any] = (
                self.catalogue.campaign_done(self.name, self._shown.scalar) if seq else []
            )
        except Exception:  # noqa: BLE001 - the folder is the truth
            log.warning("catalogue not readable: %s read from its folder", self.name)
            done = []
        try:
            on_disk = {
                n[:-5]
                for n in os.listdir(self.store.runs_dir)
                if n.endswith(".json") and n[0] != "."
            }
        except OSError:
            on_disk = set()
        return done, on_disk

    def _apply(self, run_id: str, record: Record | None, seq: int) -> None:
        """A run's record (None: not run) moves its point, the counts, the cost, the failures."""
        i = self._where[run_id]
        status = "pending" if record is None else str(record.get("status"))
        kind = status if status in ("ok", "failed") else "pending"
        old = self._status[i] if self._status[i] in ("ok", "failed") else "pending"
        self._counts[old] -= 1
        self._counts[kind] += 1
        wall = _finite(None if record is None else record.get("wall_time")) or 0.0
        self._cost += wall - self._wall[i]
        self._status[i], self._wall[i] = status, wall
        scalars = (record or {}).get("scalars") or {}
        self._value[i] = _finite(scalars.get(self._shown.scalar))
        point = self._points[self._point_of[i]]
        point.seq = max(point.seq, seq)
        if record is not None and status != "ok":
            coords = {**point.coords, "seed": self._seeds[i]}
            entry = failure_entry(run_id, coords, record)
            self._failures[run_id] = {**entry, "point": point.index, "seq": seq}
            self._cleared.pop(run_id, None)
        elif run_id in self._failures:
            del self._failures[run_id]
            self._cleared[run_id] = seq

    def _summarise(self, point: _Point) -> None:
        status, value = self._status, self._value
        values = [v for i in point.runs if status[i] == "ok" and (v := value[i]) is not None]
        mean, low, high = interval(values)
        kinds = [status[i] for i in point.runs]
        ok, failed = kinds.count("ok"), kinds.count("failed")
        point.summary = {
            "index": point.index,
            "coords": point.coords,
            "mean": _finite(mean),
            "low": _finite(low),
            "high": _finite(high),
            "n": len(values),
            "ok": ok,
            "failed": failed,
            "pending": len(kinds) - ok - failed,
        }

    def refresh(self) -> None:
        """Bring the view up to the catalogue's latest ``seq`` (see the module's docstring)."""
        upto = self._last_seq()
        if upto is None or self._layout != _stamp(self.store.root, LAYOUT_FILES):
            with _CollectorPaused():
                self._build(upto or 0)
            return
        if upto <= self.seq:
            return
        changed = self.catalogue.campaign_changes(self.name, self.seq, upto)
        touched: set[int] = set()
        for run_id, seq in changed:
            if run_id not in self._where:
                continue  # not a run of its layout (another folder's of the same name)
            self._apply(run_id, self.store.read_record(run_id), seq)
            touched.add(self._point_of[self._where[run_id]])
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
                    "runs": len(self._status) - self._status.count("pending"),
                    "cpu_seconds": float(self._cost),
                },
                points=[
                    {**p.summary, **marks.get(p.key, {})}
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
                    "run_id": self._ids[i],
                    "seed": self._seeds[i],
                    "status": self._status[i],
                    "value": self._value[i],
                }
                for i in point.runs
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
