"""``nematic report``: a campaign's results as one self-contained HTML page
(:mod:`nematic_solids.sweep.report`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..startup import paused_gc
from .app import (
    CampaignRefArg,
    Console,
    QuietOpt,
    ResultsOpt,
    VerboseOpt,
    err_console,
    setup_logging,
)


@paused_gc()  # a short command: nematic_solids.sweep.startup says why
def report(
    campaign: CampaignRefArg,
    results: ResultsOpt = Path("results"),
    output: Annotated[
        Path | None,
        typer.Option(
            "--output", "-o", help="Where to write it (default: results/NAME/report.html)."
        ),
    ] = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Write the campaign's report: one HTML file that opens without a server or a network.

    The question, grid, seeds and counts; the figures and fits; an interactive phase
    diagram (hover a point for its parameters and seed values, click it for a run's
    snapshot and sigma2_S(t)); the failures by reason; the refinement rounds; the cost and
    the provenance. Reads the results folder only (also while the campaign runs).
    """
    from ..outputs.tables import open_campaign
    from ..report import write_report
    from ..startup import defer_dask_array

    defer_dask_array()
    err = err_console()
    setup_logging(err, verbose, quiet)
    opened = open_campaign(campaign, results)
    if not opened.store.runs_dir.is_dir():
        from ..errors import StoreError

        raise StoreError(
            f"no results for campaign {opened.campaign.name} in "
            f"{opened.store.root}; run it first (nematic run)"
        )
    path = write_report(opened, output)
    Console(highlight=False, soft_wrap=True, quiet=quiet).print(f"wrote {path}", markup=False)
