"""``initial:`` -> :class:`nematic_solids.sweep.campaign.InitialSpec`: the campaign whose runs this
one's begin from, checked against it here (its file, the point, the seeds, the time, the
resolution), so that a missing parent is an error of this file with its line.

The parent is a campaign file (``.yaml`` or ``.yml``) in this campaign's folder or below it;
one elsewhere (``../``, an absolute path, a link that leads out) is read only with
``outside: true``. A file that is not a campaign (not YAML, or a mapping with other keys than a
campaign's sections) is refused without showing any of its content.

```yaml
initial:
  from:
    campaign: fig2.yaml        # the parent campaign's file, relative to this one
    outside: false             # true: the file may lie outside this campaign's folder
    point: {alpha_minus_B: 1.0}  # the parent's swept values this pins (the rest: same names here)
    seed: same                 # or one seed of the parent's
    time: end                  # or one of the parent's snapshot times
```
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nematic_solids.model.parameters import Numerics
from nematic_solids.model.resolution import is_rule

from ..campaign import InitialSpec, same_value
from ..errors import CampaignError
from .checker import Checker, KeyPath, is_int, is_number, suggest
from .yaml_input import read_document, read_text

FROM_KEYS = ("campaign", "point", "seed", "time", "outside")
#: what a campaign file is named
SUFFIXES = (".yaml", ".yml")
#: the model's numerics defaults (a parent or child that leaves them out)
DEFAULTS = Numerics()
#: the parent files being read (a chain of parents that comes back to itself is an error)
READING: ContextVar[tuple[str, ...]] = ContextVar("initial_reading", default=())


@dataclass(frozen=True)
class InitialRequest:
    """``initial.from`` as read, before its parent campaign is: the parent's file and the
    raw ``point``, ``seed`` and ``time``, with where the section is."""

    file: Path
    point: Any
    seed: Any
    time: Any
    location: str


def read_initial(c: Checker, raw: Any, read: Mapping[str, Any]) -> InitialRequest | None:
    """``initial:`` (see the module docstring) as far as it can be read without the parent
    campaign; :func:`resolve_initial` checks it against the parent. None without it."""
    if raw is None:
        return None
    top = c.mapping(("initial",), raw, ("from",))
    if "from" not in top:
        if isinstance(raw, Mapping):
            c.add(("initial",), "give 'from: {campaign: FILE, point: ..., seed: ..., time: ...}'")
        return None
    path: KeyPath = ("initial", "from")
    f = c.mapping(path, top["from"], FROM_KEYS)
    if any(read.get(k) is not None for k in ("refine", "precision", "verify")):
        c.add(path, "a campaign with initial.from has no refine, precision or verify section")
    name = f.get("campaign")
    where: KeyPath = (*path, "campaign")
    if not isinstance(name, str) or not name.strip():
        c.bad(where, name, "the parent campaign's file (a path, relative to this file)")
        return None
    outside = f.get("outside", False)
    if not isinstance(outside, bool):
        c.bad(
            (*path, "outside"),
            outside,
            "true (the parent's file may lie outside this campaign's folder) or false",
        )
        return None
    here = Path(c.source).parent if c.source and not c.source.startswith("<") else Path.cwd()
    file = here / name
    named = file.with_name(file.name + ".yaml")  # ``parent`` for parent.yaml
    if not file.exists() and named.exists():
        file = named
    if file.suffix.lower() not in SUFFIXES:
        c.add(where, f"{name} is not a campaign file (a {' or '.join(SUFFIXES)} file)")
        return None
    if not outside and not file.resolve().is_relative_to(here.resolve()):
        c.add(
            where,
            f"{name} lies outside this campaign's folder ({here.resolve()}); a parent "
            "elsewhere is read only when stated: initial.from.outside: true",
        )
        return None
    if not file.is_file():
        c.add(where, f"there is no campaign file {file}")
        return None
    key = str(file.resolve())
    if key in READING.get() or (
        not c.source.startswith("<") and key == str(Path(c.source).resolve())
    ):
        c.add(where, f"{file} starts from this campaign in turn (a cycle of parents)")
        return None
    return InitialRequest(
        file, f.get("point"), f.get("seed", "same"), f.get("time", "end"), c.location(path)
    )


def resolve_initial(
    c: Checker, request: InitialRequest, parent: Any, read: Mapping[str, Any]
) -> InitialSpec:
    """The section checked against its parent campaign (already read)."""
    path: KeyPath = ("initial", "from")
    point = _point(c, parent, request.point, read.get("sweep") or (), (*path, "point"))
    seed = _seed(c, parent, request.seed, read.get("seeds") or (), (*path, "seed"))
    time = _time(c, parent, request.time, (*path, "time"))
    _resolution(c, parent, read, path)
    return InitialSpec(parent, str(request.file), point, seed, time, request.location)


def parent_error(
    c: Checker, request: InitialRequest, error: CampaignError, keys: Sequence[str]
) -> None:
    """The parent campaign could not be read: one problem of this file, at its line. Its
    first problem is shown only when the file is a campaign file (a YAML mapping whose keys
    are among ``keys``, the campaign's sections): nothing of another file is echoed."""
    where: KeyPath = ("initial", "from", "campaign")
    if not _is_campaign_file(request.file, keys):
        c.add(
            where,
            f"{request.file} is not a campaign file (a YAML mapping of a campaign's sections: "
            f"{', '.join(keys[:6])}, ...); its content is not shown",
        )
        return
    first = error.problems[0] if error.problems else error
    c.add(
        where,
        f"the parent campaign {request.file} is invalid ({len(error.problems)} problem(s)): "
        f"{first}",
    )


def _is_campaign_file(file: Path, keys: Sequence[str]) -> bool:
    try:
        _, doc, _, _ = read_document(read_text(file), str(file))
    except CampaignError:
        return False
    return isinstance(doc, Mapping) and all(isinstance(k, str) and k in keys for k in doc)


def _point(c: Checker, parent: Any, raw: Any, dims: Any, path: KeyPath) -> dict[str, Any]:
    pinned = c.mapping(path, raw, None)
    axes = {a.name: a for d in parent.dims for a in d.axes}
    here = {a.name: a for d in dims for a in d.axes}
    out: dict[str, Any] = {}
    for name, value in pinned.items():
        if name not in axes:
            hint = suggest(name, list(axes))
            c.add(
                (*path, name),
                f"campaign {parent.name} sweeps no {name!r}{hint}; it sweeps "
                + (", ".join(axes) or "nothing"),
            )
        elif not any(same_value(v, value) for v in axes[name].values):
            c.bad(
                (*path, name),
                value,
                f"one of campaign {parent.name}'s values of {name}: "
                + ", ".join(
                    f"{v:g}" if isinstance(v, float) else str(v) for v in axes[name].values
                ),
            )
        else:
            out[name] = value
    for name, axis in axes.items():
        if name in pinned:
            continue
        if name not in here:
            c.add(
                path,
                f"campaign {parent.name} sweeps {name}: pin it here ({name}: VALUE) or "
                "sweep it in this campaign",
            )
            continue
        missing = [v for v in here[name].values if not any(same_value(v, w) for w in axis.values)]
        if missing:
            c.add(
                path,
                f"campaign {parent.name} has no run at {name} = {missing[0]!r} (its "
                f"values: {', '.join(map(str, axis.values))}); pin {name} or sweep its values",
            )
    return out


def _seed(c: Checker, parent: Any, raw: Any, seeds: Any, path: KeyPath) -> int | None:
    if raw == "same":
        missing = [s for s in seeds if s not in parent.seeds]
        if missing:
            c.add(
                path,
                f"campaign {parent.name} has no seed {missing[0]} (it has "
                f"{len(parent.seeds)} seed(s) from {min(parent.seeds)}); give one of its seeds",
            )
        return None
    if not is_int(raw) or raw not in parent.seeds:
        c.bad(path, raw, f"'same' or one of campaign {parent.name}'s seeds")
        return None
    return int(raw)


def _time(c: Checker, parent: Any, raw: Any, path: KeyPath) -> float | None:
    n = parent.numerics
    t_final = float(n.get("t_final", DEFAULTS.t_final))
    snaps = n.get("snapshot_times") or ()
    snaps = [float(t) for t in (snaps if isinstance(snaps, (list, tuple)) else [snaps])]
    swept = {a.name for d in parent.dims for a in d.axes} & {"t_final", "snapshot_times"}
    if swept:
        c.add(
            path,
            f"campaign {parent.name} sweeps {', '.join(sorted(swept))}: its runs "
            "have no common time to start from",
        )
        return None
    if raw == "end":
        return None
    if not is_number(raw) or not math.isfinite(raw):
        c.bad(path, raw, "'end' or one of the parent's snapshot times")
        return None
    if math.isclose(float(raw), t_final):
        return None  # the end
    if not any(math.isclose(float(raw), t) for t in snaps):
        c.bad(
            path,
            raw,
            f"'end' (t = {t_final:g}) or one of campaign {parent.name}'s snapshot "
            f"times ({', '.join(f'{t:g}' for t in snaps) or 'none'})",
        )
        return None
    return float(raw)


def _resolution(c: Checker, parent: Any, read: Mapping[str, Any], path: KeyPath) -> None:
    """Parent and child share one grid (fields are carried over point by point)."""
    if _sweeps(parent.dims, "resolution") or _sweeps(read.get("sweep") or (), "resolution"):
        c.add(path, "with initial.from neither campaign may sweep resolution")
        return
    mine_set = (read.get("numerics") or {}).get("resolution", DEFAULTS.resolution)
    theirs_set = parent.numerics.get("resolution", DEFAULTS.resolution)
    if is_rule(mine_set) or is_rule(theirs_set):
        c.add(
            path,
            "with initial.from both campaigns set a resolution (a number, not auto): a run "
            "starts from the parent's fields on the parent's grid",
        )
        return
    if not (is_int(mine_set) and is_int(theirs_set)):
        return  # not a grid size: the model's check of the numerics reports it
    mine, theirs = int(mine_set), int(theirs_set)
    if mine != theirs:
        c.add(
            path,
            f"this campaign's resolution {mine} is not campaign {parent.name}'s "
            f"({theirs}): a run starts from the parent's fields on the parent's grid",
        )


def _sweeps(dims: Any, name: str) -> bool:
    return any(a.name == name for d in dims for a in d.axes)
