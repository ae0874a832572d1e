"""``nematic run``: a campaign (or a collection of campaigns) run or resumed on dask, then its
phase.nc, fits, figures, verification and report; ``--dry-run`` and ``--detach``."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
)

from ..errors import CampaignError, CampaignLocked, ClusterError, StoreError
from .app import (
    EXIT_BAD_INPUT,
    EXIT_FAILED_RUNS,
    EXIT_INTERRUPTED,
    EXIT_TOO_MANY_FAILURES,
    CampaignArg,
    CatalogueOpt,
    NameOpt,
    QuietOpt,
    ResultsOpt,
    SeedsOpt,
    SetOpt,
    VerboseOpt,
    err_console,
    error,
    fmt_time,
    load,
    setup_logging,
    sigterm_as_interrupt,
)
from .campaigns import print_estimate, report_changes, storage_message
from .collection import collection_or_none, refuse_name, run_collection
from .products import regenerate_figures, regenerate_report, repair_products
from .progress import ProgressEvents


def run(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Use the dask scheduler at this address (tcp://HOST:PORT) instead "
            "of the campaign's execution section.",
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            "--workers", help="Local worker processes (default: the campaign's, else one per core)."
        ),
    ] = None,
    retry_failed: Annotated[
        bool,
        typer.Option(
            "--retry-failed",
            help="Also redo runs that failed before (their new record keeps "
            "the earlier failures under previous_failures).",
        ),
    ] = False,
    max_failures: Annotated[
        str | None,
        typer.Option(
            "--max-failures",
            metavar="N",
            help="Stop the campaign (exit 3) once more runs failed in this session than N: a "
            "count (0 stops at the first failure) or a fraction of the runs to do (0.1). Runs "
            "not finished stay pending.",
        ),
    ] = None,
    prune: Annotated[
        bool,
        typer.Option(
            "--prune",
            help="First remove the orphaned runs: the records and files in the "
            "results folder of runs this campaign does not plan (e.g. values since removed from "
            "an axis); says how many.",
        ),
    ] = False,
    check_files: Annotated[
        bool,
        typer.Option(
            "--check-files",
            help="Checksum every finished run's file (by default only files "
            "whose size or mtime changed are), and redo the corrupt ones.",
        ),
    ] = False,
    check_files_alias: Annotated[
        bool, typer.Option("--verify", hidden=True, help="The former name of --check-files.")
    ] = False,
    verification: Annotated[
        bool,
        typer.Option(
            "--verification/--no-verification",
            help="Run the campaign's verify: section "
            "(as 'nematic verify' does): after the fits, or first with verify.before.",
        ),
    ] = True,
    aggregate: Annotated[
        bool, typer.Option("--aggregate/--no-aggregate", help="Write phase.nc at the end.")
    ] = True,
    figures: Annotated[
        bool,
        typer.Option(
            "--figures/--no-figures",
            help="After phase.nc, write fits.nc and the figures "
            "(as 'nematic figures' does), then report.html (as 'nematic report' does).",
        ),
    ] = True,
    dashboard: Annotated[
        bool,
        typer.Option(
            "--dashboard/--no-dashboard",
            help="Serve the dask dashboard (local cluster: on "
            "127.0.0.1, a free port) and print its link.",
        ),
    ] = True,
    dry_run: Annotated[
        bool,
        typer.Option(
            "--dry-run",
            help="Run nothing and write nothing (no results folder, no lock): print "
            "the runs to do, their estimated CPU time and the wall time on the workers at this "
            "machine's load, from the campaign's own finished runs (per point, scaled by "
            "resolution, length and mechanics), else from the calibrated cost model; with the "
            "basis and the 10-90 % range. Takes --workers, --scheduler and --retry-failed into "
            "account.",
        ),
    ] = False,
    detach: Annotated[
        bool,
        typer.Option(
            "--detach",
            help="Run the driver in the background, in a session of its own "
            "(closing the terminal or logging out does not end it), its output in "
            "results/NAME/driver.log; prints how to follow it (`tail -f`, `nematic status`) and "
            "stop it (`nematic stop NAME`).",
        ),
    ] = False,
    catalogue: CatalogueOpt = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Run a campaign on dask, resuming where it stopped.

    Finished runs are skipped, the rest run on a local dask cluster (default), a scheduler or
    a dask-jobqueue cluster; one netCDF per run, phase.nc at the end. If the campaign
    differs from the one its results were made with, what changed and the new, kept and
    orphaned runs are printed first. Exit 0 if every run
    succeeded, 1 if some failed (listed), 2 on bad input or a locked campaign, 3 when
    stopped by `--max-failures`, 130 when interrupted (rerun to resume). With `--detach`,
    0 once the driver runs in the background; with `--dry-run`, 0 after printing the cost.
    """
    from ..expand import expand
    from ..outputs.aggregate import write_phase
    from ..run.clusters import WORKER_LOSSES
    from ..run.driver import drive
    from ..run.failures import FailureLimit, describe_failure
    from ..store import CampaignStore

    if catalogue is not None:  # the driver's recorder and the reuse of runs read it
        from ..catalogue.location import ENV

        os.environ[ENV] = catalogue
    err = err_console()
    setup_logging(err, verbose, quiet, cluster=True)
    coll = collection_or_none(campaign)
    if (
        coll is not None
    ):  # a collection of campaigns (nematic_solids.sweep.spec.collection): one after the other
        refuse_name(name)
        run_collection(
            coll,
            run,
            dict(
                results=results,
                set_=set_,
                seeds=seeds,
                scheduler=scheduler,
                workers=workers,
                retry_failed=retry_failed,
                max_failures=max_failures,
                prune=prune,
                check_files=check_files,
                check_files_alias=check_files_alias,
                verification=verification,
                aggregate=aggregate,
                figures=figures,
                dashboard=dashboard,
                dry_run=dry_run,
                detach=detach,
                verbose=verbose,
                quiet=quiet,
            ),
        )
        return
    c = load(err, campaign, set_, seeds, name, scheduler, workers)
    check_files = check_files or check_files_alias
    verification = verification and c.verify is not None
    try:
        limit = None if max_failures is None else FailureLimit.parse(max_failures)
    except ValueError as e:
        error(err, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    if dry_run:
        if detach or prune:
            error(
                err,
                "--dry-run runs and writes nothing: it does not take "
                + ("--detach" if detach else "--prune"),
            )
            raise typer.Exit(EXIT_BAD_INPUT)
        print_estimate(
            Console(highlight=False, soft_wrap=True),
            c,
            results,
            retry_failed=retry_failed,
            brief=quiet,
            header=f"dry run of campaign {c.name} ({results / c.name}): nothing is run or written",
        )
        if c.initial is not None:  # say now what 'run' would refuse
            from ..expand import expand as expand_campaign
            from ..run.todo import parents_not_done

            expansion = expand_campaign(c)
            done = CampaignStore(results, c.name).scan(save=False)
            todo = [i for i, r in enumerate(expansion.run_ids) if r not in done]
            waiting = parents_not_done(expansion, results, todo)
            if waiting is not None:
                Console(highlight=False, soft_wrap=True).print(
                    f"waiting: {waiting.problems[0].message}", markup=False
                )
        return
    if detach:
        from .driver import run_detached

        run_detached(c, results, campaign, quiet)
    say = Console(stderr=True, highlight=False, soft_wrap=True, quiet=quiet)
    store = CampaignStore(results, c.name)
    lock = store.lock()
    try:
        store.ensure()
        lock.acquire(command=" ".join(sys.argv))
    except (CampaignLocked, StoreError) as e:
        error(err, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    try:
        expansion = expand(c)
        progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[counts]}"),
            TimeElapsedColumn(),
            TextColumn("ETA {task.fields[eta]}"),
            console=err,
            transient=False,
            disable=quiet or not err.is_terminal,
        )
        events = ProgressEvents(say, progress, store)
        try:
            report_changes(
                say,
                c,
                store,
                expansion if c.refine is None else None,
                prune=prune,
                hint="--prune removes them",
            )
            if verification and c.verify is not None and c.verify.before:
                from .verify import verify_step

                verify_step(c, store, say, before=True)
            with sigterm_as_interrupt(), progress:
                try:
                    if c.refine is None and c.precision is None:
                        plan, summary = drive(
                            expansion,
                            store,
                            retry_failed=retry_failed,
                            check_files=check_files,
                            events=events,
                            dashboard=dashboard,
                            limit=limit,
                        )
                    else:  # adaptive or seeds by precision: rounds planned from the results
                        from ..refine.driver import drive_rounds

                        plan, summary, expansion = drive_rounds(
                            c,
                            store,
                            retry_failed=retry_failed,
                            check_files=check_files,
                            events=events,
                            dashboard=dashboard,
                            limit=limit,
                            say=lambda line: say.print(line, markup=False),
                            on_round=lambda number: print_estimate(
                                say,
                                c,
                                results,
                                brief=True,
                                started=events.startup,
                                indent="  ",
                                header=f"cost re-estimated for round {number} and later "
                                "from the runs so far:",
                            ),
                        )
                finally:
                    events.close()
        except (ClusterError, StoreError, CampaignError) as e:
            error(err, e)
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except OSError as e:  # the folder itself (cleaning up, discarding, adopting)
            error(err, storage_message(store, e))
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except KeyboardInterrupt:  # before any run was submitted
            err.print("[yellow]interrupted[/]; rerun the same command to resume")
            raise typer.Exit(EXIT_INTERRUPTED) from None
        if summary is not None and summary.storage_error is not None:
            kept = [str(rec.get("saved_to")) for _, rec in summary.unsaved if rec.get("saved_to")]
            err.print(
                f"[bold red]error: results cannot be written[/]: "
                f"{escape(summary.storage_error)}. "
                f"Stopped after {summary.completed} stored run(s) this session; the "
                f"other runs stay pending (not failed). "
                + (
                    f"{len(kept)} computed result(s) kept in "
                    f"{Path(kept[0]).parent} (moved in by the next run). "
                    if kept
                    else ""
                )
                + "Fix the storage and rerun the same command.",
                soft_wrap=True,
                highlight=False,
            )
            raise typer.Exit(EXIT_BAD_INPUT)
        if summary is not None and summary.stopped is not None:
            error(
                err,
                f"stopped: {summary.stopped}. {summary.completed} run(s) finished "
                "this session; the runs not finished stay pending and phase.nc was not "
                f"rewritten. Details: nematic status {campaign}; rerun (with a higher "
                "--max-failures, or after a fix) to go on",
            )
            raise typer.Exit(EXIT_TOO_MANY_FAILURES)
        if summary is not None and summary.interrupted:
            err.print(
                f"[yellow]interrupted[/] after {summary.completed} run(s) "
                f"({summary.ok} ok, {len(summary.failed)} failed); rerun the same "
                "command to resume"
            )
            raise typer.Exit(EXIT_INTERRUPTED)
        if summary is not None and summary.wall_time > 0:
            say.print(
                f"{summary.completed} run(s) in {fmt_time(summary.wall_time)} "
                f"(sum of run times {fmt_time(summary.run_time)})"
            )
        if aggregate:
            try:
                write_phase(expansion, store)
                say.print(f"phase diagram: {escape(str(store.phase_path))}")
                if figures:
                    repair_products(c, results, err, phase=False)
                    if verification:  # the fits pick its sample; the figures show it
                        from .verify import verify_step

                        regenerate_figures(c, results, draw_figures=False)
                        verify_step(c, store, say, before=False)
                        drawn = regenerate_figures(c, results, fits=False)
                    else:
                        drawn = regenerate_figures(c, results)
                    for figure in drawn:
                        say.print(f"figure: {escape(str(figure))}")
                    page = regenerate_report(c, results)
                    if page is not None:
                        say.print(f"report: {escape(str(page))}")
            except StoreError as e:
                error(
                    err,
                    f"{e}; the runs are stored, rerun the same command (or nematic "
                    "aggregate) once the folder can be written",
                )
                raise typer.Exit(EXIT_BAD_INPUT) from None
        failures = [] if summary is None else summary.failed
        n_failed = len(failures) + len(plan.failed)
        if summary is not None and summary.lost:
            err.print(
                f"[yellow]{len(summary.lost)} run(s) were cancelled by dask[/] (the "
                "scheduler or cluster went away); rerun the same command to do them"
            )
        if summary is not None and summary.worker_lost:
            err.print(
                f"[yellow]{len(summary.worker_lost)} run(s) lost their worker more "
                f"than {WORKER_LOSSES} times[/] (batch jobs cancelled, preempted or past "
                "their walltime, or the run kills its worker: memory?); they stay "
                "pending: rerun the same command to do them"
            )
        if summary is not None and (summary.lost or summary.worker_lost) and not n_failed:
            raise typer.Exit(EXIT_FAILED_RUNS)
        if n_failed:
            err.print(f"[red]{n_failed} run(s) failed[/]:")
            for r, rec in failures[:20]:
                err.print(
                    f"  {describe_failure(r, rec)}", soft_wrap=True, highlight=False, markup=False
                )
            if len(failures) > 20:
                err.print(f"  ... and {len(failures) - 20} more")
            if plan.failed:
                err.print(
                    f"  ... and {len(plan.failed)} earlier failure(s); --retry-failed redoes them"
                )
            err.print(f"details: nematic status {campaign}")
            raise typer.Exit(EXIT_FAILED_RUNS)
    finally:
        lock.release()
