"""What remains to do: every run of a campaign classified from what is on disk (done,
failed, to do), with unusable files discarded, unindexed ones adopted and spooled results
moved in."""

from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..catalogue import reuse as across
from ..errors import CampaignError, Problem
from ..expand import Expansion, continued_runs
from ..files import atomic_path
from ..store import RETRYABLE_REASONS, CampaignStore, Record
from . import continuation
from .failures import previous_failures
from .task import spool_dir

log = logging.getLogger(__name__)


@dataclass
class Plan:
    """What is on disk for a campaign's runs, and what remains to do (run positions)."""

    todo: list[int]
    done: list[int]
    failed: list[int]
    records: dict[str, Record]
    adopted: int = 0
    #: results moved in from the spool (written elsewhere when the folder could not be)
    unspooled: int = 0
    #: runs whose record or file was unusable (missing, truncated, corrupt): (run_id, why)
    redone: list[tuple[str, str]] = field(default_factory=list)
    #: failed runs redone (``--retry-failed``): position -> the failures their new record
    #: keeps as ``previous_failures`` (:func:`nematic_solids.sweep.run.failures.previous_failures`)
    history: dict[int, list[dict[str, Any]]] = field(default_factory=dict)
    #: runs to do that continue the end state of a shorter finished run of their
    #: trajectory (a campaign whose t_final grew): position -> that run's id
    parents: dict[int, str] = field(default_factory=dict)
    #: positions whose run id an earlier position has (a chain's ``up: fresh`` top run is the
    #: down branch's first run too): the run is done once, at that earlier position
    twins: list[int] = field(default_factory=list)

    @property
    def skipped(self) -> int:
        """Positions not to run this time: done, failed (kept) or another position's twin."""
        return len(self.done) + len(self.failed) + len(self.twins)

    #: the file of such a parent when another campaign made it: position -> its path
    parent_paths: dict[int, str] = field(default_factory=dict)
    #: runs another campaign of the root had finished, taken in place: campaign -> how many
    #: (this plan's); they count as done
    reused: dict[str, int] = field(default_factory=dict)

    @property
    def discarded(self) -> int:
        return len(self.redone)


def plan_runs(
    expansion: Expansion,
    store: CampaignStore,
    *,
    retry_failed: bool = False,
    check_files: bool = False,
    reuse: bool = True,
) -> Plan:
    """Classify every run: done (skipped), failed (skipped unless ``retry_failed``: then
    its failure goes into :attr:`Plan.history`, kept by its next record), to do.

    A record whose file is missing, truncated or corrupt (:meth:`CampaignStore.check_run_file`;
    ``check_files`` checksums every file) is discarded and its run redone; a ``.nc`` without a
    record is adopted if it opens, else deleted; a record of a result that could not be
    written (reason ``write_error``) is redone. With ``reuse``, runs another campaign of the
    results root finished are taken in place, and longer runs continue the longest finished
    run of their trajectory in any campaign (:func:`reuse_across`).
    """
    unspooled = import_spool(store)
    records = store.scan()
    plan = Plan(todo=[], done=[], failed=[], records=records, unspooled=unspooled)
    first: dict[str, int] = {}
    for i, rid in enumerate(expansion.run_ids):
        if first.setdefault(rid, i) != i:
            plan.twins.append(i)
            continue
        rec = records.get(rid)
        if rec is None and rid in store.nc_present:
            rec = store.adopt(rid)
            if rec is not None:
                plan.adopted += 1
        problem = None if rec is None else store.check_run_file(rid, rec, check_files=check_files)
        if rec is not None and problem is not None:
            log.warning("run %s: %s; it will be redone", rid, problem)
            store.discard(rid)
            records.pop(rid, None)
            plan.redone.append((rid, problem))
            rec = None
        elif (
            rec is not None
            and rec.get("nc_bytes") is not None
            and (not rec.get("nc_sha256") or rec.get("nc_mtime_ns") != _mtime(store, rid))
        ):
            store.refresh_stamp(rid)  # intact, but copied or checksum-less: stat next time
        if rec is None:
            plan.todo.append(i)
        elif rec.get("status") == "ok":
            plan.done.append(i)
        elif retry_failed or rec.get("reason") in RETRYABLE_REASONS:
            plan.todo.append(i)
            full = store.read_record(rid)  # the manifest's copy has no traceback
            plan.history[i] = previous_failures(full if full is not None else rec)
        else:
            plan.failed.append(i)
    for i in (*plan.done, *plan.failed):  # killed between its record and the cleanup
        continuation.remove_checkpoint(store, expansion.run_ids[i])
    here = continued_runs(expansion, plan.todo, records)
    plan.parents = {i: rid for i, (rid, _) in here.items()}
    if reuse and plan.todo:
        reuse_across(expansion, store, plan, here)
    return plan


