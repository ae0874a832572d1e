"""The catalogue's database: connecting (SQLite in WAL mode with a busy timeout, or PostgreSQL
through psycopg 3), migrating to the latest schema (Alembic, on every open), and writing runs in
batches, each batch one transaction.

Every insert or update of a run takes the next numbers of one counter (``meta.seq``, raised
under a row lock, so two writers never interleave their numbers out of commit order): a reader
that saw everything up to ``seq`` N asks for what changed since N (:meth:`Catalogue.changes`).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa

from ..errors import CatalogueError
from ..files import now_iso
from .location import redacted
from .rows import RunRow
from .schema import tables as t

if TYPE_CHECKING:
    from sqlalchemy.engine import Connection, Engine

log = logging.getLogger(__name__)

MIGRATIONS = Path(__file__).with_name("migrations")
#: how long an SQLite writer waits for another's lock before it gives up (milliseconds)
BUSY_TIMEOUT_MS = 30_000
#: the rows of one INSERT statement (SQLite's limit on bound variables is 32766)
CHUNK = 500


class CorruptCatalogue(CatalogueError):
    """The SQLite file is not a readable database (:func:`..opening.open_catalogue` rebuilds
    it from the run files)."""


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
    cursor.execute("PRAGMA journal_mode = WAL")
    cursor.execute("PRAGMA synchronous = NORMAL")
    cursor.execute("PRAGMA foreign_keys = ON")
    cursor.close()


def _sqlite_readonly(dbapi_connection: Any, _record: Any) -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA query_only = ON")
    cursor.close()


def make_engine(url: str, *, readonly: bool = False) -> Engine:
    """An engine for ``url``; :class:`CatalogueError` for a URL of no known database.
    ``readonly``: an SQLite file is opened immutable (no lock, no WAL or shared-memory file
    made: nothing written beside it), for readers that must write nothing."""
    try:
        parsed = sa.engine.make_url(url)
    except sa.exc.ArgumentError as e:
        raise CatalogueError(f"not a database URL: {url!r} ({e})") from None
    backend = parsed.get_backend_name()
    if backend == "sqlite" and readonly:
        path = Path(parsed.database or "").resolve()
        engine = sa.create_engine(
            f"sqlite:///file:{path}?mode=ro&immutable=1&uri=true", poolclass=sa.pool.NullPool
        )
        sa.event.listen(engine, "connect", _sqlite_readonly)
        return engine
    if backend == "sqlite":
        engine = sa.create_engine(
            parsed, connect_args={"timeout": BUSY_TIMEOUT_MS / 1000}, poolclass=sa.pool.NullPool
        )
        sa.event.listen(engine, "connect", _sqlite_pragmas)
        return engine
    if backend == "postgresql":
        if parsed.drivername == "postgresql":  # psycopg 3, not psycopg2
            parsed = parsed.set(drivername="postgresql+psycopg")
        try:
            return sa.create_engine(parsed, pool_pre_ping=True)
        except ImportError:
            raise CatalogueError(
                "a PostgreSQL catalogue needs psycopg 3: "
                "pip install 'active-nematic-solids[postgres]'"
            ) from None
    raise CatalogueError(f"the catalogue is SQLite or PostgreSQL, not {backend} ({redacted(url)})")


#: the key of PostgreSQL's advisory lock held while migrating (one process at a time)
ADVISORY_LOCK = 0x6E656D61


@contextlib.contextmanager
def _sqlite_lock(engine: Engine) -> Iterator[None]:
    """An exclusive lock on ``<file>.lock`` beside an SQLite catalogue: two processes that
    open a new catalogue at once migrate it one after the other."""
    import fcntl

    database = engine.url.database
    if not database or database == ":memory:":
        yield
        return
    with open(f"{database}.lock", "a+b") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def upgrade(engine: Engine) -> None:
    """Apply every migration not applied yet (Alembic, programmatic configuration), one
    process at a time (a file lock for SQLite, an advisory lock for PostgreSQL)."""
    from alembic import command
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    sqlite = engine.dialect.name == "sqlite"
    with _sqlite_lock(engine) if sqlite else contextlib.nullcontext(), engine.begin() as conn:
        if not sqlite:
            conn.execute(sa.text("SELECT pg_advisory_xact_lock(:k)"), {"k": ADVISORY_LOCK})
        config.attributes["connection"] = conn
        command.upgrade(config, "head")


def head_revision() -> str:
    """The latest migration's revision (what ``alembic_version`` holds once migrated)."""
    from alembic.config import Config
    from alembic.script import ScriptDirectory

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    head = ScriptDirectory.from_config(config).get_current_head()
    assert head is not None
    return head


