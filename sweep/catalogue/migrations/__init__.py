"""The catalogue's Alembic migrations (``versions/``), applied by
:func:`nematic_solids.sweep.catalogue.database.upgrade` on every open: ``env.py`` runs them on
the connection the catalogue hands over (no ``alembic.ini``). A new migration goes in
``versions/`` with ``down_revision`` the latest one's ``revision``."""
