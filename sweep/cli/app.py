"""The ``nematic`` application (typer) and what its commands share: error handling (every
command is :func:`guarded`), the common options, logging, loading the campaign.

Exit codes: :data:`EXIT_OK`, :data:`EXIT_FAILED_RUNS`, :data:`EXIT_BAD_INPUT`,
:data:`EXIT_TOO_MANY_FAILURES`, :data:`EXIT_PRODUCTS_FAILED`, :data:`EXIT_INTERRUPTED`
(:mod:`nematic_solids.sweep.cli`).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import click
import rich.console
import typer
from rich.logging import RichHandler
from rich.markup import escape
from typer.core import TyperCommand

if TYPE_CHECKING:
    from ..campaign import Campaign


class Console(rich.console.Console):
    """rich's console, printing what it is given as typed: no emoji codes (``:x:`` in a value
    stays ``:x:``), no highlighting, long lines not broken. Markup (``[bold]``) is on: every
    value a user wrote goes through :func:`rich.markup.escape` (or ``markup=False``)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("emoji", False)
        kwargs.setdefault("highlight", False)
        kwargs.setdefault("soft_wrap", True)
        super().__init__(*args, **kwargs)


EXIT_OK, EXIT_FAILED_RUNS, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
#: ``nematic run --max-failures``: the campaign stopped early, too many runs failed
EXIT_TOO_MANY_FAILURES = 3
#: every run succeeded (``nematic run``) but a fit or a figure failed, or (``nematic figures``)
#: a fit or a figure failed; each is listed in one line
EXIT_PRODUCTS_FAILED = 4
#: Show Python tracebacks of errors (``nematic --debug ...`` or ``NEMATIC_DEBUG=1``).
DEBUG = {"on": False}


def guarded(command: Callable[..., Any]) -> Callable[..., Any]:
    """A command that turns errors into one line on stderr instead of a traceback: bad
    input, files that cannot be read or written and similar errors exit 2 (the file and
    cause named), anything else exits 1 as an internal error. ``--debug`` (or a command's
    ``--verbose``) lets the exception through, with its traceback."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except (
            typer.Exit,
            click.exceptions.ClickException,
            click.exceptions.Abort,
            KeyboardInterrupt,
            SystemExit,
        ):
            raise
        except Exception as e:
            if DEBUG["on"] or kwargs.get("verbose"):
                raise
            code, text = _describe_error(e)
            err_console().print(
                f"[bold red]error:[/] {escape(text)} (--debug shows the traceback)",
                soft_wrap=True,
                highlight=False,
                markup=True,
            )
            raise typer.Exit(code) from None

    return wrapper


def _describe_error(e: Exception) -> tuple[int, str]:
    from nematic_solids.model.errors import NematicError

    from ..files import storage_cause

    if isinstance(e, NematicError):
        return EXIT_BAD_INPUT, str(e)
    if isinstance(e, MemoryError):
        return EXIT_BAD_INPUT, (
            "not enough memory (lower the resolution, or give the process more memory)"
        )
    if isinstance(e, OSError):
        where = str(e.filename) if e.filename else ""
        cause = storage_cause(Path(where), e) if where else (e.strerror or str(e))
        return EXIT_BAD_INPUT, f"{where + ': ' if where else ''}{cause}"
    return EXIT_FAILED_RUNS, f"internal error: {type(e).__name__}: {' '.join(str(e).split())}"


class _App(typer.Typer):
    """A Typer whose commands are :func:`guarded`; called (the ``nematic`` program, ``python
    -m nematic_solids.sweep``), it marks the process as the command line's own
    (:mod:`nematic_solids.sweep.startup`)."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        from ..startup import FRESH_PROCESS

        FRESH_PROCESS["on"] = True
        return super().__call__(*args, **kwargs)

    def command(  # type: ignore[override]
        self, *args: Any, **kwargs: Any
    ) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
        register = super().command(*args, **kwargs)

        def decorator(f: Callable[..., Any]) -> Callable[..., Any]:
            register(guarded(f))
            return f

        return decorator


class RegistryHelpCommand(TyperCommand):
    """A command whose option help names what is registered: ``{figures}`` and ``{fits}`` in
    an option's help become the names of :data:`nematic_solids.sweep.figures.registry.REGISTRY`
    and :data:`nematic_solids.sweep.analysis.registry.REGISTRY`, so that the help (and the
    command reference generated from it) lists every registered name. The registries are
    imported when the options are first asked for (help, the command reference, the command
    itself), not when the program starts: they load xarray and matplotlib."""

    _named = False

    def get_params(self, ctx: Any) -> list[Any]:
        if not self._named:
            names = registry_names()
            for param in self.params:
                text = getattr(param, "help", None)
                if text:
                    for key, value in names.items():
                        text = text.replace("{" + key + "}", value)
                    param.help = text  # type: ignore[attr-defined]
            self._named = True
        return super().get_params(ctx)


def registry_names() -> dict[str, str]:
    """The registered figures and fits, each as a comma-separated list of names."""
    from ..analysis.registry import REGISTRY as FITS
    from ..figures.registry import REGISTRY as FIGURES

    return {"figures": ", ".join(FIGURES), "fits": ", ".join(FITS)}