def reuse_across(
    expansion: Expansion, store: CampaignStore, plan: Plan, here: dict[int, tuple[str, float]]
) -> None:
    """Take the runs to do that another campaign of the root finished, in place (they move
    to ``done``), and continue the others from the longest finished run of their trajectory
    in any campaign (:mod:`nematic_solids.sweep.catalogue.reuse`); nothing without a
    catalogue."""
    catalogue = across.open_for_reuse(store.results_root)
    if catalogue is None:
        return
    with catalogue:
        ids = {expansion.run_ids[i]: i for i in plan.todo}
        taken = across.adopt(store, across.reusable(catalogue, store, ids), catalogue)
        if taken:
            plan.records.update(taken)
            plan.done.extend(ids[rid] for rid in taken)
            plan.todo = [i for i in plan.todo if expansion.run_ids[i] not in taken]
            plan.reused = dict(across.reuse_counts(taken))
            for i in (ids[rid] for rid in taken):
                plan.history.pop(i, None)
        far = across.continued_elsewhere(catalogue, expansion, plan.todo, here, store.results_root)
        for i, (rid, _, path) in far.items():
            plan.parents[i], plan.parent_paths[i] = rid, str(path)


def import_spool(store: CampaignStore) -> int:
    """Move the results the workers kept in :func:`spool_dir` (the folder could not be
    written) into the results folder, where the plan adopts them; return how many. Raises
    :class:`StorageError` if the folder still cannot be written."""
    import shutil

    spool = spool_dir(store.runs_dir)
    try:
        files = sorted(spool.glob("*.nc"))
    except OSError:
        return 0
    n = 0
    for src in files:
        target = store.nc_path(src.stem)
        if not target.exists() and store.read_record(src.stem) is None:
            with atomic_path(target) as tmp:
                shutil.copyfile(src, tmp)
            n += 1
        with contextlib.suppress(OSError):
            src.unlink()
    with contextlib.suppress(OSError):
        spool.rmdir()
    if n:
        log.info("moved %d result(s) kept in %s into %s", n, spool, store.runs_dir)
    return n


def _mtime(store: CampaignStore, run_id: str) -> int | None:
    try:
        return store.nc_path(run_id).stat().st_mtime_ns
    except OSError:
        return None


# ----------------------------------------------- the parent runs a campaign waits for
def unfinished(expansion: Expansion, results_root: Path, todo: list[int]) -> list[str]:
    """The parent runs of the runs to do (positions ``todo``) that are not done in the
    parent campaign's results folder under ``results_root``: no ok record, or a file that
    is missing, truncated or corrupt."""
    spec = expansion.campaign.initial
    starts = getattr(expansion, "starts", None)  # an adaptive campaign's expansion has none
    if spec is None or starts is None or not todo:
        return []
    store = CampaignStore(results_root, spec.parent.name)
    records = store.scan(save=False)
    need = {starts[i]["run"] for i in todo}
    return sorted(
        rid
        for rid in need
        if (rec := records.get(rid)) is None
        or rec.get("status") != "ok"
        or store.check_run_file(rid, rec) is not None
    )


def parents_not_done(
    expansion: Expansion, results_root: Path, todo: list[int]
) -> CampaignError | None:
    """The error that says which parent runs a campaign waits for, or None."""
    missing = unfinished(expansion, results_root, todo)
    spec = expansion.campaign.initial
    if not missing or spec is None:
        return None
    folder = Path(results_root) / spec.parent.name
    message = (
        f"{len(missing)} run(s) of campaign {spec.parent.name} that this campaign's runs begin "
        f"from are not done (in {folder}; e.g. {missing[0]}): run 'nematic run {spec.path} "
        f"--results {results_root}' first; nothing is run until they are"
    )
    return CampaignError(
        expansion.campaign.source, [Problem("initial.from", message, spec.location)]
    )
