"""The campaign commands ``nematic validate`` and ``aggregate``, and what ``run`` shares with
them: the cost before launch and what changed in the campaign file (``run``:
:mod:`nematic_solids.sweep.cli.run`; ``status``: :mod:`nematic_solids.sweep.cli.status`)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from ..errors import CampaignLocked, StoreError
from ..startup import paused_gc
from .app import (
    EXIT_BAD_INPUT,
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
from .collection import collection_or_none, refuse_name, validate_collection


# --------------------------------------------------------------------------- validate
def validate(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    estimate: Annotated[
        bool,
        typer.Option(
            "--estimate",
            help="Also estimate the cost: the runs to do, their CPU time "
            "and the wall time on the campaign's workers, from the campaign's finished "
            "runs in the results folder, else from the cost model (as `nematic run "
            "--dry-run`). Reads the folder, writes nothing.",
        ),
    ] = False,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Check a campaign file without running anything.

    Exit 0 if it is valid (a summary of the grid is printed), 2 with every problem listed
    (file:line, key path, value, what is allowed) otherwise.
    """
    console = Console(highlight=False, soft_wrap=True, quiet=quiet)
    setup_logging(err_console(), verbose, quiet)
    coll = collection_or_none(campaign)
    if (
        coll is not None
    ):  # a collection of campaigns (nematic_solids.sweep.spec.collection): each, then the sum
        refuse_name(name)
        validate_collection(
            coll,
            validate,
            dict(
                results=results,
                set_=set_,
                seeds=seeds,
                estimate=estimate,
                verbose=verbose,
                quiet=quiet,
            ),
            console,
        )
        return
    c = load(err_console(), campaign, set_, seeds, name)
    console.print(f"[green]valid[/]: campaign [bold]{escape(c.name)}[/] ({escape(str(campaign))})")
    for d in c.dims:
        for a in d.axes:
            vals = ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in a.values[:8])
            more = ", ..." if len(a.values) > 8 else ""
            zipped = f" (zipped with {d.name})" if a.name != d.name else ""
            console.print(
                f"  axis {a.name}{zipped}: {len(a.values)} values {escape(f'[{vals}{more}]')}"
            )
    console.print(f"  seeds: {len(c.seeds)}; grid points: {c.n_points}; runs: {c.n_runs}")
    ex = c.execution
    where = {
        "local": f"local dask cluster ({ex.workers or 'one per core'} worker(s))",
        "scheduler": f"dask scheduler {ex.scheduler}",
        "cluster": f"dask-jobqueue {ex.cluster.kind if ex.cluster else ''}",
    }[ex.mode]
    console.print(f"  execution: {where}; results: {results / c.name}", markup=False)
    if c.fits or c.figures is not None:
        shown = (
            "every one that applies"
            if c.figures is None
            else ", ".join(p.name for p in c.figures) or "none"
        )
        console.print(
            "  fits: " + (", ".join(p.name for p in c.fits) or "none") + "; figures: " + shown
        )
    if c.refine is not None:  # an adaptive campaign: its first round and a bound (sweep/refine)
        from ..refine.report import validation_lines

        for line in validation_lines(c):
            console.print(f"  {line}", markup=False)
    if c.precision is not None and c.refine is None:  # seeds by precision on the grid
        from ..precision.rounds import validation_lines as precision_lines

        for line in precision_lines(c):
            console.print(f"  {line}", markup=False)
    if c.verify is not None:
        from .verify import validation_line

        console.print(f"  {validation_line(c.verify)}", markup=False)
    if estimate:
        print_estimate(console, c, results, indent="  ")


def print_estimate(
    console: Console,
    campaign: Any,
    results: Path,
    *,
    indent: str = "",
    retry_failed: bool = False,
    brief: bool = False,
    header: str | None = None,
    started: float | None = None,
) -> None:
    """The cost before launch (:mod:`nematic_solids.sweep.cost.estimate`): what changed in the
    campaign file, the runs to do and their CPU and wall time; ``brief``: the totals only;
    ``started``: the seconds the running driver took to start (a re-estimate mid-campaign:
    the estimate leaves them out of the driver's own time)."""
    from ..cost.estimate import estimate
    from ..cost.result import lines
    from ..store import CampaignStore

    e = estimate(
        campaign,
        CampaignStore(results, campaign.name),
        retry_failed=retry_failed,
        started=started,
    )
    for line in ([header] if header else []) + ([] if brief else e.changes) + lines(e, brief=brief):
        console.print(f"{indent}{line}", markup=False)


def report_changes(
    say: Console,
    campaign: Any,
    store: Any,
    expansion: Any = None,
    *,
    prune: bool = False,
    hint: str = "",
) -> dict[str, Any] | None:
    """Print what changed since the results were made (:mod:`nematic_solids.sweep.outputs.changes`)
    and, with ``prune``, remove the orphaned runs (the caller holds the lock); return the changes
    for ``--json``."""
    from ..outputs.changes import campaign_changes, run_counts
    from ..outputs.changes import prune as prune_runs

    changed = campaign_changes(campaign, store, expansion)
    if changed is not None:
        for line in changed.lines():
            say.print(line, markup=False)
        if changed.counts.orphaned and not prune and hint:
            say.print(f"  the orphaned runs are kept; {hint}", markup=False)
    if prune:
        if changed is not None:
            orphaned = changed.counts.orphaned
        else:
            from ..refine.rounds import expansion_for

            orphaned = run_counts(
                campaign, expansion or expansion_for(campaign, store), store, store.scan()
            ).orphaned
        n = prune_runs(store, orphaned)
        say.print(
            f"pruned {n} orphaned run(s) (their records and run files) from {store.runs_dir}"
            if n
            else "nothing to prune: every run in the folder is planned by this campaign",
            markup=False,
        )
    return None if changed is None else changed.to_dict()


def storage_message(store: Any, e: OSError) -> str:
    from ..files import storage_error

    return str(storage_error(Path(e.filename) if e.filename else store.root, e))


# --------------------------------------------------------------------------- aggregate
@paused_gc()  # a short command: nematic_solids.sweep.startup says why
def aggregate(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Write `results/NAME/phase.nc` from the runs on disk.

    Missing and failed runs are NaN. Refuses while a driver is running the campaign (the
    driver aggregates when it ends).
    """
    from ..outputs.aggregate import write_phase
    from ..refine.rounds import expansion_for
    from ..startup import defer_dask_array
    from ..store import CampaignStore

    err = err_console()
    setup_logging(err, verbose, quiet)
    c = load(err, campaign, set_, seeds, name)
    defer_dask_array()
    store = CampaignStore(results, c.name)
    if not store.runs_dir.is_dir():
        error(
            err,
            f"no results for campaign {c.name} in {store.root}; run it first "
            f"(nematic run {campaign})",
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    lock = store.lock()
    try:
        lock.acquire(command=" ".join(sys.argv))
        try:
            ds = write_phase(expansion_for(c, store), store)
        finally:
            lock.release()
    except (CampaignLocked, StoreError) as e:
        error(err, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    Console(highlight=False, soft_wrap=True, quiet=quiet).print(
        f"wrote {store.phase_path}: {ds.attrs['n_ok']} ok, {ds.attrs['n_failed']} failed, "
        f"{ds.attrs['n_missing']} missing of {ds.attrs['n_runs']} runs"
    )
