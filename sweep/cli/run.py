"""``nematic run``: a campaign (or a collection of campaigns) run or resumed on dask, then its
phase.nc, fits, figures, verification and report; ``--dry-run`` and ``--detach``."""

from __future__ import annotations

import contextlib
import gc
import os
import shutil
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
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
    EXIT_PRODUCTS_FAILED,
    EXIT_TOO_MANY_FAILURES,
    CampaignArg,
    CatalogueOpt,
    Console,
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
from .products import failure_lines, regenerate_figures, regenerate_report, repair_products
from .progress import ProgressEvents

if TYPE_CHECKING:
    from ..store import CampaignStore


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
            help="Use the dask scheduler at tcp://HOST:PORT instead of the execution section.",
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
            help="Also redo the runs that failed before.",
        ),
    ] = False,
    max_failures: Annotated[
        str | None,
        typer.Option(
            "--max-failures",
            metavar="N",
            help="Stop (exit 3) once more than N runs failed: a count (0: the first failure) "
            "or a fraction of the runs to do (0.1).",
        ),
    ] = None,
    prune: Annotated[
        bool,
        typer.Option(
            "--prune",
            help="First remove the runs in the folder that this campaign no longer plans.",
        ),
    ] = False,
    check_files: Annotated[
        bool,
        typer.Option(
            "--check-files",
            help="Checksum every finished run's file (not only changed ones); redo corrupt ones.",
        ),
    ] = False,
    check_files_alias: Annotated[
        bool, typer.Option("--verify", hidden=True, help="The former name of --check-files.")
    ] = False,
    verification: Annotated[
        bool,
        typer.Option(
            "--verification/--no-verification",
            help="Run the campaign's verify: section, as 'nematic verify' does.",
        ),
    ] = True,
    aggregate: Annotated[
        bool, typer.Option("--aggregate/--no-aggregate", help="Write phase.nc at the end.")
    ] = True,
    figures: Annotated[
        bool,
        typer.Option(
            "--figures/--no-figures",
            help="Then write fits.nc, the figures and report.html.",
        ),
    ] = True,
    dashboard: Annotated[
        bool,
        typer.Option(
            "--dashboard/--no-dashboard",
            help="Serve the dask dashboard and print its link.",
        ),
    ] = True,
    dry_run: Annotated[
        bool,
        typer.Option(
            "--dry-run",
            help="Run and write nothing: print the runs to do and their estimated cost.",
        ),
    ] = False,
    detach: Annotated[
        bool,
        typer.Option(
            "--detach",
            help="Run the driver in the background (log: results/NAME/driver.log); nematic "
            "stop NAME ends it.",
        ),
    ] = False,
    no_service: Annotated[
        bool,
        typer.Option(
            "--no-service",
            help="Run here, not in the results root's service (nematic serve).",
        ),
    ] = False,
    catalogue: CatalogueOpt = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Run a campaign on dask, resuming where it stopped.

    With a service (`nematic serve`) for the results root, the campaign is handed to it
    (exit 0 once queued) unless --no-service.

    Finished runs are skipped. Exit 0: every run succeeded (--detach: the driver runs;
    --dry-run: the cost printed), 1: some failed, 2: bad input or locked, 3: stopped by
    --max-failures, 4: a fit or figure failed, 130: interrupted (docs/campaigns/execution.md).
    """
    from ..expand import expand
    from ..models.interface import Compiled
    from ..models.registry import get_model
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
                no_service=no_service,
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
    if not no_service:
        from .service import hand_to_service

        options = {
            "--scheduler": scheduler,
            "--workers": workers,
            "--retry-failed": retry_failed,
            "--max-failures": max_failures,
            "--prune": prune,
            "--detach": detach,
            "--check-files": check_files,
            "--no-verification": not verification and c.verify is not None,
            "--no-aggregate": not aggregate,
            "--no-figures": not figures,
        }
        hand_to_service(campaign, results, set_, seeds, name, options, quiet)
    if detach:
        from .driver import run_detached

        run_detached(c, results, campaign, quiet)
    say = Console(stderr=True, highlight=False, soft_wrap=True, quiet=quiet)
    store = CampaignStore(results, c.name)
    lock = store.lock()
    fresh = not store.root.exists()  # made by this command: removed again if it is refused
    try:
        store.ensure()
        lock.acquire(command=" ".join(sys.argv))
    except (CampaignLocked, StoreError) as e:
        error(err, e)
        if fresh:  # the folders ensure() made, if still empty (another driver's are not)
            for folder in (store.runs_dir, store.root):
                with contextlib.suppress(OSError):
                    folder.rmdir()
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
        events = ProgressEvents(
            say, progress, store, compiled=isinstance(get_model(c.model), Compiled)
        )
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
            refused = True
        except OSError as e:  # the folder itself (cleaning up, discarding, adopting)
            error(err, storage_message(store, e))
            refused = True
        except KeyboardInterrupt:  # before any run was submitted
            err.print("[yellow]interrupted[/]; rerun the same command to resume")
            raise typer.Exit(EXIT_INTERRUPTED) from None
        else:
            refused = False
        if refused:
            # outside the handler: the failure's traceback no longer holds the cluster's
            # objects (a batch job's credential files, removed when it is collected)
            if fresh:
                discard_unused(store)
            raise typer.Exit(EXIT_BAD_INPUT)
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
        product_failures: list[str] = []
        if aggregate:
            try:
                write_phase(expansion, store)
                say.print(f"phase diagram: {escape(str(store.phase_path))}")
                if figures:
                    repair_products(c, results, err, phase=False)
                    if verification:  # the fits pick its sample; the figures show it
                        from .verify import verify_step

                        fitted = regenerate_figures(c, results, draw_figures=False)
                        verify_step(c, store, say, before=False)
                        drawn = regenerate_figures(c, results, fits=False)
                        drawn.failures = {**fitted.failures, **drawn.failures}
                    else:
                        drawn = regenerate_figures(c, results)
                    for figure in drawn.paths:
                        say.print(f"figure: {escape(str(figure))}")
                    product_failures = failure_lines(drawn.failures)
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
        for line in product_failures:
            err.print(f"[red]failed[/]: {escape(line)}", soft_wrap=True, highlight=False)
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
            err.print(f"details: nematic status {campaign}", markup=False)
            raise typer.Exit(EXIT_FAILED_RUNS)
        if product_failures:
            err.print(
                f"every run succeeded, but {len(product_failures)} fit(s) or figure(s) failed "
                f"(above); nematic figures {campaign} redraws them"
            )
            raise typer.Exit(EXIT_PRODUCTS_FAILED)
    finally:
        lock.release()


def discard_unused(store: CampaignStore) -> None:
    """Remove the campaign folder that this command made for a campaign it then refused
    (e.g. its parent's runs are not done, or its cluster did not start): its lock file and
    campaign copy, never a run's file (the folder is kept if ``runs/`` holds anything)."""
    gc.collect()  # objects of a cluster that did not start remove their files in it first
    with contextlib.suppress(OSError):
        if store.runs_dir.is_dir() and any(store.runs_dir.iterdir()):
            return
        shutil.rmtree(store.root)
