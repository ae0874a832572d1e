"""Starting this command again in the background (``nematic run --detach``, for a campaign
or a collection of campaigns): :func:`launch_detached`."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import NoReturn

import typer

from .app import EXIT_OK, Console, err_console, error


def launch_detached(
    log: Path,
    lock_path: Path,
    *,
    who: str,
    title: str,
    status_target: str,
    stop_target: str,
    results: Path,
    quiet: bool,
) -> NoReturn:
    """Run this command line without ``--detach`` in a session of its own, its output in
    ``log`` (:func:`nematic_solids.sweep.run.detach.start_detached`, which waits until it holds the
    lock at ``lock_path``), then say how to follow and stop it; exits with 0, or with the driver's
    own code if it ended at once. ``who`` names the driver in the message of an early end ("the
    driver"), ``title`` in the message that it runs ("driver")."""
    from ..run.detach import detached_args, log_tail, start_detached

    err = err_console()
    say = Console(highlight=False, soft_wrap=True, quiet=quiet)
    started = start_detached(detached_args(sys.argv[1:]), log, lock_path)
    if started.returncode is not None:
        text = (
            f"{who} (pid {started.pid}) ended at once with exit code "
            f"{started.returncode}; the end of {log}:"
        )
        out = err if started.returncode else say
        if started.returncode:
            error(err, text)
        else:
            say.print(text, markup=False)
        for line in log_tail(log):
            out.print(f"  {line}", markup=False)
        raise typer.Exit(started.returncode)
    state = "running" if started.holds_lock else "starting (it has not taken the lock yet)"
    say.print(
        f"{title} {state} in the background: pid {started.pid}; its output goes to "
        f"{log}\n"
        f"  follow it:  tail -f {log}\n"
        f"  progress:   nematic status {status_target}\n"
        f"  stop it:    nematic stop {stop_target}"
        + (f" --results {results}" if results != Path("results") else ""),
        markup=False,
    )
    raise typer.Exit(EXIT_OK)
