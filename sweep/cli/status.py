"""``nematic status``: where a campaign stands, from its run records (and what changed in its
file, its rounds, its failures by reason, its verification's summary)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from ..startup import paused_gc
from .app import (
    CampaignArg,
    Console,
    NameOpt,
    QuietOpt,
    ResultsOpt,
    SeedsOpt,
    SetOpt,
    VerboseOpt,
    err_console,
    fmt_time,
    load,
    setup_logging,
)
from .campaigns import report_changes
from .collection import collection_or_none, refuse_name, status_collection


# a short command (10^5 records: millions of objects): nematic_solids.sweep.startup says why
@paused_gc()
def status(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    workers: Annotated[
        int | None,
        typer.Option(
            "--workers",
            help="Concurrency assumed for the ETA (default: the processes seen "
            "finishing runs under the running driver, else the local worker count).",
        ),
    ] = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Show done / failed / pending runs, failure reasons and an ETA.

    Counts are given overall and per sweep value, with what changed if the campaign differs
    from the one its results were made with. Only the run records are read (no netCDF), so
    it answers in seconds for 10^5 runs, also while the campaign runs.
    """
    from ..outputs.status import campaign_status
    from ..refine.rounds import expansion_for
    from ..store import CampaignStore

    console = Console(highlight=False, soft_wrap=True)
    setup_logging(err_console(), verbose, quiet)
    coll = collection_or_none(campaign)
    if (
        coll is not None
    ):  # a collection of campaigns (nematic_solids.sweep.spec.collection): each in turn
        refuse_name(name)
        status_collection(
            coll,
            status,
            dict(
                results=results,
                set_=set_,
                seeds=seeds,
                as_json=as_json,
                workers=workers,
                verbose=verbose,
                quiet=quiet,
            ),
        )
        return
    c = load(err_console(), campaign, set_, seeds, name)
    store = CampaignStore(results, c.name)
    expansion = expansion_for(c, store)
    report = campaign_status(expansion, store, workers=workers)
    refinement = getattr(expansion, "refinement", None)  # an adaptive campaign's rounds
    if as_json:
        from ..outputs.changes import campaign_changes
        from ..refine.rounds import status_dict
        from .verify import verification_lines

        changed = campaign_changes(c, store, expansion)
        checks = verification_lines(store.root)
        typer.echo(
            json.dumps(
                {
                    **report.to_dict(),
                    **status_dict(refinement),
                    "changes": None if changed is None else changed.to_dict(),
                    "verification": checks[0] if checks else None,
                },
                default=str,
            )
        )
        return
    pct = 100.0 * report.done / max(report.total, 1)
    console.print(
        f"campaign [bold]{escape(str(report.campaign))}[/] ({escape(str(report.folder))}): "
        f"[green]{report.done} done[/], [red]{report.failed} failed[/], "
        f"{report.pending} pending of {report.total} ({pct:.0f}% done)"
    )
    if quiet:
        return
    console.print(driver_line(report.running, report.campaign), markup=False)
    report_changes(console, c, store, expansion, hint="'nematic run --prune' removes them")
    if refinement is not None:
        from ..refine.report import status_lines

        for line in status_lines(refinement):
            console.print(line, markup=False)
    if report.pending:
        basis = f" ({report.eta_basis})" if report.eta_basis else ""
        console.print(f"ETA: {fmt_time(report.eta_seconds)}{basis}")
    if report.median_run_time is not None and report.mean_run_time is not None:
        console.print(
            f"run time: median {report.median_run_time:.3g} s, mean "
            f"{report.mean_run_time:.3g} s (successful runs)"
        )
    if report.in_progress:
        console.print(
            f"{len(report.in_progress)} pending run(s) with a checkpoint (in progress, or "
            "continued from it by the next 'nematic run'):"
        )
        for run in report.in_progress[:MAX_IN_PROGRESS]:
            coords = ", ".join(f"{k} = {_label(v)}" for k, v in run["coords"].items())
            console.print(
                f"  {run['run_id']} ({coords}): t = {run['t']:.6g} of {run['t_final']:g}, "
                f"checkpoint {run['checkpoint']} (written {run['written']})",
                markup=False,
            )
        if len(report.in_progress) > MAX_IN_PROGRESS:
            console.print(
                f"  ... and {len(report.in_progress) - MAX_IN_PROGRESS} more (--json lists all)"
            )
    for ax in report.per_axis:
        table = Table(title=f"by {ax.dim}", title_justify="left", show_edge=False)
        for col in (ax.dim, "done", "failed", "pending"):
            table.add_column(col, justify="right")
        for row in zip(ax.labels, ax.done, ax.failed, ax.pending, strict=True):
            table.add_row(*(escape(str(x)) for x in row))
        console.print(table)
    if report.reasons:
        console.print(
            "[red]failures by reason[/]: "
            + escape(", ".join(f"{k}: {v}" for k, v in report.reasons.items()))
        )
        for group in report.failure_groups:
            for line in failure_group_lines(group):
                console.print(line, markup=False)
    if report.unreadable:
        console.print(
            f"[yellow]{report.unreadable} run(s) pending because their file is "
            "missing, truncated or corrupt[/] (the next 'nematic run' redoes them):"
        )
        for ex in report.unreadable_examples:
            console.print(f"  {ex['run_id']}: {ex['problem']}", markup=False)
    if report.reused:
        parts = ", ".join(f"{n} from {name}" for name, n in report.reused.items())
        console.print(
            f"{sum(report.reused.values())} done run(s) made by other campaigns, taken in "
            f"place: {parts}",
            markup=False,
        )
    if report.foreign_runs:
        console.print(
            f"{report.foreign_runs} run record(s) in the folder belong to other "
            "grids (kept, not counted)"
        )
    from .verify import verification_lines

    for line in verification_lines(store.root, detail=verbose):
        console.print(line, markup=False)


#: runs in progress listed by name (``--json`` has all)
MAX_IN_PROGRESS = 20


def _label(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def driver_line(running: dict[str, Any] | None, name: str) -> str:
    """Whether a driver holds the campaign (the lock's holder: alive, since the kernel
    releases the lock when it ends), with its pid, host, start, SLURM job and log."""
    if running is None:
        return "driver: none running"
    job = f", SLURM job {running['slurm_job']}" if running.get("slurm_job") else ""
    log = f"; log: {running['log']}" if running.get("log") else ""
    return (
        f"driver running: pid {running.get('pid')} on {running.get('host')} since "
        f"{running.get('started')}{job}{log} (nematic stop {name} stops it)"
    )


def failure_group_lines(group: dict[str, Any]) -> list[str]:
    """``nematic status``'s lines for one failure reason: the count, the first such run
    (swept values and seed, model time and date of the failure, message) and its files."""
    coords = ", ".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in group["coords"].items()
    )
    t = group.get("t_failed")
    at = f" at t = {t:.4g}" if isinstance(t, (int, float)) else ""
    when = f" on {group['finished']}" if group.get("finished") else ""
    detail = str(group.get("detail") or "").strip().splitlines()
    files = f"record (with traceback): {group['record']}"
    if group.get("run_file"):
        files += f"; partial run file: {group['run_file']}"
    return [
        f"  {group['reason']}: {group['count']} run(s); first: {group['run_id']} "
        f"({coords}){at}{when}" + (f": {detail[-1]}" if detail else ""),
        f"    {files}",
    ]
