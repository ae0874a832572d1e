"""A driver in the background: ``nematic run --detach`` (:func:`run_detached`) and
``nematic stop`` (:mod:`nematic_solids.sweep.run.detach`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..campaign import Campaign
from .app import (
    EXIT_BAD_INPUT,
    EXIT_FAILED_RUNS,
    Console,
    QuietOpt,
    ResultsOpt,
    VerboseOpt,
    err_console,
    error,
    load,
    setup_logging,
)
from .background import launch_detached
from .collection import collection_or_none, stop_collection


def run_detached(c: Campaign, results: Path, campaign: Path, quiet: bool) -> None:
    """``nematic run --detach``: start the driver in the background and say how to follow
    it; exits (0, or the driver's own code if it ended at once)."""
    from ..lock import read_lock_holder
    from ..run.detach import DRIVER_LOG
    from ..store import CampaignStore

    err = err_console()
    store = CampaignStore(results, c.name)
    holder = read_lock_holder(store.lock_path)
    if holder is not None:
        error(
            err,
            f"campaign folder {store.root} is in use by another driver (pid "
            f"{holder.get('pid', '?')} on {holder.get('host', '?')}, since "
            f"{holder.get('started', '?')}); 'nematic status {campaign}' shows it, "
            f"'nematic stop {c.name}' stops it",
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    launch_detached(
        store.root / DRIVER_LOG,
        store.lock_path,
        who="the driver",
        title="driver",
        status_target=str(campaign),
        stop_target=c.name,
        results=results,
        quiet=quiet,
    )


def stop(
    campaign: Annotated[
        str,
        typer.Argument(
            metavar="CAMPAIGN",
            show_default=False,
            help="The campaign YAML file, or the campaign's name (its results folder).",
        ),
    ],
    results: ResultsOpt = Path("results"),
    timeout: Annotated[
        float,
        typer.Option(
            "--timeout", metavar="SECONDS", min=0, help="How long to wait for the driver to exit."
        ),
    ] = 300.0,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Stop the driver running a campaign (one started with `run --detach`, or any other).

    Sends it SIGTERM, which it takes as Ctrl-C: the runs in flight are cancelled and stay
    pending (a run's file and record are written whole or not at all), the cluster is
    closed and the lock released; then waits for it to exit. A driver in a SLURM job on
    another host is signalled with `scancel --batch --signal=TERM JOB`. Exit 0 once it has
    stopped, 1 if no driver was running, 2 if it cannot be signalled from here, or has not
    exited within `--timeout` seconds.
    """
    from ..errors import ClusterError
    from ..run.detach import DRIVER_LOG, log_tail, stop_driver
    from ..store import CampaignStore

    err = err_console()
    setup_logging(err, verbose, quiet)
    say = Console(highlight=False, soft_wrap=True, quiet=quiet)
    path = Path(campaign)
    coll = collection_or_none(path) if path.is_file() else None
    if coll is not None:  # a collection of campaigns: the driver of each member that has one
        stop_collection(
            coll, stop, dict(results=results, timeout=timeout, verbose=verbose, quiet=quiet)
        )
        return
    if path.is_file():
        name = load(err, path, None, None, None).name
    elif path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        error(err, f"no campaign file {path}")
        raise typer.Exit(EXIT_BAD_INPUT)
    else:
        name = campaign
    store = CampaignStore(results, name)
    if not store.root.is_dir():
        error(
            err,
            f"no results of a campaign named {name!r} in {store.results_root}; give "
            "the campaign file or its name (and --results if its folder is elsewhere)",
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    try:
        stopped = stop_driver(store.lock_path, wait=timeout)
    except ClusterError as e:
        error(err, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    holder = stopped.holder
    if holder is None:
        say.print(
            f"no driver is running campaign {name} ({store.root}): nothing to stop", markup=False
        )
        raise typer.Exit(EXIT_FAILED_RUNS)
    who = f"pid {holder.get('pid')} on {holder.get('host')}"
    if stopped.took is None:
        error(
            err,
            f"the driver of {name} ({who}) has not exited {timeout:g} s after "
            f"{stopped.how}; it may still be cancelling runs or closing its cluster: "
            f"'nematic status' shows whether it runs, 'nematic stop {name} --timeout N' "
            "waits longer",
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    say.print(
        f"stopped the driver of {name} ({who}, since {holder.get('started')}) in "
        f"{stopped.took:.1f} s ({stopped.how}); the runs not finished stay pending: "
        f"'nematic run' resumes",
        markup=False,
    )
    log = Path(str(holder.get("log") or store.root / DRIVER_LOG))
    tail = log_tail(log, 1) if holder.get("log") else []
    if tail:
        say.print(f"its last line ({log}): {tail[-1]}", markup=False)
