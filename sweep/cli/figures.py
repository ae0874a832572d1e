"""``nematic figures``: fits and figures of a campaign from its results folder.

Only parses and calls :func:`nematic_solids.sweep.figures.produce.produce`.
Exit codes: 0 every fit and figure was produced, 4 some failed (each listed in one line), 2 bad
input (invalid campaign, unknown figure name, no phase.nc yet).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from ..errors import CampaignLocked, FigureError, StoreError
from .app import (
    EXIT_BAD_INPUT,
    EXIT_PRODUCTS_FAILED,
    CampaignArg,
    Console,
    NameOpt,
    QuietOpt,
    ResultsOpt,
    SeedsOpt,
    SetOpt,
    VerboseOpt,
    err_console,
    error,
    load,
    setup_logging,
)
from .products import failure_lines, regenerate_report, repair_products


def figures(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    only: Annotated[
        list[str] | None,
        typer.Option(
            "--only",
            metavar="FIGURE",
            help="Draw only this figure (repeatable): {figures}. Default: the campaign's "
            "'figures:' list ('figures: []': none), else every figure that applies to its grid.",
        ),
    ] = None,
    fits: Annotated[
        bool,
        typer.Option(
            "--fits/--no-fits",
            help="Recompute fits.nc from phase.nc first (default), or draw from the fits.nc on "
            "disk. Fits: {fits}.",
        ),
    ] = True,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Write `results/NAME/fits.nc` and `results/NAME/figures/*.png|pdf` from phase.nc.

    Figures read only the results folder (phase.nc, fits.nc, runs/*.nc). The overrides
    (--set, --seeds, --name) must match those of the run, since they name the folder. Exit 0
    if everything was produced, 4 if a fit or figure failed (each listed in one line, and
    in the report, which is rewritten if there is one), 2 on bad input or when the campaign
    has no phase.nc yet.
    """
    from ..figures.produce import produce
    from ..files import probe_write, storage_cause
    from ..report.page import REPORT

    console = Console(highlight=False, soft_wrap=True, quiet=quiet)
    err = err_console()
    setup_logging(err, verbose, quiet)
    c = load(err, campaign, set_, seeds, name)
    root = results / c.name
    problem = probe_write(root) if root.is_dir() else None
    if problem is not None:
        err.print(
            "[bold red]error:[/] "
            + escape(
                f"cannot write the fits and figures in {root}: "
                f"{storage_cause(root / 'figures', problem)}"
            ),
            soft_wrap=True,
            highlight=False,
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    try:
        if repair_products(c, results, err) and not fits:
            err.print("fits.nc was unreadable: recomputing the fits despite --no-fits")
            fits = True
        out = produce(c, results, names=only or None, fits=fits)
    except (FigureError, StoreError, CampaignLocked) as e:
        error(err, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    if out.fits_path is not None:
        console.print(f"fits: {out.fits_path}", markup=False)
    for note in out.notes:
        console.print(f"  note: {note}", markup=False)
    for path in out.paths:
        console.print(f"figure: {path}", markup=False)
    if not out.figures:
        why = (
            "the campaign lists none (figures: [])"
            if c.figures is not None
            else "none applies to this grid"
        )
        console.print(f"no figures: {why}; --only FIGURE draws one", markup=False)
    if (root / REPORT).is_file():  # a report written before shows these figures and failures
        page = regenerate_report(c, results)
        if page is not None:
            console.print(f"report: {page}", markup=False)
    for line in failure_lines(out.failures):
        err.print(f"[red]failed[/]: {escape(line)}", soft_wrap=True, highlight=False)
    if out.failures:
        raise typer.Exit(EXIT_PRODUCTS_FAILED)
