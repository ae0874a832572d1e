"""The service's persistent queue of campaigns: the table ``service_queue`` of the catalogue's
database (created by the Alembic migration ``r0002_service_queue`` of the catalogue's
``migrations/versions/``; :data:`queue_table` is the same table for SQLAlchemy Core's queries),
written by the service alone.

A submitted campaign is a row: its YAML text and where it came from (relative paths in it are
read from there), the command-line overrides, its priority, its state (:data:`STATES`) and
times, the estimate made before it started and the outcome. The order (:meth:`QueueStore.next`):
a campaign the service was running when it stopped (or was killed) first, so that it resumes
from its runs' files; then the highest priority; then the earliest submission. A running
campaign is never preempted: a higher priority takes the workers when it ends."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import sqlalchemy as sa

from ..files import now_iso

QUEUED, RUNNING, DONE, FAILED, CANCELLED = "queued", "running", "done", "failed", "cancelled"
STATES = (QUEUED, RUNNING, DONE, FAILED, CANCELLED)
#: States a campaign leaves no more.
FINAL = (DONE, FAILED, CANCELLED)

metadata = sa.MetaData()
queue_table = sa.Table(
    "service_queue",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("name", sa.String(200), nullable=False),
    sa.Column("source", sa.Text, nullable=False),
    sa.Column("text", sa.Text, nullable=False),
    sa.Column("overrides", sa.Text, nullable=False, default="{}"),
    sa.Column("priority", sa.Integer, nullable=False, default=0),
    sa.Column("state", sa.String(16), nullable=False),
    sa.Column("submitted", sa.String(40), nullable=False),
    sa.Column("started", sa.String(40)),
    sa.Column("finished", sa.String(40)),
    sa.Column("starts", sa.Integer, nullable=False, default=0),
    sa.Column("cancel_requested", sa.Boolean, nullable=False, default=False),
    sa.Column("message", sa.Text, nullable=False, default=""),
    sa.Column("estimate", sa.Text),
    sa.Column("outcome", sa.Text),
    #: the queue's own change counter: every write of a row gives it the next value
    sa.Column("version", sa.Integer, nullable=False, default=0),
)


@dataclass(frozen=True)
class Entry:
    """One row of the queue."""

    id: int
    name: str
    source: str
    text: str
    overrides: dict[str, Any]
    priority: int
    state: str
    submitted: str
    started: str | None
    finished: str | None
    starts: int
    cancel_requested: bool
    message: str
    estimate: dict[str, Any] | None
    outcome: dict[str, Any] | None
    version: int

    @classmethod
    def of(cls, row: Any) -> Entry:
        m = row._mapping
        return cls(
            id=int(m["id"]),
            name=str(m["name"]),
            source=str(m["source"]),
            text=str(m["text"]),
            overrides=json.loads(m["overrides"] or "{}"),
            priority=int(m["priority"]),
            state=str(m["state"]),
            submitted=str(m["submitted"]),
            started=m["started"],
            finished=m["finished"],
            starts=int(m["starts"]),
            cancel_requested=bool(m["cancel_requested"]),
            message=str(m["message"] or ""),
            estimate=json.loads(m["estimate"]) if m["estimate"] else None,
            outcome=json.loads(m["outcome"]) if m["outcome"] else None,
            version=int(m["version"]),
        )

    def public(self) -> dict[str, Any]:
        """What the API shows of it (all but the campaign's text)."""
        out = {k: v for k, v in self.__dict__.items() if k != "text"}
        return out


#: The order in which queued campaigns start (see the module's docstring); the campaigns that
#: ended come after, in the order they were submitted.
ORDER = (
    sa.case((queue_table.c.state == RUNNING, 0), (queue_table.c.state == QUEUED, 1), else_=2),
    queue_table.c.priority.desc(),
    queue_table.c.submitted,
    queue_table.c.id,
)


class QueueStore:
    """The queue in a database (any SQLAlchemy engine: SQLite or PostgreSQL)."""

    def __init__(self, engine: sa.Engine):
        self.engine = engine

    def _next_version(self, conn: sa.Connection) -> int:
        return int(conn.execute(sa.select(sa.func.max(queue_table.c.version))).scalar() or 0) + 1

    def _update(self, entry_id: int, **values: Any) -> None:
        with self.engine.begin() as conn:
            values["version"] = self._next_version(conn)
            conn.execute(queue_table.update().where(queue_table.c.id == entry_id).values(**values))

    def submit(
        self, name: str, source: str, text: str, overrides: dict[str, Any], priority: int
    ) -> Entry:
        with self.engine.begin() as conn:
            result = conn.execute(
                queue_table.insert().values(
                    name=name,
                    source=source,
                    text=text,
                    overrides=json.dumps(overrides, sort_keys=True),
                    priority=priority,
                    state=QUEUED,
                    submitted=now_iso(),
                    starts=0,
                    cancel_requested=False,
                    message="",
                    version=self._next_version(conn),
                )
            )
            key = result.inserted_primary_key
            assert key is not None
            new_id = int(key[0])
        return self.get(new_id)

    def get(self, entry_id: int) -> Entry:
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(queue_table).where(queue_table.c.id == entry_id)).first()
        if row is None:
            raise KeyError(entry_id)
        return Entry.of(row)

    def entries(self, states: tuple[str, ...] = STATES, since: int = 0) -> list[Entry]:
        """The rows in ``states`` changed after version ``since``, in the queue's order."""
        query = (
            sa.select(queue_table)
            .where(queue_table.c.state.in_(states), queue_table.c.version > since)
            .order_by(*ORDER)
        )
        with self.engine.connect() as conn:
            return [Entry.of(row) for row in conn.execute(query)]

    def version(self) -> int:
        with self.engine.connect() as conn:
            return int(conn.execute(sa.select(sa.func.max(queue_table.c.version))).scalar() or 0)

    def next(self, skip: set[int] | None = None) -> Entry | None:
        """The campaign to run next (a running one left by a stopped service first), or
        ``None``; ``skip``: ids that wait (their folder is in use by another driver)."""
        for entry in self.entries((RUNNING, QUEUED)):
            if not skip or entry.id not in skip:
                return entry
        return None

    def start(self, entry: Entry, estimate: dict[str, Any] | None) -> None:
        self._update(
            entry.id,
            state=RUNNING,
            started=now_iso(),
            starts=entry.starts + 1,
            message="",
            estimate=json.dumps(estimate) if estimate is not None else None,
        )

    def requeue(self, entry_id: int, message: str) -> None:
        """Back to the queue (the service stops; it resumes on its next start)."""
        self._update(entry_id, state=QUEUED, message=message)

    def note(self, entry_id: int, message: str) -> None:
        self._update(entry_id, message=message)

    def finish(
        self, entry_id: int, state: str, message: str, outcome: dict[str, Any] | None = None
    ) -> None:
        assert state in FINAL
        self._update(
            entry_id,
            state=state,
            finished=now_iso(),
            message=message,
            outcome=json.dumps(outcome) if outcome is not None else None,
        )

    def cancel(self, entry_id: int) -> Entry:
        """Cancel a campaign: a queued one at once; a running one is marked, and the service
        stops it (its runs in flight stay pending: a rerun resumes them). Raises ``KeyError``
        for an unknown id, ``ValueError`` for a campaign that has ended."""
        entry = self.get(entry_id)
        if entry.state in FINAL:
            raise ValueError(f"campaign {entry_id} ({entry.name}) has ended: {entry.state}")
        if entry.state == QUEUED:
            self.finish(entry_id, CANCELLED, "cancelled before it started")
        else:
            self._update(entry_id, cancel_requested=True, message="cancelling")
        return self.get(entry_id)
