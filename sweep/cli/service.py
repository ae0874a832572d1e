"""``nematic serve``, ``submit``, ``queue`` and ``cancel``: the service of a results root
(:mod:`nematic_solids.sweep.service`) and the commands that talk to it."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from .app import (
    EXIT_BAD_INPUT,
    NameOpt,
    QuietOpt,
    ResultsOpt,
    SeedsOpt,
    SetOpt,
    VerboseOpt,
    _parse_seeds,
    err_console,
    error,
    setup_logging,
)

RootArg = Annotated[
    Path,
    typer.Argument(
        envvar="NEMATIC_RESULTS",
        help="The results root the service owns (the folder holding `NAME/` for every campaign).",
    ),
]


def serve(
    root: RootArg = Path("results"),
    host: Annotated[
        str,
        typer.Option(
            "--host",
            help="The address to listen on. Any but the loopback needs the token and TLS "
            "(--certfile, --keyfile); on a cluster's login node keep 127.0.0.1 and use an SSH "
            "tunnel.",
        ),
    ] = "127.0.0.1",
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="The port (0: a free one).")
    ] = 8765,
    no_token: Annotated[
        bool,
        typer.Option(
            "--no-token",
            help="Serve without a token (127.0.0.1 only: anyone on this machine can then "
            "read, submit and cancel).",
        ),
    ] = False,
    certfile: Annotated[
        Path | None, typer.Option("--certfile", help="TLS certificate (PEM), with --keyfile.")
    ] = None,
    keyfile: Annotated[
        Path | None, typer.Option("--keyfile", help="TLS private key (PEM).")
    ] = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Run the service of a results root: a queue of campaigns run one after the other on one
    dask cluster kept warm, a JSON API and a live dashboard.

    Prints the dashboard's URL with its token. One service per results root; stop it with
    Ctrl-C or SIGTERM (the campaign in flight goes back to the queue, and resumes from its
    runs' files at the next start; so does one of a service that was killed). Exit 2 when it
    cannot start (another service holds the root, an address refused, a port in use).
    """
    from ..service.server import ServeOptions
    from ..service.server import serve as run_service

    err = err_console()
    setup_logging(err, verbose, quiet, cluster=True)
    say = Console(highlight=False, soft_wrap=True)
    options = ServeOptions(
        host=host,
        port=port,
        token=not no_token,
        certfile=certfile,
        keyfile=keyfile,
    )
    run_service(root, options, say=lambda line: say.print(line, markup=False))


def submit(
    campaign: Annotated[Path, typer.Argument(help="The campaign YAML file.", show_default=False)],
    results: ResultsOpt = Path("results"),
    priority: Annotated[
        int, typer.Option("--priority", help="Higher runs first (default 0; may be negative).")
    ] = 0,
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Queue a campaign with the service of the results root.

    The service validates it (the problems are printed, exit 2, when it is not valid) and
    runs it after the campaigns before it in the queue: a campaign it was running when it
    stopped, then the highest priority, then the earliest submission. Exit 2 when no service
    runs for the root.
    """
    from ..service.client import require_client
    from ..spec.yaml_input import parse_assignments

    setup_logging(err_console(), verbose, quiet)
    if not campaign.is_file():
        error(err_console(), f"no campaign file {campaign}")
        raise typer.Exit(EXIT_BAD_INPUT)
    client = require_client(results)
    entry = client.submit(
        campaign,
        priority=priority,
        settings=dict(parse_assignments(set_ or [])),
        seeds=_parse_seeds(seeds),
        name=name,
    )
    Console(highlight=False, soft_wrap=True, quiet=quiet).print(
        f"queued campaign {entry['name']} as {entry['id']} (priority {entry['priority']}); "
        f"watch it at {client.url}/campaigns/{entry['name']}; 'nematic cancel {entry['id']}' "
        "cancels it",
        markup=False,
    )


def queue(
    results: ResultsOpt = Path("results"),
    as_json: Annotated[bool, typer.Option("--json", help="Print the queue as JSON.")] = False,
    all_: Annotated[
        bool, typer.Option("--all", help="Also the campaigns that ended (done, failed, cancelled).")
    ] = False,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """List the campaigns of the service's queue, in the order they run (exit 2 when no
    service runs for the results root)."""
    from ..service.client import require_client

    setup_logging(err_console(), verbose, quiet)
    entries = require_client(results).queue()["entries"]
    if not all_:
        entries = [e for e in entries if e["state"] in ("queued", "running")]
    out = Console(highlight=False, soft_wrap=True)
    if as_json:
        out.print(json.dumps(entries, indent=1), markup=False)
        return
    if not entries:
        out.print("the queue is empty", markup=False)
        return
    table = Table("id", "campaign", "state", "priority", "submitted", "message")
    for e in entries:
        table.add_row(
            str(e["id"]), e["name"], e["state"], str(e["priority"]), e["submitted"], e["message"]
        )
    out.print(table)


def cancel(
    entry_id: Annotated[int, typer.Argument(metavar="ID", help="The campaign's id in the queue.")],
    results: ResultsOpt = Path("results"),
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Cancel a queued campaign, or stop a running one (its runs not finished stay pending: a
    later submission or 'nematic run' resumes them). Exit 2 for an unknown id, one that has
    ended, or when no service runs."""
    from ..service.client import require_client

    setup_logging(err_console(), verbose, quiet)
    entry = require_client(results).cancel(entry_id)
    Console(highlight=False, soft_wrap=True, quiet=quiet).print(
        f"campaign {entry['id']} ({entry['name']}): {entry['state']}"
        + (f", {entry['message']}" if entry["message"] else ""),
        markup=False,
    )


def hand_to_service(
    campaign: Path,
    results: Path,
    settings: list[str] | None,
    seeds: str | None,
    name: str | None,
    options: Mapping[str, object],
    quiet: bool,
) -> None:
    """``nematic run`` when a service runs for the results root: the campaign is queued with
    it and the command exits 0 (returns when no service runs). Options the service does not
    take (``options``: those given) refuse, naming ``--no-service``."""
    from ..service.client import ServiceClient
    from ..spec.yaml_input import parse_assignments

    client = ServiceClient.for_root(results)
    if client is None:
        return
    given = [flag for flag, value in options.items() if value]
    if given:
        error(
            err_console(),
            f"a service runs for {results} ({client.url}) and takes the campaign without "
            f"{', '.join(given)}: run it here with --no-service, or without "
            f"{'that option' if len(given) == 1 else 'those options'}",
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    entry = client.submit(
        campaign,
        settings=dict(parse_assignments(settings or [])),
        seeds=_parse_seeds(seeds),
        name=name,
    )
    Console(highlight=False, soft_wrap=True, quiet=quiet).print(
        f"a service runs for {results}: campaign {entry['name']} handed to it as {entry['id']} "
        f"(--no-service runs it here instead); watch it at "
        f"{client.url}/campaigns/{entry['name']}, 'nematic queue' lists the queue",
        markup=False,
    )
    raise typer.Exit(0)
