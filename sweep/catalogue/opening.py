""":func:`open_catalogue`: the catalogue of a results root (or at a URL), migrated to the latest
schema, created and indexed from the files if new, rebuilt from the files if corrupt."""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

from ..errors import CatalogueError
from .catalogue import Catalogue
from .database import CorruptCatalogue, Database
from .location import catalogue_url, is_url, redacted

log = logging.getLogger(__name__)

#: the meta key holding the results root a catalogue indexes
ROOT_KEY = "root"


def _sqlite_file(url: str) -> Path | None:
    from sqlalchemy.engine import make_url

    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite" or not parsed.database:
        return None
    return Path(parsed.database)


def _move_aside(path: Path) -> Path:
    """Move a corrupt SQLite file (and its WAL and shared-memory files) aside."""
    stamp = time.strftime("%Y%m%dT%H%M%S")
    aside = path.with_name(f"{path.name}.corrupt-{stamp}")
    for suffix in ("", "-wal", "-shm"):
        src = Path(f"{path}{suffix}")
        if src.exists():
            os.replace(src, f"{aside}{suffix}")
    return aside


def open_catalogue(
    target: str | os.PathLike[str] | None = None,
    *,
    root: str | os.PathLike[str] | None = None,
    index: bool = True,
    readonly: bool = False,
) -> Catalogue:
    """The catalogue of a results root.

    ``target``: a results root (the folder holding ``<campaign>/`` folders; its catalogue is
    the URL of :data:`~.location.ENV` if set, else ``<root>/catalogue.sqlite``) or a database
    URL (``sqlite:///path``, ``postgresql+psycopg://user@host/db``; ``root`` then names the
    results root, else the one the catalogue recorded). A new catalogue is indexed from the
    root's files (``index``); a corrupt SQLite file is moved aside
    (``catalogue.sqlite.corrupt-<time>``) and rebuilt from the files. Raises
    :class:`~nematic_solids.sweep.errors.CatalogueError` (one line) where it cannot be opened:
    SQLite on a network filesystem, an unreachable server, a catalogue of another root.

    ``readonly``: only an existing catalogue, neither migrated nor indexed nor rebuilt, and
    nothing written beside an SQLite file (``run --dry-run``); write through it and the
    database refuses."""
    if readonly:
        return _open_readonly(target, root)
    url, root_path = _url_and_root(target, root)
    state, moved = "opened", None
    sqlite = _sqlite_file(url)
    if sqlite is not None:
        if not sqlite.parent.is_dir():
            raise CatalogueError(f"cannot create the catalogue {sqlite}: no folder {sqlite.parent}")
        if not sqlite.exists():
            state = "created"
    try:
        database = Database(url)
    except CorruptCatalogue as e:
        assert sqlite is not None
        moved = _move_aside(sqlite)
        log.warning("%s; moved to %s and rebuilt from the run files", e, moved)
        database, state = Database(url), "rebuilt"
    if sqlite is None and database.get_meta(ROOT_KEY) is None:
        state = "created"
    recorded = database.get_meta(ROOT_KEY)
    if root_path is None:
        if recorded is None:
            database.close()
            raise CatalogueError(
                f"the catalogue {redacted(url)} names no results root yet: give one (--results)"
            )
        root_path = Path(recorded)
    resolved = str(root_path.resolve())
    if recorded is not None and recorded != resolved:
        if sqlite is not None and sqlite.parent.resolve() == root_path.resolve():
            log.info("catalogue: the results root moved from %s to %s", recorded, resolved)
        elif sqlite is None or state == "opened":
            database.close()
            raise CatalogueError(
                f"the catalogue {redacted(url)} indexes the results root {recorded}, not "
                f"{resolved}: one catalogue per results root (give another URL)"
            )
    if recorded != resolved:
        database.set_meta(ROOT_KEY, resolved)
    catalogue = Catalogue(database, root_path)
    catalogue.state, catalogue.moved_to = state, moved
    if index and state in ("created", "rebuilt") and root_path.is_dir():
        from .index import index_root

        index_root(catalogue, root_path)
    return catalogue


def _url_and_root(
    target: str | os.PathLike[str] | None, root: str | os.PathLike[str] | None
) -> tuple[str, Path | None]:
    """The database URL that ``target`` names (a URL, or a results root whose SQLite file it
    is; default ``results``) and the results root (None for a URL without ``root``)."""
    text = os.fspath(target) if target is not None else None
    if text is not None and is_url(text):
        return text, Path(root) if root is not None else None
    root_path = Path(text if text is not None else (root if root is not None else "results"))
    return catalogue_url(root_path), root_path


def _open_readonly(
    target: str | os.PathLike[str] | None, root: str | os.PathLike[str] | None
) -> Catalogue:
    url, root_path = _url_and_root(target, root)
    sqlite = _sqlite_file(url)
    if sqlite is not None and not sqlite.is_file():
        raise CatalogueError(f"no catalogue {sqlite}")
    try:
        database = Database(url, readonly=True)
    except CorruptCatalogue as e:
        raise CatalogueError(str(e)) from None
    if root_path is None:
        recorded = database.get_meta(ROOT_KEY)
        if recorded is None:
            database.close()
            raise CatalogueError(f"the catalogue {redacted(url)} names no results root")
        root_path = Path(recorded)
    return Catalogue(database, root_path)