def _upsert(
    conn: Connection,
    table: sa.Table,
    rows: list[dict[str, Any]],
    keys: Sequence[str],
    update: Sequence[str] | None,
) -> None:
    """INSERT the rows; on a key that exists, update the columns ``update`` (None: nothing)."""
    if not rows:
        return
    if conn.dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert
    else:
        from sqlalchemy.dialects.sqlite import insert  # type: ignore[assignment]
    # one statement, executed for many rows (SQLAlchemy batches them: "insertmanyvalues")
    stmt = insert(table)
    if update:
        stmt = stmt.on_conflict_do_update(
            index_elements=list(keys), set_={c: stmt.excluded[c] for c in update}
        )
    else:
        stmt = stmt.on_conflict_do_nothing(index_elements=list(keys))
    conn.execute(stmt, rows)


def next_seqs(conn: Connection, n: int) -> int:
    """Take ``n`` numbers of the counter; returns the first."""
    top = conn.execute(
        t.meta.update()
        .where(t.meta.c.key == "seq")
        .values(number=t.meta.c.number + n)
        .returning(t.meta.c.number)
    ).scalar_one()
    return int(top) - n + 1


#: what SQLite says of a file that is not a database, or a damaged one
CORRUPT = ("file is not a database", "malformed", "file is encrypted")


def is_corrupt(e: BaseException) -> bool:
    """Whether SQLite's error says the file is damaged (not: locked, missing table, ...)."""
    return any(text in str(getattr(e, "orig", e)) for text in CORRUPT)


#: a campaign's counts of ``campaign_summary`` that one membership adds to
COUNTS = ("runs", "ok", "failed", "made", "reused")


def _counted(status: str | None, origin: str) -> dict[str, int]:
    """What one run (its status) held by a campaign (its origin there) adds to its counts."""
    return {
        "runs": 1,
        "ok": int(status == "ok"),
        "failed": int(status != "ok"),
        "made": int(origin == "made"),
        "reused": int(origin == "reused"),
    }


def _summary_state(
    conn: Connection, run_ids: Sequence[str]
) -> tuple[dict[str, str], dict[tuple[str, str], str]]:
    """The runs' statuses and memberships (campaign, run) -> origin before a write."""
    r, m = t.runs, t.campaign_runs
    status: dict[str, str] = {}
    members: dict[tuple[str, str], str] = {}
    for start in range(0, len(run_ids), CHUNK):
        chunk = list(run_ids[start : start + CHUNK])
        for rid, st in conn.execute(sa.select(r.c.run_id, r.c.status).where(r.c.run_id.in_(chunk))):
            status[rid] = st
        rows = conn.execute(
            sa.select(m.c.campaign, m.c.run_id, m.c.origin).where(m.c.run_id.in_(chunk))
        )
        for name, rid, origin in rows:
            members[(name, rid)] = origin
    return status, members


def _update_summary(
    conn: Connection,
    before: tuple[dict[str, str], dict[tuple[str, str], str]],
    status: Mapping[str, str],
    origins: Mapping[tuple[str, str], str],
    seq: int,
) -> None:
    """Move each campaign's counts by what the write changed: every membership of a written
    run (in any campaign: a reused run's new status counts wherever it is held) less what it
    counted before; ``seq``: the write's last."""
    old_status, old_members = before
    delta: dict[str, dict[str, int]] = {}
    for key in set(old_members) | set(origins):
        name, rid = key
        d = delta.setdefault(name, dict.fromkeys(COUNTS, 0))
        if key in old_members:
            for k, v in _counted(old_status.get(rid), old_members[key]).items():
                d[k] -= v
        new_status = status.get(rid, old_status.get(rid))
        for k, v in _counted(new_status, origins.get(key, old_members.get(key, ""))).items():
            d[k] += v
    s = t.campaign_summary
    for name in sorted(delta):
        conn.execute(
            s.update()
            .where(s.c.campaign == name)
            .values(**{k: s.c[k] + v for k, v in delta[name].items()}, seq=seq)
        )


