"""Fits and figures around a campaign command: an unreadable phase.nc rebuilt, an unreadable
fits.nc removed (:func:`repair_products`), and the figures drawn after a run."""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from rich.markup import escape

from ..campaign import Campaign
from .app import Console

if TYPE_CHECKING:
    from ..figures.produce import Outcome


def repair_products(
    campaign: Campaign, results: Path, console: Console, *, phase: bool = True
) -> bool:
    """Before fits and figures are drawn: an unreadable ``phase.nc`` is rebuilt from the run
    records (taking the campaign's lock) and an unreadable ``fits.nc`` removed (the fits
    recompute it), each with a message. Returns whether ``fits.nc`` was removed. Raises
    :class:`CampaignLocked` if a driver holds the campaign while phase.nc must be rebuilt."""
    from ..analysis.fits_file import FITS
    from ..files import netcdf_problem
    from ..outputs.aggregate import write_phase
    from ..refine.rounds import expansion_for
    from ..store import CampaignStore

    store = CampaignStore(results, campaign.name)
    if phase and store.phase_path.exists():
        problem = netcdf_problem(store.phase_path, ("status", "run_id"))
        if problem is not None:
            console.print(
                f"[yellow]{escape(f'{store.phase_path}: {problem}')}[/]; rebuilding it from the "
                "run records",
                soft_wrap=True,
                highlight=False,
            )
            lock = store.lock()
            lock.acquire(command=" ".join(sys.argv))
            try:
                write_phase(expansion_for(campaign, store), store)
            finally:
                lock.release()
    fits_path = store.root / FITS
    if fits_path.exists():
        problem = netcdf_problem(fits_path)
        if problem is not None:
            console.print(
                f"[yellow]{escape(f'{fits_path}: {problem}')}[/]; removing it (the fits "
                "recompute it)",
                soft_wrap=True,
                highlight=False,
            )
            fits_path.unlink()
            return True
    return False


def regenerate_figures(
    campaign: Campaign, results: Path, *, fits: bool = True, draw_figures: bool = True
) -> Outcome:
    """Fits and figures after a run (:func:`nematic_solids.sweep.figures.produce.produce`):
    what was written and what failed (``Outcome.failures``; the caller reports them, and
    ``nematic run`` exits :data:`~nematic_solids.sweep.cli.app.EXIT_PRODUCTS_FAILED`); the
    fits' caveats are logged. No phase.nc yet: nothing written, logged. ``fits`` /
    ``draw_figures`` false leave either out."""
    import logging

    from ..errors import FigureError
    from ..figures.produce import Outcome, produce

    log = logging.getLogger(__name__)
    try:
        out = produce(campaign, results, fits=fits, draw_figures=draw_figures)
    except FigureError as e:
        log.warning("no figures: %s", e)
        return Outcome()
    for note in out.notes:
        log.warning("fits: %s", note)
    return out


def failure_lines(failures: Mapping[str, str]) -> list[str]:
    """One line per failed fit or figure (``Outcome.failures`` of
    :func:`nematic_solids.sweep.figures.produce.produce`, keys ``fit NAME`` or the figure's
    name): ``fit transition: why``, ``figure loop: why``."""
    from ..figures.failed import label

    return [f"{label(k)}: {v}" for k, v in failures.items()]


def regenerate_report(campaign: Campaign, results: Path) -> Path | None:
    """The report after a run's figures (:func:`nematic_solids.sweep.report.write_report`): its
    path, or ``None`` (logged) when it cannot be written; a report never sinks the run it
    follows."""
    import logging

    from nematic_solids.model.errors import NematicError

    from ..outputs.tables import CampaignResults
    from ..report import write_report

    try:
        return write_report(CampaignResults(campaign, results))
    except NematicError as e:
        logging.getLogger(__name__).warning("report not written: %s", e)
    except Exception:  # a bug here must not fail the campaign's runs
        logging.getLogger(__name__).warning("report not written", exc_info=True)
    return None
