"""Running a verification: the sample's base runs (into the campaign's folder) and the
variants' runs (into ``results/NAME/verify/``) on one dask cluster, then ``verify.nc``.

Both are ordinary runs (:func:`nematic_solids.sweep.run.todo.plan_runs`,
:func:`nematic_solids.sweep.run.driver.run_campaign`): resumable, checked, recorded; the caller
holds the campaign's lock.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..campaign import Campaign
from ..refine.rounds import RunList
from ..run.clusters import open_cluster
from ..run.driver import REMOTE_TMP_AGE, RunEvents, RunSummary, run_campaign
from ..run.todo import plan_runs
from ..run.workers import ClusterLink
from ..store import CampaignStore
from .measure import verify_dataset, write_verify
from .sample import Sample, plan_sample
from .summary import summary_line

log = logging.getLogger(__name__)

#: The variants' runs: ``results/NAME/verify/`` (a results folder of its own).
VERIFY_DIR = "verify"


def verify_store(store: CampaignStore) -> CampaignStore:
    return CampaignStore(store.root, VERIFY_DIR)


@dataclass
class VerifyOutcome:
    """What a verification did: its sample, the runs' summaries (``None``: nothing to run),
    the file written and its Dataset (``None`` when interrupted) and its one-line summary."""

    sample: Sample
    base: RunSummary | None = None
    variants: RunSummary | None = None
    path: Path | None = None
    dataset: Any = None
    summary: str = ""
    interrupted: bool = False

    @property
    def failed(self) -> list[Any]:
        return [
            *(self.base.failed if self.base else []),
            *(self.variants.failed if self.variants else []),
        ]


def load_fits_or_none(store: CampaignStore) -> Any:
    """The campaign's fits.nc (``None`` when it has none or it cannot be read)."""
    from ..analysis.fits_file import FITS

    path = store.root / FITS
    if not path.exists():
        return None
    import xarray as xr

    try:
        with xr.open_dataset(path) as ds:
            return ds.load()
    except (OSError, ValueError) as e:
        log.warning("verify: fits.nc not read (%s): sampling the corners and listed points", e)
        return None


def sample_of(campaign: Campaign, store: CampaignStore, *, before: bool = False) -> Sample:
    """The sample of ``campaign``: with the fitted transitions unless ``before``."""
    from ..refine.rounds import expansion_for

    expansion = expansion_for(campaign, store)
    return plan_sample(campaign, expansion, None if before else load_fits_or_none(store))


def run_verification(
    campaign: Campaign,
    store: CampaignStore,
    *,
    before: bool = False,
    events: RunEvents | None = None,
    dashboard: bool = False,
    say: Callable[[str], None] = print,
    link: ClusterLink | None = None,
    stop: threading.Event | None = None,
) -> VerifyOutcome:
    """Run what the sample needs and write ``verify.nc``; the caller holds the lock. With
    ``link`` the runs go to that open cluster (the service's), which stays open; ``stop`` set
    interrupts them as Ctrl-C does."""
    sample = sample_of(campaign, store, before=before)
    outcome = VerifyOutcome(sample)
    for problem in sample.problems:
        say(f"verify: skipped {problem}")
    vstore = verify_store(store)
    vstore.ensure()
    base = RunList(campaign, sample.base_list())
    variants = RunList(campaign, sample.variant_list())
    # the variants' folder is no campaign of the results root: no catalogue, no reuse there
    plan_b, plan_v = plan_runs(base, store), plan_runs(variants, vstore, reuse=False)
    say(
        f"verify {campaign.name}: {len(sample.points)} points x {len(sample.seeds)} seeds, "
        f"{len(sample.variants)} variant(s): {len(base)} base runs ({len(plan_b.todo)} to "
        f"do), {len(variants)} variant runs ({len(plan_v.todo)} to do) -> {vstore.root}"
    )
    local = campaign.execution.mode == "local"
    if plan_b.todo or plan_v.todo:
        with contextlib.ExitStack() as stack:
            own = link is None
            try:
                if link is None:
                    link = stack.enter_context(
                        open_cluster(
                            campaign.execution, dashboard=dashboard, campaign_dir=store.root
                        )
                    )
                for runs, where, plan, attr in (
                    (base, store, plan_b, "base"),
                    (variants, vstore, plan_v, "variants"),
                ):
                    if not plan.todo:
                        continue
                    where.clean_temporaries(min_age=0.0 if local else REMOTE_TMP_AGE)
                    # the variants' runs are not the campaign's: not in the catalogue
                    summary = run_campaign(
                        runs, where, link, plan, events, record=where is store, stop=stop
                    )
                    setattr(outcome, attr, summary)
                    if summary.interrupted or summary.storage_error or summary.lost:
                        outcome.interrupted = True
                        break
            except KeyboardInterrupt:
                outcome.interrupted = True
            finally:
                if local and own:
                    stack.close()
                    store.clean_temporaries()
                    vstore.clean_temporaries()
    ran = bool(plan_b.todo or plan_v.todo)  # else the plans' scans are the records
    records = store.scan() if ran else plan_b.records
    vrecords = vstore.scan() if ran else plan_v.records
    if outcome.interrupted:
        return outcome
    outcome.dataset = verify_dataset(sample, records, vrecords)
    outcome.path = write_verify(store.root, outcome.dataset)
    outcome.summary = summary_line(outcome.dataset)
    return outcome
