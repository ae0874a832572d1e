"""The driver's writer of the catalogue: :class:`Recorder` records each run as it finishes, from
a background thread, so the driver never waits on the database.

The driver hands every record it takes to :meth:`Recorder.add` (a queue: no I/O); the thread
writes whatever has arrived as one transaction, then waits for more (``FLUSH_EVERY`` at most),
so runs that finish every few milliseconds are recorded in batches and none is lost;
:meth:`Recorder.close` writes what is left. Workers never write the catalogue.

A catalogue problem never fails or loses a run: the run files stay the source of truth. If the
catalogue cannot be opened or written (a network filesystem under SQLite, a server that went
away, a full disk), the recorder logs one warning and drops the rows; the next driver of the
campaign brings the catalogue up to date from the run records (:meth:`Recorder.catch_up`, on
start), and ``nematic catalogue index`` rebuilds it whole.
"""

from __future__ import annotations

import logging
import os
import queue
import threading
from collections.abc import Mapping
from typing import Any

import sqlalchemy as sa

from ..store import CampaignStore
from .catalogue import Catalogue
from .index import campaign_hash, file_path, record_rows
from .location import OFF
from .rows import RunRow, row_from_record
from .schema import tables as t

log = logging.getLogger(__name__)

#: the longest a finished run waits before the thread writes it (seconds)
FLUSH_EVERY = 0.25
#: how long :meth:`Recorder.close` waits for the thread to write what is left (seconds)
CLOSE_WAIT = 60.0
_STOP = object()


def catalogue_off() -> bool:
    """Whether the user turned the catalogue off (``NEMATIC_CATALOGUE=off``)."""
    from .location import ENV

    return os.environ.get(ENV, "").strip().lower() in OFF


def known_runs(catalogue: Catalogue, campaign: str) -> dict[str, tuple[str, str | None]]:
    """The runs the catalogue holds for ``campaign``: run_id -> (status, finished)."""
    r, m = t.runs, t.campaign_runs
    stmt = (
        sa.select(r.c.run_id, r.c.status, r.c.finished)
        .join(m, m.c.run_id == r.c.run_id)
        .where(m.c.campaign == campaign)
    )
    with catalogue.engine.connect() as conn:
        return {rid: (status, finished) for rid, status, finished in conn.execute(stmt)}


class Recorder:
    """Records the runs of one campaign (``store``) into its results root's catalogue, from a
    background thread (see the module docstring). ``url``: the catalogue's URL (default:
    :func:`~.opening.open_catalogue`'s for the root)."""

    def __init__(self, store: CampaignStore, url: str | None = None, *, catch_up: bool = True):
        self.store = store
        self.url = url
        self.campaign = store.root.name
        self._queue: queue.Queue[Any] = queue.Queue()
        self._catch_up = catch_up
        #: runs written, and why the catalogue could not be used (None: it could)
        self.written = 0
        self.problem: str | None = None
        self.off = catalogue_off()
        self._thread: threading.Thread | None = None
        if not self.off:
            self._thread = threading.Thread(
                target=self._work, name=f"catalogue-{self.campaign}", daemon=True
            )
            self._thread.start()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def add(self, record: Mapping[str, Any]) -> None:
        """Queue a finished run's record (ok or failed) for the catalogue."""
        if self._thread is not None and record.get("status") in ("ok", "failed"):
            self._queue.put(dict(record))

    def close(self, timeout: float = CLOSE_WAIT) -> None:
        """Write what is queued and stop the thread (waits ``timeout`` seconds at most)."""
        if self._thread is None:
            return
        self._queue.put(_STOP)
        self._thread.join(timeout)
        if self._thread.is_alive():
            log.warning(
                "catalogue: not all runs recorded within %.0f s (the run files have them; "
                "'nematic catalogue index' records them)",
                timeout,
            )
        self._thread = None

    # ------------------------------------------------------------------ the thread
    def _fail(self, e: BaseException) -> None:
        if self.problem is None:
            self.problem = str(e).splitlines()[0] if str(e) else type(e).__name__
            log.warning(
                "catalogue: runs of %s not recorded (%s); the run files have them, and "
                "'nematic catalogue index' records them",
                self.campaign,
                self.problem,
            )

    def _open(self) -> Catalogue | None:
        from .opening import open_catalogue

        try:
            if self.url is not None:
                return open_catalogue(self.url, root=self.store.results_root)
            return open_catalogue(self.store.results_root)
        except Exception as e:  # noqa: BLE001 - a catalogue problem never stops a driver
            self._fail(e)
            return None

    def catch_up(self, catalogue: Catalogue) -> int:
        """Record the campaign's runs whose records the catalogue lacks or holds in another
        state (runs a driver without a catalogue ran; a status that changed)."""
        known = known_runs(catalogue, self.campaign)
        current = self.store.scan(save=False)
        stale = [
            rid
            for rid, rec in current.items()
            if known.get(rid) != (rec.get("status"), rec.get("finished"))
        ]
        folder = os.path.relpath(self.store.root, self.store.results_root)
        catalogue.set_campaign(self.campaign, folder, campaign_hash(self.store.root))
        rows = list(record_rows(self.store, stale))
        return catalogue.record(rows, {self.campaign: folder}) if rows else 0

    def _row(self, record: Mapping[str, Any]) -> RunRow:
        rid = str(record["run_id"])
        path, linked = file_path(self.store, rid)
        origin = "reused" if linked or record.get("reused_from") else "made"
        return row_from_record(record, self.campaign, path, origin)

    def _work(self) -> None:
        catalogue = self._open()
        try:
            if catalogue is not None and self._catch_up:
                try:
                    self.written += self.catch_up(catalogue)
                except Exception as e:  # noqa: BLE001 - never stops the driver
                    self._fail(e)
            stop = False
            while not stop:
                batch: list[Mapping[str, Any]] = []
                try:
                    item = self._queue.get(timeout=FLUSH_EVERY)
                except queue.Empty:
                    continue
                while True:
                    if item is _STOP:
                        stop = True
                    else:
                        batch.append(item)
                    try:
                        item = self._queue.get_nowait()
                    except queue.Empty:
                        break
                if batch and catalogue is not None:
                    self._write(catalogue, batch)
        finally:
            if catalogue is not None:
                catalogue.close()

    def _write(self, catalogue: Catalogue, batch: list[Mapping[str, Any]]) -> None:
        try:
            rows = [self._row(r) for r in batch]
            folder = os.path.relpath(self.store.root, self.store.results_root)
            self.written += catalogue.record(rows, {self.campaign: folder})
        except Exception as e:  # noqa: BLE001 - never stops the driver
            self._fail(e)


def recorder_for(store: CampaignStore, url: str | None = None) -> Recorder:
    """The recorder of a campaign's driver (off with ``NEMATIC_CATALOGUE=off``)."""
    return Recorder(store, url)
