"""The catalogue's per-campaign counts (``campaign_summary``, kept by the writer): after any
sequence of writes (new runs, statuses that change, runs reused by other campaigns, rewrites of
the same run) they equal the counts recounted from every run; a catalogue made before the
table existed (revision r0002) gets it filled by the migration."""

from __future__ import annotations

import sqlalchemy as sa
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nematic_solids.sweep.catalogue import RunRow, open_catalogue
from nematic_solids.sweep.catalogue.query import campaign_counts, recount_campaigns

CAMPAIGNS = ("a", "b", "c")

writes = st.lists(
    st.lists(
        st.tuples(
            st.integers(0, 7),  # run
            st.sampled_from(CAMPAIGNS),
            st.sampled_from(["ok", "failed"]),
            st.sampled_from(["made", "reused"]),
        ),
        min_size=1,
        max_size=6,
    ),
    min_size=1,
    max_size=6,
)


def counts(cat, stmt) -> list[dict]:
    with cat.engine.connect() as conn:
        return [dict(r._mapping) for r in conn.execute(stmt)]


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(batches=writes)
def test_the_summary_equals_a_recount_after_any_writes(tmp_path_factory, batches):
    cat = open_catalogue(tmp_path_factory.mktemp("cat"))
    try:
        for batch in batches:
            cat.record(
                RunRow(run_id=f"r{i}", campaign=c, status=s, origin=o) for i, c, s, o in batch
            )
            assert counts(cat, campaign_counts()) == counts(cat, recount_campaigns())
        cat.set_campaign("empty", "empty")
        listed = cat.campaigns().set_index("name")
        assert listed.loc["empty", "runs"] == 0
        assert int(listed["runs"].sum()) == len({(c, i) for b in batches for i, c, _, _ in b})
    finally:
        cat.close()


def test_the_migration_fills_the_summary_of_an_older_catalogue(tmp_path):
    from alembic import command
    from alembic.config import Config

    from nematic_solids.sweep.catalogue.database import MIGRATIONS, upgrade

    cat = open_catalogue(tmp_path)
    cat.record(
        [
            RunRow(run_id="x", campaign="a", status="ok"),
            RunRow(run_id="y", campaign="a", status="failed"),
            RunRow(run_id="x", campaign="b", status="ok", origin="reused"),
        ]
    )
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    with cat.engine.begin() as conn:
        config.attributes["connection"] = conn
        command.downgrade(config, "r0002")
        assert "campaign_summary" not in sa.inspect(conn).get_table_names()
    upgrade(cat.engine)
    rows = {r["name"]: r for r in counts(cat, campaign_counts())}
    assert (rows["a"]["runs"], rows["a"]["ok"], rows["a"]["failed"]) == (2, 1, 1)
    assert (rows["b"]["runs"], rows["b"]["reused"], rows["b"]["made"]) == (1, 1, 0)
    assert counts(cat, campaign_counts()) == counts(cat, recount_campaigns())
    cat.close()
