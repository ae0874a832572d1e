"""Each campaign's counts of runs, kept by the writer as it records runs (the campaign list
reads one row per campaign instead of counting every run), filled here from the runs already
recorded.

Revision ID: r0003
Revises: r0002
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "r0003"
down_revision = "r0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "campaign_summary",
        sa.Column("campaign", sa.String(255), sa.ForeignKey("campaigns.name"), primary_key=True),
        sa.Column("runs", sa.BigInteger, nullable=False),
        sa.Column("ok", sa.BigInteger, nullable=False),
        sa.Column("failed", sa.BigInteger, nullable=False),
        sa.Column("made", sa.BigInteger, nullable=False),
        sa.Column("reused", sa.BigInteger, nullable=False),
        sa.Column("seq", sa.BigInteger, nullable=False),
    )
    op.execute(
        """
        INSERT INTO campaign_summary (campaign, runs, ok, failed, made, reused, seq)
        SELECT c.name,
               COUNT(m.run_id),
               COALESCE(SUM(CASE WHEN r.status = 'ok' THEN 1 ELSE 0 END), 0),
               COALESCE(SUM(CASE WHEN r.status <> 'ok' THEN 1 ELSE 0 END), 0),
               COALESCE(SUM(CASE WHEN m.origin = 'made' THEN 1 ELSE 0 END), 0),
               COALESCE(SUM(CASE WHEN m.origin = 'reused' THEN 1 ELSE 0 END), 0),
               COALESCE(MAX(r.seq), 0)
        FROM campaigns c
        LEFT OUTER JOIN campaign_runs m ON m.campaign = c.name
        LEFT OUTER JOIN runs r ON r.run_id = m.run_id
        GROUP BY c.name
        """
    )


def downgrade() -> None:
    op.drop_table("campaign_summary")
