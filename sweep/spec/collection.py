"""A collection of campaigns run as one: a YAML file whose ``campaigns:`` lists campaign files
(``campaigns/paper.yaml``: the whole paper).

::

    name: paper                 # default: the file's stem; results/NAME/ holds its index page
    description: ...
    campaigns:                  # campaign files, relative to this file, run in this order
      - fig2_precision.yaml
      - fig3_precision.yaml

``nematic validate``, ``run`` (with ``--dry-run`` and ``--detach``), ``status`` and ``stop``
take a collection where they take a campaign file (:mod:`nematic_solids.sweep.cli.collection`);
every campaign keeps its own results folder, lock, runs and products, so a member can also be run,
inspected or resumed on its own. A collection is not a campaign: it has no other keys, and its
members are campaign files (a collection does not include collections), at most
:data:`~nematic_solids.sweep.limits.MAX_COLLECTION_MEMBERS` of them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from ..errors import CampaignError, Problem
from ..limits import MAX_COLLECTION_MEMBERS
from .checker import Checker
from .yaml_input import read_document, read_text

KEYS = ("name", "description", "campaigns")
#: The key that makes a YAML file a collection.
MARK = "campaigns"


@dataclass(frozen=True)
class Collection:
    """A collection file read and checked: its name, description, source and member files
    (absolute or relative to the working directory, as the source was given)."""

    name: str
    description: str
    source: str
    members: tuple[Path, ...]


def read_collection(path: str | Path) -> Collection | None:
    """The collection at ``path``, or ``None`` if the file is not one (no ``campaigns:`` key
    at the top, or not readable: the campaign reader reports that). Raises
    :class:`CampaignError` listing every problem of a collection file."""
    p = Path(path)
    try:
        text = read_text(p)
    except CampaignError:
        return None
    try:
        _, doc, lines, dups = read_document(text, str(p))
    except CampaignError:
        return None  # not YAML: the campaign reader says so
    if not isinstance(doc, Mapping) or MARK not in doc:
        return None
    c = Checker(str(p), lines, {})
    for d in dups:
        c.add(d, "duplicate key (YAML keeps only the last one)")
    sec = c.mapping((), doc, KEYS)
    name = sec.get("name", p.stem)
    if not isinstance(name, str) or not name or "/" in name or name.startswith("."):
        c.bad(("name",), name, "a folder name for results/NAME/ (no '/', not starting with '.')")
    description = sec.get("description", "")
    if not isinstance(description, str):
        c.bad(("description",), description, "a string")
    raw = sec.get(MARK)
    members: list[Path] = []
    if not isinstance(raw, list) or not raw:
        c.bad((MARK,), raw, "a non-empty list of campaign files (relative to this file)")
        raw = []
    elif len(raw) > MAX_COLLECTION_MEMBERS:  # refused by its count, before any member is read
        c.add(
            (MARK,),
            f"{len(raw)} campaign files; allowed: at most {MAX_COLLECTION_MEMBERS} (more "
            "campaigns are several collections)",
        )
        raw = []
    seen: dict[Path, int] = {}
    for i, item in enumerate(raw):
        where: tuple[str | int, ...] = (MARK, i)
        if not isinstance(item, str) or not item.strip():
            c.bad(where, item, "a campaign file name, e.g. fig2.yaml")
            continue
        member = p.parent / item
        if member.suffix not in (".yaml", ".yml"):
            c.bad(where, item, "a campaign file ending in .yaml or .yml")
        elif not member.is_file():
            c.add(where, f"no campaign file {member}")
        elif member.resolve() == p.resolve() or read_collection(member) is not None:
            c.bad(where, item, "a campaign file (a collection does not include collections)")
        elif member.resolve() in seen:
            c.add(where, f"{item} is listed twice (also as item {seen[member.resolve()]})")
        else:
            seen[member.resolve()] = i
            members.append(member)
    if c.problems:
        raise CampaignError(str(p), c.problems)
    return Collection(
        name=name, description=" ".join(description.split()), source=str(p), members=tuple(members)
    )


def duplicate_names(names: list[str], sources: list[str]) -> list[Problem]:
    """A problem for every campaign name that two members share (their results folders
    would be one)."""
    first: dict[str, str] = {}
    out = []
    for name, source in zip(names, sources, strict=True):
        if name in first:
            out.append(
                Problem(
                    "name",
                    f"campaign name {name!r} is also the name of "
                    f"{first[name]}: two members would share results/{name}/",
                    source,
                )
            )
        first.setdefault(name, source)
    return out
