"""One module per migration of the catalogue's schema, chained by ``down_revision``."""
