"""The catalogue of runs: meta, campaigns, runs, campaign_runs, lineage, run_values.

Revision ID: r0001
Revises:
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "r0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "meta",
        sa.Column("key", sa.String(64), primary_key=True),
        sa.Column("value", sa.Text, nullable=True),
        sa.Column("number", sa.BigInteger, nullable=True),
    )
    op.create_table(
        "campaigns",
        sa.Column("name", sa.String(255), primary_key=True),
        sa.Column("folder", sa.Text, nullable=False),
        sa.Column("campaign_sha256", sa.String(64), nullable=True),
        sa.Column("first_seen", sa.String(32), nullable=False),
        sa.Column("last_seen", sa.String(32), nullable=False),
    )
    op.create_table(
        "runs",
        sa.Column("run_id", sa.String(64), primary_key=True),
        sa.Column("trajectory_id", sa.String(64), nullable=True),
        sa.Column("status", sa.String(16), nullable=False),
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
        sa.Column("seq", sa.BigInteger, nullable=False),
    )
    op.create_index("ix_runs_trajectory_id", "runs", ["trajectory_id"])
    op.create_index("ix_runs_status", "runs", ["status"])
    op.create_index("ix_runs_seq", "runs", ["seq"])
    op.create_table(
        "campaign_runs",
        sa.Column("campaign", sa.String(255), sa.ForeignKey("campaigns.name"), primary_key=True),
        sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id"), primary_key=True),
        sa.Column("origin", sa.String(16), nullable=False),
        sa.Column("coords", sa.JSON, nullable=True),
    )
    op.create_index("ix_campaign_runs_run_id", "campaign_runs", ["run_id"])
    op.create_table(
        "lineage",
        sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id"), primary_key=True),
        sa.Column("kind", sa.String(16), primary_key=True),
        sa.Column("parent_run_id", sa.String(64), primary_key=True),
    )
    op.create_index("ix_lineage_parent", "lineage", ["parent_run_id"])
    op.create_table(
        "run_values",
        sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id"), primary_key=True),
        sa.Column("space", sa.String(16), primary_key=True),
        sa.Column("key", sa.String(255), primary_key=True),
        sa.Column("num_value", sa.Float, nullable=True),
        sa.Column("text_value", sa.Text, nullable=True),
    )
    op.create_index("ix_run_values_num", "run_values", ["key", "num_value"])
    op.create_index("ix_run_values_text", "run_values", ["key", "text_value"])
    op.bulk_insert(
        sa.table("meta", sa.column("key", sa.String), sa.column("number", sa.BigInteger)),
        [{"key": "seq", "number": 0}],
    )


def downgrade() -> None:
    for name in ("run_values", "lineage", "campaign_runs", "runs", "campaigns", "meta"):
        op.drop_table(name)
