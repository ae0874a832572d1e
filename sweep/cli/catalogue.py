"""``nematic catalogue``: the catalogue of runs of a results root
(:mod:`nematic_solids.sweep.catalogue`): ``index`` (from the run files, recomputing nothing),
``runs`` (filtered by campaign, status and ranges of any value, across campaigns; a table or
CSV) and ``campaigns``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table

from .app import (
    EXIT_BAD_INPUT,
    CatalogueOpt,
    QuietOpt,
    VerboseOpt,
    err_console,
    error,
    setup_logging,
)

if TYPE_CHECKING:
    import pandas as pd

ACTIONS = ("index", "runs", "campaigns")
#: the columns ``runs`` shows in a table unless --columns says otherwise
SHOWN = ("run_id", "status", "reason", "seed", "t_final", "wall_time")


def _open(root: Path, url: str | None, index: bool = True):  # type: ignore[no-untyped-def]
    from ..catalogue import open_catalogue
    from ..catalogue.location import is_url, sqlite_url

    if url is None:
        return open_catalogue(root, index=index)
    if not is_url(url):
        url = sqlite_url(Path(url).expanduser())
    return open_catalogue(url, root=root, index=index)


def _print_frame(df: pd.DataFrame, fmt: str, output: Path | None, quiet: bool) -> None:
    if fmt == "csv":
        if output is None:
            df.to_csv(sys.stdout, index=False)
        else:
            from ..files import atomic_write_text

            atomic_write_text(output, df.to_csv(index=False))
        return
    # a pipe or a file gets every column whole; a terminal, its width
    width = None if sys.stdout.isatty() else 100_000
    console = Console(highlight=False, soft_wrap=False, quiet=quiet, width=width)
    table = Table(*[str(c) for c in df.columns], box=None, pad_edge=False)
    for row in df.itertuples(index=False):
        table.add_row(*(_cell(v) for v in row))
    console.print(table)


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if value != value else f"{value:.6g}"
    return str(value)


def catalogue(
    action: Annotated[
        str,
        typer.Argument(
            metavar="index|runs|campaigns",
            help="index: record every results folder under ROOT from its files; runs: list "
            "runs; campaigns: list campaigns with their counts.",
            show_default=False,
        ),
    ],
    root: Annotated[
        Path,
        typer.Argument(
            envvar="NEMATIC_RESULTS",
            help="The results root (the folder holding results/NAME/ folders).",
        ),
    ] = Path("results"),
    url: CatalogueOpt = None,
    campaign: Annotated[
        str | None, typer.Option("--campaign", help="runs: only this campaign's runs.")
    ] = None,
    status: Annotated[
        str | None, typer.Option("--status", metavar="ok|failed", help="runs: only these.")
    ] = None,
    where: Annotated[
        list[str] | None,
        typer.Option(
            "--where",
            metavar="KEY=VALUE|KEY=LOW:HIGH",
            help="runs: a condition on any parameter, numeric, scalar or swept value "
            "(repeatable; all must hold), e.g. --where K=1e-5 --where alpha_minus_B=0.5:0.7 "
            "--where resolution=256; a number matches within 1e-9 relative; "
            "'parameters.K' names the space.",
        ),
    ] = None,
    columns: Annotated[
        str | None,
        typer.Option(
            "--columns",
            metavar="A,B,...",
            help="runs: the columns to show (default: the run's, the campaign(s), and the "
            "values --where names; 'all' for every column).",
        ),
    ] = None,
    fmt: Annotated[
        str, typer.Option("--format", metavar="table|csv", help="How to print the rows.")
    ] = "table",
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the CSV here (--format csv).")
    ] = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """The catalogue of every run of every campaign under a results root.

    `nematic catalogue index [ROOT]` records every results folder under ROOT from its run
    records (or its phase.nc alone), recomputing nothing; `nematic catalogue runs` lists runs
    across campaigns, filtered by --campaign, --status and --where; `nematic catalogue
    campaigns` lists the campaigns with their counts of runs (made, reused).
    """
    from ..catalogue import index_root, parse_condition

    err = err_console()
    setup_logging(err, verbose, quiet)
    if action not in ACTIONS:
        error(err, f"unknown action {action!r}; allowed: {', '.join(ACTIONS)}")
        raise typer.Exit(EXIT_BAD_INPUT)
    if fmt not in ("table", "csv"):
        error(err, f"--format: got {fmt!r}; allowed: table, csv")
        raise typer.Exit(EXIT_BAD_INPUT)
    if not root.is_dir():
        error(err, f"no results root {root} (give the folder holding results/NAME/ folders)")
        raise typer.Exit(EXIT_BAD_INPUT)
    try:
        conditions = [parse_condition(w) for w in where or ()]
    except ValueError as e:
        error(err, f"--where {e}")
        raise typer.Exit(EXIT_BAD_INPUT) from None
    out = Console(highlight=False, soft_wrap=True, quiet=quiet)
    if action == "index":
        with _open(root, url, index=False) as cat:
            found = index_root(cat, root)
            for name, n in found.runs.items():
                out.print(f"{name}: {n} run(s) from its {found.sources[name]}", markup=False)
            for problem in found.problems:
                error(err, problem)
            out.print(
                f"indexed {found.total} run(s) of {len(found.runs)} campaign(s) into {_where(cat)}",
                markup=False,
            )
        if found.problems:
            raise typer.Exit(1)
        return
    with _open(root, url) as cat:
        if action == "campaigns":
            _print_frame(cat.campaigns(), fmt, output, quiet)
            return
        df = cat.runs(campaign=campaign, where=conditions, status=status)
    df = _select(df, columns, [c.key.rpartition(".")[2] for c in conditions])
    _print_frame(df, fmt, output, quiet)
    if fmt == "table":
        err.print(f"{len(df)} run(s)", highlight=False, markup=False)


def _where(cat: object) -> str:
    from ..catalogue.location import redacted

    return redacted(str(getattr(cat, "url", "")))


def _select(df: pd.DataFrame, columns: str | None, named: list[str]) -> pd.DataFrame:
    if columns == "all":
        return df
    if columns:
        wanted = [c.strip() for c in columns.split(",") if c.strip()]
        missing = [c for c in wanted if c not in df.columns]
        if missing and not df.empty:
            raise typer.BadParameter(
                f"no column {', '.join(missing)} (there are: {', '.join(map(str, df.columns))})",
                param_hint="--columns",
            )
        return df[[c for c in wanted if c in df.columns]]
    base = [*SHOWN, "campaign", "origin", "campaigns"]
    keep = [c for c in dict.fromkeys([*base, *named]) if c in df.columns]
    return df[keep]
