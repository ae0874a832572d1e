"""Alembic's environment for the catalogue: migrations run on the connection that
:func:`nematic_solids.sweep.catalogue.database.upgrade` passes in ``config.attributes``."""

from __future__ import annotations

from alembic import context

from nematic_solids.sweep.catalogue.schema import metadata

connection = context.config.attributes["connection"]
context.configure(
    connection=connection,
    target_metadata=metadata,
    render_as_batch=connection.dialect.name == "sqlite",
)
with context.begin_transaction():
    context.run_migrations()
