"""Where a catalogue lives: the database URL for a results root, and the refusal of SQLite on a
network filesystem.

The URL, first that applies: the one given (``--catalogue URL``, ``open_catalogue(url)``), the
environment variable :data:`ENV` (a URL, or a path of an SQLite file), else the SQLite file
``<results root>/catalogue.sqlite``. A PostgreSQL URL is ``postgresql+psycopg://user@host/db``
(psycopg 3).

SQLite's locks and its write-ahead log need a local disk: on NFS, SMB, Lustre, GPFS, sshfs and
the like two processes can both believe they hold the lock (a corrupt database), and WAL's
shared memory does not work at all. :func:`network_filesystem` reads the mount table
(:func:`mount_table`, ``/proc/self/mountinfo``) and names the filesystem type of the folder;
:func:`sqlite_url` refuses such a folder with a message that says what to do instead.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from ..errors import CatalogueError

#: the environment variable naming the catalogue (a URL, or a path of an SQLite file)
ENV = "NEMATIC_CATALOGUE"
#: the values of :data:`ENV` that turn the catalogue off (nothing recorded, no reuse)
OFF = ("off", "none", "no", "0")
#: the SQLite file's name in the results root
FILENAME = "catalogue.sqlite"
#: filesystem types (``/proc/self/mountinfo``'s fstype) on which SQLite is refused
NETWORK_FS = frozenset(
    {
        "nfs",
        "nfs4",
        "cifs",
        "smb",
        "smb3",
        "smbfs",
        "ncpfs",
        "afs",
        "lustre",
        "gpfs",
        "beegfs",
        "glusterfs",
        "ceph",
        "cephfs",
        "9p",
        "virtiofs",
        "davfs",
        "fuse.sshfs",
        "fuse.glusterfs",
        "fuse.cephfs",
        "fuse.rclone",
        "fuse.s3fs",
        "fuse.gcsfuse",
        "fuse.davfs",
        "orangefs",
        "pvfs2",
        "quobyte",
        "fuse.quobyte",
        "wekafs",
    }
)
MOUNTINFO = Path("/proc/self/mountinfo")


def _unescape(field: str) -> str:
    """A mount point as mountinfo writes it (space, tab, newline, backslash as octal)."""
    for code, char in (("\\040", " "), ("\\011", "\t"), ("\\012", "\n"), ("\\134", "\\")):
        field = field.replace(code, char)
    return field


def mount_table() -> list[tuple[str, str]]:
    """Every mount as ``(mount point, filesystem type)`` from ``/proc/self/mountinfo`` (empty
    where there is none: not Linux). The tests replace this function to fake a mount table."""
    try:
        text = MOUNTINFO.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return []
    out = []
    for line in text.splitlines():
        head, sep, tail = line.partition(" - ")
        fields = head.split()
        if not sep or len(fields) < 5 or not tail.split():
            continue
        out.append((_unescape(fields[4]), tail.split()[0]))
    return out


def filesystem_type(path: Path, mounts: Iterable[tuple[str, str]] | None = None) -> str | None:
    """The filesystem type of the mount that holds ``path`` (the longest mount point above
    it; the last mount of that point wins), or None if the table is empty."""
    target = str(path.resolve())
    best: tuple[int, str] | None = None
    for point, fstype in mount_table() if mounts is None else mounts:
        inside = target == point or target.startswith(point.rstrip("/") + "/") or point == "/"
        if inside and (best is None or len(point) >= best[0]):
            best = (len(point), fstype)
    return None if best is None else best[1]


def network_filesystem(path: Path) -> str | None:
    """The network filesystem type ``path`` is on (``nfs4``, ``lustre``, ...), or None."""
    fstype = filesystem_type(path)
    if fstype is None:
        return None
    return fstype if fstype in NETWORK_FS or fstype.split(".")[-1] in NETWORK_FS else None


def is_url(text: str) -> bool:
    return "://" in text


def sqlite_url(path: Path) -> str:
    """The URL of the SQLite file ``path``; :class:`CatalogueError` if its folder is on a
    network filesystem."""
    folder = path.parent
    fstype = network_filesystem(folder if folder.exists() else Path(os.path.dirname(folder)))
    if fstype is not None:
        raise CatalogueError(
            f"the catalogue {path} would be on a network filesystem ({fstype}), where SQLite's "
            "locking is unsafe: give a PostgreSQL URL (--catalogue postgresql+psycopg://"
            f"USER@HOST/DB, or {ENV}=that URL) or an SQLite file on a local disk "
            f"({ENV}=/local/disk/catalogue.sqlite)"
        )
    return f"sqlite:///{path.resolve()}"


def catalogue_url(root: Path | None, given: str | None = None) -> str:
    """The catalogue's URL for the results root ``root`` (see the module docstring)."""
    chosen = given or os.environ.get(ENV, "").strip() or None
    if chosen is not None and chosen.lower() in OFF:
        raise CatalogueError(f"the catalogue is off ({ENV}={chosen})")
    if chosen is not None:
        return chosen if is_url(chosen) else sqlite_url(Path(chosen).expanduser())
    if root is None:
        raise CatalogueError(f"no catalogue named: give a results root, a URL or set {ENV}")
    return sqlite_url(Path(root) / FILENAME)


def redacted(url: str) -> str:
    """``url`` without its password (for messages)."""
    from sqlalchemy.engine import make_url

    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001 - not a URL SQLAlchemy reads: shown as given
        return url
