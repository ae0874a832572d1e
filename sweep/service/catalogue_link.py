"""The service's database: the catalogue of its results root
(:func:`nematic_solids.sweep.catalogue.open_catalogue`: ``<root>/catalogue.sqlite``, or the URL
of ``NEMATIC_CATALOGUE``, e.g. PostgreSQL), migrated to the latest schema, which holds the
service's queue (:mod:`.queue`) beside the runs the driver records."""

from __future__ import annotations

from pathlib import Path

from ..catalogue import Catalogue, open_catalogue
from .queue import QueueStore


def open_service_database(root: Path) -> tuple[Catalogue, QueueStore]:
    """The catalogue of ``root`` and the queue in it. Raises
    :class:`~nematic_solids.sweep.errors.CatalogueError` where the catalogue cannot be opened
    (SQLite on a network filesystem, an unreachable server, the catalogue turned off)."""
    catalogue = open_catalogue(root)
    return catalogue, QueueStore(catalogue.engine)
