"""A campaign file that changed since its results were made: what changed, compared with the
copy the last ``nematic run`` left in the results folder
(:mod:`nematic_solids.sweep.outputs.stored`), and what it means for the runs: how many of the
current plan are new (no record yet) or kept (a record from before), and which runs in the folder
are *orphaned* (the current campaign does not plan them). ``nematic run --prune`` removes the
orphaned runs (:func:`prune`).

An adaptive campaign (``refine:``) plans its runs round by round: a run in the folder is not
orphaned when the current campaign could plan it in some round, that is when it is a run of
the campaign's grid with each refined axis at any value between the axis's first and last
grid values (same run id: the other swept values on the grid, the base parameters and
numerics, one of the seeds), whether the replayed rounds have planned it yet or not.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..campaign import Campaign
from ..campaign_copy import OVERRIDE_PREFIX, SOURCE_PREFIX, campaign_copy_text
from ..errors import CampaignError
from ..store import CampaignStore, Record
from .stored import stored_campaign, stored_text

if TYPE_CHECKING:
    from ..expand import Expansion

#: At most this many values of an axis are named in a change line.
MAX_VALUES = 6
#: Command-line overrides that choose where runs go, not what they are: a copy that differs
#: only in these is the same campaign.
WHERE_OVERRIDES = ("--workers ", "--scheduler ")


@dataclass
class RunCounts:
    """The current plan against the folder."""

    new: int
    kept: int
    orphaned: list[str] = field(default_factory=list)
    #: new runs that continue a finished shorter run of their trajectory (t_final grew)
    continuing: int = 0

    def line(self) -> str:
        more = (
            f" ({self.continuing} continue a finished shorter run from its end state)"
            if self.continuing
            else ""
        )
        return (
            f"runs: {self.new} new{more}, {self.kept} kept, {len(self.orphaned)} orphaned "
            "(in the folder, not planned by this campaign)"
        )


@dataclass
class CampaignChanges:
    """What differs between the campaign and the copy its results were made with."""

    copy: str
    changes: list[str]
    counts: RunCounts

    def lines(self) -> list[str]:
        return [
            f"the campaign differs from the one its results were made with ({self.copy}):",
            *(f"  {c}" for c in self.changes),
            f"  {self.counts.line()}",
        ]

    def to_dict(self) -> dict[str, Any]:
        return {
            "copy": self.copy,
            "changes": self.changes,
            "new": self.counts.new,
            "kept": self.counts.kept,
            "orphaned": len(self.counts.orphaned),
            "continuing": self.counts.continuing,
        }


def _fmt(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _values(values: Sequence[Any]) -> str:
    shown = ", ".join(_fmt(v) for v in values[:MAX_VALUES])
    return shown + (f", ... ({len(values)} values)" if len(values) > MAX_VALUES else "")


def _mapping_changes(section: str, old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    parts = []
    for key in sorted(set(old) | set(new)):
        if key not in new:
            parts.append(f"{key} {_fmt(old[key])} removed")
        elif key not in old:
            parts.append(f"{key} = {_fmt(new[key])} added")
        elif old[key] != new[key]:
            parts.append(f"{key} {_fmt(old[key])} -> {_fmt(new[key])}")
    return [f"{section}: " + "; ".join(parts)] if parts else []


def describe_changes(old: Campaign, new: Campaign) -> list[str]:
    """One line per change: axes added, removed or with other values, zip groups, base
    parameters and numerics, seeds, the refine section, and the other sections by name."""
    out = _axis_changes(old, new)
    out += _zip_changes(old, new)
    out += _mapping_changes("parameters", old.parameters, new.parameters)
    out += _mapping_changes("numerics", old.numerics, new.numerics)
    out += _seed_changes(old, new)
    out += _section_change("refine", old.refine, new.refine)
    out += _section_change("precision", old.precision, new.precision)
    others = [
        name
        for name in ("store", "fits", "figures", "execution", "limits", "description")
        if getattr(old, name) != getattr(new, name)
    ]
    if others:
        out.append("also changed (no effect on the run ids): " + ", ".join(others))
    return out or ["nothing that changes the runs (comments or layout)"]


def _axis_changes(old: Campaign, new: Campaign) -> list[str]:
    """One line per axis added, removed, with values added or removed, or reordered."""
    out = []
    old_axes = {a.name: a.values for a in old.axes}
    new_axes = {a.name: a.values for a in new.axes}
    for name, values in new_axes.items():
        if name not in old_axes:
            out.append(f"axis {name} added: {_values(values)}")
            continue
        added = [v for v in values if v not in set(old_axes[name])]
        removed = [v for v in old_axes[name] if v not in set(values)]
        what = ([f"values added {_values(added)}"] if added else []) + (
            [f"values removed {_values(removed)}"] if removed else []
        )
        if what:
            out.append(f"axis {name}: " + "; ".join(what))
        elif tuple(values) != tuple(old_axes[name]):
            out.append(f"axis {name}: values reordered")
    out.extend(
        f"axis {name} removed (was {_values(values)})"
        for name, values in old_axes.items()
        if name not in new_axes
    )
    return out


def _zip_changes(old: Campaign, new: Campaign) -> list[str]:
    """The zip groups before and after, when they differ."""
    groups_old = {tuple(a.name for a in d.axes) for d in old.dims if len(d.axes) > 1}
    groups_new = {tuple(a.name for a in d.axes) for d in new.dims if len(d.axes) > 1}
    if groups_old == groups_new:
        return []
    return [
        "zip groups: "
        + (", ".join(f"[{', '.join(g)}]" for g in sorted(groups_old)) or "none")
        + " -> "
        + (", ".join(f"[{', '.join(g)}]" for g in sorted(groups_new)) or "none")
    ]


def _seed_changes(old: Campaign, new: Campaign) -> list[str]:
    """The number of seeds before and after, and those added and removed, when they differ."""
    if old.seeds == new.seeds:
        return []
    added = [s for s in new.seeds if s not in set(old.seeds)]
    removed = [s for s in old.seeds if s not in set(new.seeds)]
    return [
        f"seeds: {len(old.seeds)} -> {len(new.seeds)}"
        + (f"; added {_values(added)}" if added else "")
        + (f"; removed {_values(removed)}" if removed else "")
    ]


def _section_change(name: str, old: Any, new: Any) -> list[str]:
    """``name: added``, ``removed`` or ``changed`` for a section that differs, else none."""
    if old == new:
        return []
    return [f"{name}: " + ("added" if old is None else "removed" if new is None else "changed")]


def _reachable(campaign: Campaign, run_id: str, record: Mapping[str, Any] | None) -> bool:
    """Whether an adaptive campaign could plan ``run_id`` (module doc) from its record."""
    from ..refine.plan import point_at, refined_dims
    from ..refine.rounds import RunNamer

    coords = (record or {}).get("coords")
    seed = (record or {}).get("seed")
    if not isinstance(coords, Mapping) or seed not in campaign.seeds:
        return False
    ks = refined_dims(campaign)
    refined: list[float] = []
    line = []
    for i, d in enumerate(campaign.dims):
        if i in ks:
            grid = d.axes[0].values
            x = coords.get(d.name)
            if not isinstance(x, (int, float)) or not min(grid) <= x <= max(grid):
                return False
            refined.append(float(x))
            continue
        matches = [
            j for j in range(len(d)) if all(coords.get(a.name) == a.values[j] for a in d.axes)
        ]
        if not matches:
            return False
        line.append(matches[0])
    try:
        return RunNamer(campaign).run_id(tuple(line), point_at(refined), int(seed)) == run_id
    except (ValueError, TypeError, ArithmeticError):
        return False


def run_counts(
    campaign: Campaign, expansion: Expansion, store: CampaignStore, records: Mapping[str, Record]
) -> RunCounts:
    """New and kept runs of the plan, and the orphaned ones of the folder (``records`` is
    :meth:`CampaignStore.scan`, which also lists the run files without a record)."""
    planned = getattr(expansion, "planned", None)
    ids = (
        expansion.run_ids
        if planned is None
        else [rid for rid, keep in zip(expansion.run_ids, planned, strict=True) if keep]
    )
    kept = sum(1 for rid in ids if rid in records)
    orphaned = sorted((set(records) | store.nc_present) - set(expansion.position))
    if campaign.refine is not None:
        orphaned = [
            rid for rid in orphaned if not _reachable(campaign, rid, store.read_record(rid))
        ]
    from ..expand import continued_runs

    todo = [i for i, rid in enumerate(expansion.run_ids) if rid not in records]
    if planned is not None:
        todo = [i for i in todo if planned[i]]
    continuing = len(continued_runs(expansion, todo, records))
    return RunCounts(new=len(ids) - kept, kept=kept, orphaned=orphaned, continuing=continuing)


def _significant(copy_text: str) -> str:
    """A campaign copy without the overrides of :data:`WHERE_OVERRIDES` and without the
    line naming the file it was read from."""
    where = (*(OVERRIDE_PREFIX + o for o in WHERE_OVERRIDES), SOURCE_PREFIX)
    return "".join(
        line for line in copy_text.splitlines(keepends=True) if not line.startswith(where)
    )


def campaign_changes(
    campaign: Campaign,
    store: CampaignStore,
    expansion: Expansion | None = None,
    records: Mapping[str, Record] | None = None,
) -> CampaignChanges | None:
    """What changed since the last run, or ``None`` when the folder has no copy or the same
    campaign (the same text and command-line overrides, but ``--workers`` and
    ``--scheduler``)."""
    text = stored_text(store)
    if text is None or _significant(text) == _significant(
        campaign_copy_text(campaign.text, campaign.overrides)
    ):
        return None
    try:
        old = stored_campaign(store, text)
        assert old is not None
        changes = describe_changes(old, campaign)
    except CampaignError as e:
        first = e.problems[0] if e.problems else e
        changes = [
            f"(the copy is not a valid campaign for this code, so what changed is not "
            f"listed: {first})"
        ]
    if expansion is None:
        from ..refine.rounds import expansion_for

        expansion = expansion_for(campaign, store)
    if records is None:
        records = store.scan(save=False)
    return CampaignChanges(
        str(store.campaign_copy), changes, run_counts(campaign, expansion, store, records)
    )


def prune(store: CampaignStore, run_ids: Sequence[str]) -> int:
    """Remove the records and files of ``run_ids`` (the orphaned runs; the caller holds the
    campaign's lock); return how many runs were removed."""
    for rid in run_ids:
        store.discard(rid)
    store.scan()
    return len(run_ids)