class Database:
    """The connection to one catalogue: migrated on construction, written in batches.
    ``readonly``: not migrated, an SQLite file opened immutable (:func:`make_engine`); a
    catalogue of another revision than the code's is refused."""

    def __init__(self, url: str, *, readonly: bool = False):
        self.url = url
        self.readonly = readonly
        self.engine = make_engine(url, readonly=readonly)
        try:
            if readonly:
                self._check_revision()
            else:
                upgrade(self.engine)
        except sa.exc.DatabaseError as e:
            self.engine.dispose()
            if self.engine.dialect.name == "sqlite" and is_corrupt(e):
                raise CorruptCatalogue(
                    f"{redacted(url)} is not a readable catalogue: {e.orig}"
                ) from e
            raise CatalogueError(f"cannot open the catalogue {redacted(url)}: {e.orig}") from e
        except sa.exc.OperationalError as e:  # pragma: no cover - subclass of DatabaseError
            raise CatalogueError(f"cannot open the catalogue {redacted(url)}: {e.orig}") from e

    def _check_revision(self) -> None:
        with self.engine.connect() as conn:
            found = conn.execute(sa.text("SELECT version_num FROM alembic_version")).scalar()
        if found != head_revision():
            raise CatalogueError(
                f"the catalogue {redacted(self.url)} is at revision {found}, the code's is "
                f"{head_revision()}: open it once to migrate it"
            )

    @property
    def dialect(self) -> str:
        return self.engine.dialect.name

    def close(self) -> None:
        self.engine.dispose()

    # ---------------------------------------------------------------- meta
    def get_meta(self, key: str) -> str | None:
        with self.engine.connect() as conn:
            return conn.execute(
                sa.select(t.meta.c.value).where(t.meta.c.key == key)
            ).scalar_one_or_none()

    def set_meta(self, key: str, value: str) -> None:
        with self.engine.begin() as conn:
            _upsert(conn, t.meta, [{"key": key, "value": value}], ["key"], ["value"])

    def last_seq(self) -> int:
        with self.engine.connect() as conn:
            return int(
                conn.execute(sa.select(t.meta.c.number).where(t.meta.c.key == "seq")).scalar_one()
            )

    # ---------------------------------------------------------------- writing
    def ensure_campaign(
        self, conn: Connection, name: str, folder: str, sha256: str | None = None
    ) -> None:
        """Insert the campaign, or refresh its folder, last sight and (if given) its hash."""
        now = now_iso()
        row = {
            "name": name,
            "folder": folder,
            "campaign_sha256": sha256,
            "first_seen": now,
            "last_seen": now,
        }
        update = ["folder", "last_seen"] + (["campaign_sha256"] if sha256 else [])
        _upsert(conn, t.campaigns, [row], ["name"], update)
        zero = {k: 0 for k in ("runs", "ok", "failed", "made", "reused", "seq")}
        _upsert(conn, t.campaign_summary, [{"campaign": name, **zero}], ["campaign"], None)

    def write(self, rows: Iterable[RunRow], folders: dict[str, str] | None = None) -> int:
        """Record ``rows`` in one transaction (campaigns created as needed, ``folders``:
        campaign -> its folder relative to the root, default its name); returns how many."""
        rows = list(rows)
        if not rows:
            return 0
        # one row per run id (the last wins), one membership per (campaign, run)
        by_run = {r.run_id: r for r in rows}
        with self.engine.begin() as conn:
            for name in sorted({r.campaign for r in rows}):
                self.ensure_campaign(conn, name, (folders or {}).get(name, name))
            first = next_seqs(conn, len(by_run))  # the counter's row lock: writers in turn
            ids = list(by_run)
            before = _summary_state(conn, ids)  # read under it: no other writer in between
            run_rows = [{**r.run_values(), "seq": first + k} for k, r in enumerate(by_run.values())]
            columns = [c for c in run_rows[0] if c != "run_id"]
            _upsert(conn, t.runs, run_rows, ["run_id"], columns)
            for start in range(0, len(ids), CHUNK):
                conn.execute(
                    t.run_values.delete().where(
                        t.run_values.c.run_id.in_(ids[start : start + CHUNK])
                    )
                )
            values = [v for r in by_run.values() for v in r.key_values()]
            _upsert(conn, t.run_values, values, ["run_id", "space", "key"], None)
            members = {
                (r.campaign, r.run_id): {
                    "campaign": r.campaign,
                    "run_id": r.run_id,
                    "origin": r.origin,
                    "coords": r.coords or None,
                }
                for r in rows
            }
            _upsert(
                conn,
                t.campaign_runs,
                list(members.values()),
                ["campaign", "run_id"],
                ["origin", "coords"],
            )
            status = {r.run_id: r.status for r in by_run.values()}
            origins = {key: str(m["origin"]) for key, m in members.items()}
            _update_summary(conn, before, status, origins, first + len(by_run) - 1)
            parents = {
                (r.run_id, kind, parent): {
                    "run_id": r.run_id,
                    "kind": kind,
                    "parent_run_id": parent,
                }
                for r in by_run.values()
                for parent, kind in r.parents
            }
            _upsert(
                conn, t.lineage, list(parents.values()), ["run_id", "kind", "parent_run_id"], None
            )
        return len(rows)
