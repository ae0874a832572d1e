"""The service: one long-lived process per results root (``nematic serve``) that owns the dask
cluster, holds a persistent queue of campaigns (a table of the catalogue's database), runs them
one after the other through the driver on its warm workers, and serves a JSON API and a live
dashboard on 127.0.0.1 behind a token (docs/guide/service.md)."""

from nematic_solids.model.errors import NematicError


class ServiceError(NematicError, RuntimeError):
    """The service cannot start or be reached: another service holds the root, an address it
    must not listen on, a port in use, no service running, a refused request."""
