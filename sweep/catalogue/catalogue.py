""":class:`Catalogue`: one results root's catalogue of runs, read and written from Python.

Run files stay the source of truth: everything here can be rebuilt from them
(:func:`nematic_solids.sweep.catalogue.index.index_root`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa

from .database import Database
from .location import redacted
from .query import Condition, campaign_counts, frame, memberships, select_runs
from .rows import RunRow
from .schema import tables as t

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr


class Catalogue:
    """The catalogue of every run of every campaign under one results root.

    Read: :meth:`runs`, :meth:`campaigns`, :meth:`changes`, :meth:`run`, :meth:`lineage`,
    :meth:`last_seq`, :meth:`finished`, :meth:`longest_finished`. Write: :meth:`record`
    (rows of :class:`~nematic_solids.sweep.catalogue.rows.RunRow`, one transaction)."""

    def __init__(self, database: Database, root: Path | None):
        self.db = database
        #: the results root whose files the catalogue indexes (paths are relative to it)
        self.root = root
        #: how it was opened: "opened", "created" or "rebuilt" (a corrupt file moved aside)
        self.state = "opened"
        #: where a corrupt SQLite file was moved to (``state == "rebuilt"``)
        self.moved_to: Path | None = None

    def __repr__(self) -> str:
        return f"<Catalogue {redacted(self.db.url)} of {self.root}>"

    def __enter__(self) -> Catalogue:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def url(self) -> str:
        return self.db.url

    @property
    def engine(self) -> sa.Engine:
        """The SQLAlchemy engine (for a table of one's own in a later migration)."""
        return self.db.engine

    def close(self) -> None:
        self.db.close()

    # ------------------------------------------------------------------ writing
    def record(self, rows: Iterable[RunRow], folders: dict[str, str] | None = None) -> int:
        """Record runs (inserted or updated, each with a new ``seq``) in one transaction."""
        return self.db.write(rows, folders)

    def set_campaign(self, name: str, folder: str, sha256: str | None = None) -> None:
        """Record a campaign (its folder relative to the root, its campaign file's hash)."""
        with self.db.engine.begin() as conn:
            self.db.ensure_campaign(conn, name, folder, sha256)

    # ------------------------------------------------------------------ reading
    def last_seq(self) -> int:
        """The ``seq`` of the latest insert or update (0: none yet)."""
        return self.db.last_seq()

    def _rows(self, stmt: sa.Select[Any], campaign: str | None) -> list[dict[str, Any]]:
        with self.db.engine.connect() as conn:
            rows = [dict(r._mapping) for r in conn.execute(stmt)]
            if campaign is None and rows:
                members = memberships(conn, [r["run_id"] for r in rows])
                for row in rows:
                    held = members.get(row["run_id"], [])
                    row["campaigns"] = ",".join(m["campaign"] for m in held)
                    row["coords"] = next((m["coords"] for m in held if m["coords"]), None)
        return rows

    def runs(
        self,
        campaign: str | None = None,
        where: Mapping[str, Any] | Sequence[Condition] | None = None,
        status: str | None = None,
    ) -> pd.DataFrame:
        """The runs (one row each) of ``campaign`` (None: every campaign) whose values meet
        every condition of ``where`` (``{"K": 1e-5, "alpha_minus_B": (0.5, 0.7),
        "mechanics": "finite"}``; :mod:`~nematic_solids.sweep.catalogue.query`) and of
        ``status`` ("ok", "failed"). Columns: the run's (``run_id``, ``status``, ``reason``,
        ``seed``, ``t_final``, ``wall_time``, ``path``, ...), ``campaign`` and ``origin``
        (with ``campaign``) or ``campaigns`` (comma-separated), then every swept value,
        parameter, numeric and scalar by name."""
        return frame(self._rows(select_runs(campaign, where, status), campaign))

    def changes(self, since_seq: int = 0, limit: int | None = None) -> pd.DataFrame:
        """The runs inserted or updated after ``since_seq``, in ``seq`` order, ``limit`` at
        most (the table of :meth:`runs`; its last ``seq`` is where the next poll starts)."""
        stmt = select_runs(since_seq=since_seq)
        return frame(self._rows(stmt if limit is None else stmt.limit(limit), None))

    def campaign_changes(
        self, campaign: str, since_seq: int, upto_seq: int
    ) -> list[tuple[str, int]]:
        """``(run_id, seq)`` of the runs of ``campaign`` inserted or updated after
        ``since_seq`` and up to ``upto_seq`` (both ends from :meth:`last_seq`: what a reader
        saw before and now), in ``seq`` order; through the ``seq`` index, so its cost follows
        the number of changes, not of runs."""
        r, m = t.runs, t.campaign_runs
        stmt = (
            sa.select(r.c.run_id, r.c.seq)
            .join(m, m.c.run_id == r.c.run_id)
            .where(m.c.campaign == campaign, r.c.seq > since_seq, r.c.seq <= upto_seq)
            .order_by(r.c.seq)
        )
        with self.db.engine.connect() as conn:
            return [(str(rid), int(seq)) for rid, seq in conn.execute(stmt)]

    def campaign_done(self, campaign: str, scalar: str) -> Sequence[sa.Row[Any, Any, Any]]:
        """``(run_id, wall time, the value of scalar ``scalar`` or None)`` of every run of
        ``campaign`` done ok, in one query (what a campaign's page needs of such a run)."""
        r, m, v = t.runs, t.campaign_runs, t.run_values
        value = sa.and_(v.c.run_id == r.c.run_id, v.c.space == "scalars", v.c.key == scalar)
        stmt = (
            sa.select(r.c.run_id, r.c.wall_time, v.c.num_value)
            .join(m, m.c.run_id == r.c.run_id)
            .outerjoin(v, value)
            .where(m.c.campaign == campaign, r.c.status == "ok")
        )
        with self.db.engine.connect() as conn:
            return conn.execute(stmt).all()

    def campaigns(self) -> pd.DataFrame:
        """One row per campaign: ``name``, ``folder``, ``campaign_sha256``, ``first_seen``,
        ``last_seen`` and its counts of runs (``runs``, ``ok``, ``failed``, ``made``,
        ``reused``)."""
        import pandas as pd

        with self.db.engine.connect() as conn:
            rows = [dict(r._mapping) for r in conn.execute(campaign_counts())]
        columns = [
            "name",
            "folder",
            "campaign_sha256",
            "first_seen",
            "last_seen",
            "runs",
            "ok",
            "failed",
            "made",
            "reused",
        ]
        return pd.DataFrame(rows, columns=columns)

    def run(self, run_id: str) -> dict[str, Any] | None:
        """One run's row (with ``campaigns``: its memberships, and ``parents``), or None."""
        with self.db.engine.connect() as conn:
            row = conn.execute(sa.select(t.runs).where(t.runs.c.run_id == run_id)).first()
            if row is None:
                return None
            out = dict(row._mapping)
            out["campaigns"] = memberships(conn, [run_id]).get(run_id, [])
        out["parents"] = self.lineage(run_id)
        return out

    def lineage(self, run_id: str) -> list[tuple[str, str]]:
        """``(parent run id, kind)`` of a run (kind: continued, initial_from, chain)."""
        with self.db.engine.connect() as conn:
            rows = conn.execute(
                sa.select(t.lineage.c.parent_run_id, t.lineage.c.kind)
                .where(t.lineage.c.run_id == run_id)
                .order_by(t.lineage.c.kind)
            )
            return [(str(p), str(k)) for p, k in rows]

    def finished(self, run_ids: Iterable[str]) -> dict[str, dict[str, Any]]:
        """Of ``run_ids``, those finished (status ok) with a file: run_id -> ``path``
        (relative to the root) and ``campaign`` (one that made it)."""
        ids = list(dict.fromkeys(run_ids))
        out: dict[str, dict[str, Any]] = {}
        r, m = t.runs, t.campaign_runs
        with self.db.engine.connect() as conn:
            for start in range(0, len(ids), 500):
                chunk = ids[start : start + 500]
                rows = conn.execute(
                    sa.select(r.c.run_id, r.c.path, m.c.campaign, m.c.origin)
                    .join(m, m.c.run_id == r.c.run_id)
                    .where(r.c.run_id.in_(chunk), r.c.status == "ok", r.c.path.is_not(None))
                    .order_by(m.c.origin, m.c.campaign)  # "made" before "reused"
                )
                for rid, path, name, _origin in rows:
                    out.setdefault(rid, {"path": path, "campaign": name})
        return out

    def longest_finished(
        self, trajectories: Iterable[str]
    ) -> dict[str, list[tuple[float, str, str, str]]]:
        """The finished runs of each trajectory that kept an end state: trajectory ->
        ``(end_state, run_id, path, campaign)``, longest first."""
        ids = list(dict.fromkeys(trajectories))
        out: dict[str, list[tuple[float, str, str, str]]] = {}
        r, m = t.runs, t.campaign_runs
        with self.db.engine.connect() as conn:
            for start in range(0, len(ids), 500):
                chunk = ids[start : start + 500]
                rows = conn.execute(
                    sa.select(
                        r.c.trajectory_id,
                        r.c.end_state,
                        r.c.run_id,
                        r.c.path,
                        sa.func.min(m.c.campaign),
                    )
                    .join(m, m.c.run_id == r.c.run_id)
                    .where(
                        r.c.trajectory_id.in_(chunk),
                        r.c.status == "ok",
                        r.c.end_state.is_not(None),
                        r.c.path.is_not(None),
                    )
                    .group_by(r.c.trajectory_id, r.c.end_state, r.c.run_id, r.c.path)
                )
                for traj, end, rid, path, name in rows:
                    out.setdefault(traj, []).append((float(end), rid, path, name))
        for found in out.values():
            found.sort(reverse=True)
        return out

    def dataset(
        self,
        campaign: str | None = None,
        where: Mapping[str, Any] | Sequence[Condition] | None = None,
        status: str | None = None,
    ) -> xr.Dataset:
        """:meth:`runs` as an xarray Dataset with one dimension ``run`` (indexed by
        ``run_id``)."""
        import xarray as xr

        df = self.runs(campaign, where, status)
        df = df.set_index("run_id") if "run_id" in df else df
        df.index.name = "run"
        simple = [c for c in df.columns if not df[c].map(lambda v: isinstance(v, tuple)).any()]
        return xr.Dataset.from_dataframe(df[simple])
