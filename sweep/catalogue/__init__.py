"""The catalogue of runs: one database of every run of every campaign under a results root
(issue 59, item 1), and the reuse of finished runs across campaigns (item 2).

Public API (stable: names are added, never renamed)::

    from nematic_solids.sweep.catalogue import open_catalogue

    cat = open_catalogue("results")            # <root>/catalogue.sqlite (or $NEMATIC_CATALOGUE)
    cat = open_catalogue("postgresql+psycopg://me@db/nematic", root="results")
    cat.runs(campaign=None, where={"K": 1e-5, "alpha_minus_B": (0.5, 0.7)}, status="ok")
                                                # -> pandas.DataFrame, one row per run
    cat.dataset(...)                            # the same as an xarray.Dataset (dim "run")
    cat.campaigns()                             # -> DataFrame: name, folder, counts
    cat.changes(since_seq)                      # -> DataFrame of runs with seq > since_seq
    cat.last_seq()                              # the latest seq (0: nothing yet)
    cat.run(run_id) / cat.lineage(run_id)       # one run's row, its parents
    cat.finished(run_ids)                       # run_id -> {path, campaign} of finished runs
    cat.longest_finished(trajectory_ids)        # trajectory -> [(end, run_id, path, campaign)]
    cat.record([RunRow(...)])                   # write runs (one transaction)
    cat.engine                                  # the SQLAlchemy engine
    index_root(cat, root)                       # index every results folder (from the files)

- Storage: SQLAlchemy Core; SQLite (WAL, busy timeout) on a local disk by default, refused on
  a network filesystem (:mod:`.location`); PostgreSQL by URL (psycopg 3). The schema
  (:mod:`.schema`) is versioned by Alembic migrations shipped in ``migrations/versions/`` and
  applied on every open; a later migration adds its tables with ``down_revision`` the latest.
- Writers: the driver alone, through :class:`.recorder.Recorder` (a background thread that
  writes the runs as they finish, in batches, one transaction each); workers never write. A
  catalogue problem never fails or loses a run: the run files stay the source of truth, and
  :func:`.index.index_root` rebuilds the catalogue from them.
- Reuse across campaigns: :mod:`.reuse`.
"""

from __future__ import annotations

from ..errors import CatalogueError
from .catalogue import Catalogue
from .index import Indexed, index_root
from .location import ENV
from .opening import open_catalogue
from .query import Condition, parse_condition
from .rows import RunRow, row_from_record

__all__ = [
    "ENV",
    "Catalogue",
    "CatalogueError",
    "Condition",
    "Indexed",
    "RunRow",
    "index_root",
    "open_catalogue",
    "parse_condition",
    "row_from_record",
]
