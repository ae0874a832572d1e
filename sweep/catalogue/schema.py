"""The catalogue's tables (SQLAlchemy Core), as the latest migration leaves them.

No column is named after a parameter or an observable of any model: a run's parameters,
numerics and scalars are JSON documents (``runs.parameters``, ``runs.numerics``,
``runs.scalars``), and every number or word of them is also a row of the key/value table
``run_values`` (``space``: parameters, numerics, scalars or coords; ``key``; ``num_value`` or
``text_value``), indexed, so a range over any key is an indexed query on SQLite and PostgreSQL
alike (JSON operators differ between the two; a key/value table does not).

- ``meta``: key/value facts of the catalogue (the results root it indexes, the counter
  behind ``runs.seq``).
- ``campaigns``: one row per results folder (``name``, its ``folder`` relative to the root,
  the SHA-256 of its campaign file's text, first and last seen).
- ``runs``: one row per run (``run_id``), whichever campaigns hold it; ``path`` is its file
  relative to the root (None: a run known from phase.nc alone, or one that failed before
  writing a file); ``source``: "record" (its ``runs/<id>.json``) or "phase" (a phase.nc
  without run files); ``seq`` grows on every insert or update (:meth:`Catalogue.changes`).
- ``campaign_runs``: which campaigns hold which runs, with the run's swept values there
  (``coords``) and its ``origin``: "made" (the campaign ran it) or "reused" (another
  campaign's file, used in place).
- ``lineage``: ``(run_id, parent_run_id, kind)``, ``kind`` one of :data:`LINEAGE_KINDS`.
- ``campaign_summary``: each campaign's counts of runs (``runs``, ``ok``, ``failed``,
  ``made``, ``reused``) and the ``seq`` of its latest change, kept by the writer in the
  transaction that records the runs (:meth:`Database.write`), so the campaign list reads one
  row per campaign whatever the number of runs.

Changing a table means a new migration in ``migrations/versions/`` and the same change here.
"""

from __future__ import annotations

import sqlalchemy as sa

metadata = sa.MetaData()

#: the kinds of lineage: a longer run continued a shorter one's end state, a run began from
#: another campaign's run (``initial.from``), a run of a chain began from its predecessor
LINEAGE_KINDS = ("continued", "initial_from", "chain")
#: how a campaign came to hold a run
ORIGINS = ("made", "reused")
#: the spaces of ``run_values``
SPACES = ("parameters", "numerics", "scalars", "coords")

meta = sa.Table(
    "meta",
    metadata,
    sa.Column("key", sa.String(64), primary_key=True),
    sa.Column("value", sa.Text, nullable=True),
    sa.Column("number", sa.BigInteger, nullable=True),
)

campaigns = sa.Table(
    "campaigns",
    metadata,
    sa.Column("name", sa.String(255), primary_key=True),
    sa.Column("folder", sa.Text, nullable=False),
    sa.Column("campaign_sha256", sa.String(64), nullable=True),
    sa.Column("first_seen", sa.String(32), nullable=False),
    sa.Column("last_seen", sa.String(32), nullable=False),
)

runs = sa.Table(
    "runs",
    metadata,
    sa.Column("run_id", sa.String(64), primary_key=True),
    sa.Column("trajectory_id", sa.String(64), nullable=True, index=True),
    sa.Column("status", sa.String(16), nullable=False, index=True),
    sa.Column("reason", sa.String(64), nullable=True),
    sa.Column("detail", sa.Text, nullable=True),
    sa.Column("started", sa.String(32), nullable=True),
    sa.Column("finished", sa.String(32), nullable=True),
    sa.Column("wall_time", sa.Float, nullable=True),
    sa.Column("t_final", sa.Float, nullable=True),
    sa.Column("end_state", sa.Float, nullable=True),
    sa.Column("seed", sa.BigInteger, nullable=True),
    sa.Column("path", sa.Text, nullable=True),
    sa.Column("source", sa.String(16), nullable=False),
    sa.Column("code_version", sa.String(64), nullable=True),
    sa.Column("parameters", sa.JSON, nullable=True),
    sa.Column("numerics", sa.JSON, nullable=True),
    sa.Column("scalars", sa.JSON, nullable=True),
    sa.Column("seq", sa.BigInteger, nullable=False, index=True),
)

campaign_runs = sa.Table(
    "campaign_runs",
    metadata,
    sa.Column("campaign", sa.String(255), sa.ForeignKey("campaigns.name"), primary_key=True),
    sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id"), primary_key=True),
    sa.Column("origin", sa.String(16), nullable=False),
    sa.Column("coords", sa.JSON, nullable=True),
    sa.Index("ix_campaign_runs_run_id", "run_id"),
)

lineage = sa.Table(
    "lineage",
    metadata,
    sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id"), primary_key=True),
    sa.Column("kind", sa.String(16), primary_key=True),
    sa.Column("parent_run_id", sa.String(64), primary_key=True),
    sa.Index("ix_lineage_parent", "parent_run_id"),
)

run_values = sa.Table(
    "run_values",
    metadata,
    sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id"), primary_key=True),
    sa.Column("space", sa.String(16), primary_key=True),
    sa.Column("key", sa.String(255), primary_key=True),
    sa.Column("num_value", sa.Float, nullable=True),
    sa.Column("text_value", sa.Text, nullable=True),
    sa.Index("ix_run_values_num", "key", "num_value"),
    sa.Index("ix_run_values_text", "key", "text_value"),
)


campaign_summary = sa.Table(
    "campaign_summary",
    metadata,
    sa.Column("campaign", sa.String(255), sa.ForeignKey("campaigns.name"), primary_key=True),
    sa.Column("runs", sa.BigInteger, nullable=False),
    sa.Column("ok", sa.BigInteger, nullable=False),
    sa.Column("failed", sa.BigInteger, nullable=False),
    sa.Column("made", sa.BigInteger, nullable=False),
    sa.Column("reused", sa.BigInteger, nullable=False),
    sa.Column("seq", sa.BigInteger, nullable=False),
)


class _Tables:
    """The tables by name, as ``t.runs`` (what the catalogue's modules import as ``t``)."""

    meta = meta
    campaigns = campaigns
    runs = runs
    campaign_runs = campaign_runs
    lineage = lineage
    run_values = run_values
    campaign_summary = campaign_summary
    SPACES = SPACES


tables = _Tables
