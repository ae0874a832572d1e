"""``nematic export``: a campaign's runs as one tidy table (CSV or Parquet), for pandas, R
or a spreadsheet (:mod:`nematic_solids.sweep.outputs.tables`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .app import (
    EXIT_BAD_INPUT,
    CampaignRefArg,
    Console,
    QuietOpt,
    ResultsOpt,
    VerboseOpt,
    err_console,
    error,
    setup_logging,
)


def export(
    campaign: CampaignRefArg,
    results: ResultsOpt = Path("results"),
    fmt: Annotated[
        str | None,
        typer.Option(
            "--format",
            metavar="csv|parquet",
            help="The table's format (default: from the "
            "--output suffix, else csv). Parquet needs pyarrow (the parquet extra).",
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help="Where to write it (default: results/NAME/runs.csv or runs.parquet).",
        ),
    ] = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Write the campaign's runs as one tidy table.

    One row per finished run (ok or failed): every swept axis, seed, run_id, status, reason
    and every per-run scalar (the variables of phase.nc over seed), written atomically.
    Reads the run records only, so it also works while the campaign runs.
    """
    from ..outputs.tables import FORMATS, open_campaign, parquet_engine, write_table

    err = err_console()
    setup_logging(err, verbose, quiet)
    if fmt is None:
        suffix = output.suffix.lower().lstrip(".") if output is not None else ""
        fmt = suffix if suffix in FORMATS else "csv"
    if fmt not in FORMATS:
        error(err, f"--format: got {fmt!r}; allowed: {', '.join(FORMATS)}")
        raise typer.Exit(EXIT_BAD_INPUT)
    if fmt == "parquet":
        parquet_engine()  # before reading the runs: say at once if it cannot be written
    opened = open_campaign(campaign, results)
    table = opened.runs()
    path = output if output is not None else opened.store.root / f"runs.{fmt}"
    write_table(table, path, fmt)
    n_ok = int((table["status"] == "ok").sum())
    Console(highlight=False, soft_wrap=True, quiet=quiet).print(
        f"wrote {path}: {len(table)} run(s) ({n_ok} ok, {len(table) - n_ok} failed), "
        f"{len(table.columns)} columns",
        markup=False,
    )
