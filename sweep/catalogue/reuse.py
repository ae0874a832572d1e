"""Reuse across campaigns: a planned run that another campaign of the same results root has
already finished is not run again, and a longer run continues the longest finished run of its
trajectory, whichever campaign made it.

- **The same run** (same run_id: same parameters, numerics, seed and start): the catalogue
  names a finished run (status ok) with a file; that file is checked where it lies (its size,
  and its checksum when its mtime is not the recorded one:
  :meth:`~nematic_solids.sweep.store.CampaignStore.check_run_file`), and the campaign takes it
  in place: ``runs/<run_id>.nc`` becomes a symbolic link to it (relative, so the root can move)
  and ``runs/<run_id>.json`` a copy of its record with ``reused_from`` naming the campaign that
  made it. No run file is copied; every reader of the folder (phase.nc, reports, tables) reads
  the link as the file. If the file goes away or changes later, the link's check fails and the
  run is done again, as any run whose file is missing.
- **A longer run of a trajectory** (same trajectory_id, a later ``t_final``): the finished run
  that kept its end state and went furthest below the new ``t_final``, in any campaign, is
  its parent (:mod:`nematic_solids.sweep.run.continuation` reads its end state from its path).

Nothing here fails a campaign: without a catalogue (turned off, unreachable) the runs are
simply run.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..files import temporary_path
from ..identity import identity_start, trajectory_id
from ..store import CampaignStore, Record
from .catalogue import Catalogue
from .location import ENV, FILENAME
from .rows import RunRow, row_from_record

if TYPE_CHECKING:
    from ..expand import Expansion

log = logging.getLogger(__name__)

#: the record key that names the campaign whose file a reused run is
REUSED_FROM = "reused_from"


@dataclass(frozen=True)
class Source:
    """A finished run of another campaign: its id, that campaign, its file and record."""

    run_id: str
    campaign: str
    path: Path
    record: Record


def open_for_reuse(results_root: Path, *, create: bool = True) -> Catalogue | None:
    """The root's catalogue, or None (turned off, cannot be opened: logged). ``create``:
    make (and index) it if there is none; else only an existing one, read only (for readers
    that write nothing, e.g. ``run --dry-run``)."""
    from .opening import open_catalogue
    from .recorder import catalogue_off

    if catalogue_off():
        return None
    if not create and not os.environ.get(ENV) and not (results_root / FILENAME).exists():
        return None
    try:
        if not create:
            return open_catalogue(results_root, readonly=True)
        return open_catalogue(results_root)
    except Exception as e:  # noqa: BLE001 - no catalogue: the runs are run
        log.warning("catalogue: not used to reuse runs (%s)", str(e).splitlines()[0])
        return None


def _campaign_store(root: Path, relative: str) -> CampaignStore | None:
    """The store of the run file at ``root/relative`` (``NAME/runs/<id>.nc``)."""
    parts = Path(relative).parts
    if len(parts) < 3 or parts[-2] != "runs" or ".." in parts:
        return None
    return CampaignStore(root.joinpath(*parts[:-3]) if len(parts) > 3 else root, parts[-3])


def reusable(
    catalogue: Catalogue, store: CampaignStore, run_ids: Iterable[str]
) -> dict[str, Source]:
    """Of ``run_ids``, the runs another campaign of the root finished whose file checks out
    where it lies (read only)."""
    out: dict[str, Source] = {}
    root = store.results_root
    try:
        found = catalogue.finished(run_ids)
    except Exception as e:  # noqa: BLE001 - no reuse, the runs are run
        log.warning("catalogue: not read (%s); no run reused", str(e).splitlines()[0])
        return out
    for rid, info in found.items():
        source = _campaign_store(root, str(info["path"]))
        if source is None or source.root.resolve() == store.root.resolve():
            continue
        record = source.read_record(rid)
        if record is None or record.get("status") != "ok" or record.get(REUSED_FROM):
            continue
        if source.nc_path(rid).is_symlink():
            continue
        problem = source.check_run_file(rid, record)
        if problem is not None:
            log.info("run %s of %s not reused: %s", rid, source.root.name, problem)
            continue
        out[rid] = Source(rid, source.root.name, source.nc_path(rid), record)
    return out


def _link(path: Path, target: Path) -> None:
    """``path`` made a relative symbolic link to ``target``, atomically."""
    tmp = temporary_path(path)
    os.symlink(os.path.relpath(target, path.parent), tmp)
    try:
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def adopt(
    store: CampaignStore, sources: Mapping[str, Source], catalogue: Catalogue | None = None
) -> dict[str, Record]:
    """Take ``sources`` into the campaign ``store`` in place (links and record copies; see the
    module docstring) and record them in the catalogue as reused; returns the records
    written. A run that cannot be taken (the folder refuses the link) is left to run."""
    taken: dict[str, Record] = {}
    for rid, src in sources.items():
        record: dict[str, Any] = {k: v for k, v in src.record.items() if k != "stamp"}
        record[REUSED_FROM] = src.campaign
        try:
            _link(store.nc_path(rid), src.path)
            store.write_record(record)
        except OSError as e:
            log.warning("run %s of %s not reused: %s", rid, src.campaign, e)
            store.discard(rid)
            continue
        taken[rid] = record  # type: ignore[assignment]
    if catalogue is not None and taken:
        root = store.results_root.resolve()
        rows: list[RunRow] = []
        for rid, rec in taken.items():
            rel = os.path.relpath(sources[rid].path.resolve(), root)
            rows.append(row_from_record(rec, store.root.name, rel, origin="reused"))
        folder = os.path.relpath(store.root, store.results_root)
        try:
            catalogue.record(rows, {store.root.name: folder})
        except Exception as e:  # noqa: BLE001 - the files have it; index records it
            log.warning("catalogue: reused runs not recorded (%s)", str(e).splitlines()[0])
    return taken


def reuse_counts(records: Mapping[str, Mapping[str, Any]]) -> Counter[str]:
    """How many of ``records`` came from which campaign (``reused_from``)."""
    return Counter(str(r[REUSED_FROM]) for r in records.values() if r.get(REUSED_FROM))


def reuse_line(counts: Mapping[str, int]) -> str:
    """``reused 4 finished run(s): 4 from fig2`` (the dry-run, ``nematic run``, the report)."""
    total = sum(counts.values())
    parts = ", ".join(f"{n} from {name}" for name, n in sorted(counts.items()))
    return f"reused {total} finished run(s): {parts} (taken in place, not run again)"


def trajectories(expansion: Expansion, positions: Iterable[int]) -> dict[int, str]:
    """The trajectory id of each run at ``positions``."""
    out = {}
    for i in positions:
        run = expansion.run(i)
        start = identity_start(run.start)  # as the run task records it (the state too)
        out[i] = trajectory_id(
            run.point.parameters.to_dict(),
            run.point.numerics.to_dict(),
            run.seed,
            start,
            expansion.campaign.model,
        )
    return out


def continued_elsewhere(
    catalogue: Catalogue,
    expansion: Expansion,
    todo: Iterable[int],
    here: Mapping[int, tuple[str, float]],
    results_root: Path,
) -> dict[int, tuple[str, float, Path]]:
    """For each run to do, the finished run of its trajectory in any campaign of the root that
    kept its end state and went furthest below its ``t_final``, when it goes further than
    ``here`` (the campaign's own, :func:`nematic_solids.sweep.expand.continued_runs`):
    position -> (run id, its end, its file)."""
    wanted = trajectories(expansion, todo)
    try:
        found = catalogue.longest_finished(set(wanted.values()))
    except Exception as e:  # noqa: BLE001 - no continuation across campaigns
        log.warning("catalogue: not read (%s)", str(e).splitlines()[0])
        return {}
    out: dict[int, tuple[str, float, Path]] = {}
    for i, traj in wanted.items():
        run = expansion.run(i)
        t_final = run.point.numerics.t_final
        own = here.get(i, ("", -1.0))[1]
        for end, rid, path, _campaign in found.get(traj, ()):
            if end < t_final and rid != run.run_id and end > own:
                file = results_root / path
                if file.exists():
                    out[i] = (rid, end, file)
                    break
    return out