app = _App(
    name="nematic",
    help="Active nematic solids: run the model, sweep it, aggregate phase diagrams.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


# --------------------------------------------------------------------------- shared options
CampaignArg = Annotated[Path, typer.Argument(help="The campaign YAML file.", show_default=False)]
#: a campaign given by its file or by the name of its results folder (export, report)
CampaignRefArg = Annotated[
    str,
    typer.Argument(
        metavar="CAMPAIGN",
        show_default=False,
        help="The campaign YAML file, or the campaign's name (its results folder, read with "
        "the campaign copy the last run left there).",
    ),
]
ResultsOpt = Annotated[
    Path,
    typer.Option(
        "--results",
        envvar="NEMATIC_RESULTS",
        help="Folder holding `results/NAME/` for every campaign.",
    ),
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        metavar="NAME=VALUE",
        help="Override a base parameter or numerics value (repeatable), e.g. "
        "--set mechanics=linear.",
    ),
]
SeedsOpt = Annotated[
    str | None, typer.Option("--seeds", help="Override the seeds: a count (5) or a list (0,1,2).")
]
NameOpt = Annotated[
    str | None,
    typer.Option("--name", help="Override the campaign name (and so its results folder)."),
]
#: the catalogue of runs (``nematic catalogue``, ``nematic run``): sweep/catalogue/
CatalogueOpt = Annotated[
    str | None,
    typer.Option(
        "--catalogue",
        metavar="URL",
        help="The catalogue: a database URL (postgresql+psycopg://USER@HOST/DB, "
        "sqlite:///PATH) or an SQLite file; default $NEMATIC_CATALOGUE, else "
        "ROOT/catalogue.sqlite (the results root's); off: none.",
        show_default=False,
    ),
]

VerboseOpt = Annotated[
    bool,
    typer.Option("--verbose", "-v", help="Also log details (INFO messages, library warnings)."),
]
QuietOpt = Annotated[
    bool, typer.Option("--quiet", "-q", help="Only results and errors: no progress, no warnings.")
]


def error(console: Console, message: object) -> None:
    """One error line, ``error: MESSAGE``, the same for every command. The message is
    printed literally (no rich markup: ``[start, stop, num]`` stays as it is)."""
    console.print(f"[bold red]error:[/] {escape(str(message))}", highlight=False, soft_wrap=True)


def _version_callback(value: bool) -> None:
    if value:
        from ..provenance import code_version, git_commit

        typer.echo(f"nematic {code_version()} (git {git_commit()})")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            callback=_version_callback,
            is_eager=True,
            help="Print the version and exit.",
        ),
    ] = False,
    debug: Annotated[
        bool,
        typer.Option(
            "--debug",
            envvar="NEMATIC_DEBUG",
            help="Show the Python traceback of an error (by default one line says what went "
            "wrong).",
        ),
    ] = False,
) -> None:
    """Active nematic solids: run the model, sweep it, aggregate phase diagrams."""
    DEBUG["on"] = debug


def setup_logging(
    console: Console, verbose: bool, quiet: bool = False, cluster: bool = False
) -> None:
    """Log to ``console`` (INFO with ``verbose``, ERROR with ``quiet``, else WARNING), with
    the chatty libraries' loggers at ERROR. ``cluster``: the command starts a dask cluster;
    distributed configures its loggers when it is imported, so it is imported first (the
    other commands do not import it: a third of a second saved)."""
    if cluster:
        import distributed  # noqa: F401 - configures its loggers on import: quieten them after

    level = logging.INFO if verbose else logging.ERROR if quiet else logging.WARNING
    handler = RichHandler(console=console, show_path=False, show_time=verbose)
    handler.setLevel(level)
    root = logging.getLogger()
    for h in list(root.handlers):
        if isinstance(h, RichHandler):
            root.removeHandler(h)
    root.addHandler(handler)
    root.setLevel(level)
    for noisy in ("distributed", "tornado", "asyncio", "bokeh"):
        logging.getLogger(noisy).setLevel(logging.ERROR)


def _parse_seeds(text: str | None) -> int | list[int] | None:
    from ..spec.yaml_input import parse_value

    if text is None:
        return None
    value = parse_value(text if "," not in text or "[" in text else f"[{text}]")
    return value  # validated with the rest of the campaign


def load(
    console: Console,
    path: Path,
    settings: list[str] | None,
    seeds: str | None,
    name: str | None,
    scheduler: str | None = None,
    workers: int | None = None,
) -> Campaign:
    from ..errors import CampaignError
    from ..spec import Overrides, load_campaign
    from ..spec.yaml_input import parse_assignments

    try:
        overrides = Overrides(
            settings=parse_assignments(settings or []),
            seeds=_parse_seeds(seeds),
            name=name,
            scheduler=scheduler,
            workers=workers,
        )
        return load_campaign(path, overrides)
    except CampaignError as e:
        if _is_collection(path):
            error(
                console,
                f"{path} is a collection of campaigns (its campaigns: list): this "
                "command takes one of its campaign files; validate, run, status and stop "
                "take the collection",
            )
        else:
            error(console, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None


def _is_collection(path: Path) -> bool:
    """Whether the file that is not a valid campaign is a collection of campaigns (asked
    only then: a campaign file is read once)."""
    from ..errors import CampaignError
    from ..spec.collection import read_collection

    try:
        return read_collection(path) is not None
    except CampaignError:
        return False  # its problems are the campaign reader's to report


def err_console() -> Console:
    return Console(stderr=True, highlight=False, soft_wrap=True)


def fmt_time(seconds: float | None) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "unknown"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM (a batch system ending the driver's job) stops as cleanly as Ctrl-C."""

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
