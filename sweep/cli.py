"""The ``nematic`` program: parses the command line, calls :mod:`sweep` and prints.

Exit codes: 0 success; 1 some runs failed (they are listed); 2 bad input (invalid campaign,
unreachable scheduler) or refused to start (the campaign is locked by another driver);
130 interrupted (Ctrl-C / SIGTERM; rerun the same command to resume).
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import json
import logging
import math
import os
import signal
import statistics
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated, Any

import click
import typer
from rich.console import Console
from rich.logging import RichHandler
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table

from .errors import CampaignError, CampaignLocked, ClusterError, StoreError
from .spec import Campaign, Overrides, load_campaign, parse_assignments, parse_value

EXIT_OK, EXIT_FAILED_RUNS, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
#: Show Python tracebacks of errors (``nematic --debug ...`` or ``NEMATIC_DEBUG=1``).
DEBUG = {"on": False}


def _guarded(command: Callable[..., Any]) -> Callable[..., Any]:
    """A command that turns errors into one line on stderr instead of a traceback: bad
    input, files that cannot be read or written and similar errors exit 2 (the file and
    cause named), anything else exits 1 as an internal error. ``--debug`` (or a command's
    ``--verbose``) lets the exception through, with its traceback."""
    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except (typer.Exit, click.exceptions.ClickException, click.exceptions.Abort,
                KeyboardInterrupt, SystemExit):
            raise
        except Exception as e:
            if DEBUG["on"] or kwargs.get("verbose"):
                raise
            code, text = _describe_error(e)
            _err_console().print(f"[bold red]error:[/] {escape(text)} (--debug shows the "
                                 "traceback)", soft_wrap=True, highlight=False, markup=True)
            raise typer.Exit(code) from None

    return wrapper


def _describe_error(e: Exception) -> tuple[int, str]:
    from model.errors import NematicError

    from .store import storage_cause

    if isinstance(e, NematicError):
        return EXIT_BAD_INPUT, str(e)
    if isinstance(e, MemoryError):
        return EXIT_BAD_INPUT, ("not enough memory (lower the resolution, or give the process "
                                "more memory)")
    if isinstance(e, OSError):
        where = str(e.filename) if e.filename else ""
        cause = storage_cause(Path(where), e) if where else (e.strerror or str(e))
        return EXIT_BAD_INPUT, f"{where + ': ' if where else ''}{cause}"
    return EXIT_FAILED_RUNS, f"internal error: {type(e).__name__}: {' '.join(str(e).split())}"


class _App(typer.Typer):
    """A Typer whose commands are :func:`_guarded`."""

    def command(self, *args: Any, **kwargs: Any  # type: ignore[override]
                ) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
        register = super().command(*args, **kwargs)

        def decorator(f: Callable[..., Any]) -> Callable[..., Any]:
            register(_guarded(f))
            return f

        return decorator


app = _App(
    name="nematic",
    help="Active nematic solids: run the model, sweep it, aggregate phase diagrams.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",
)

log = logging.getLogger("sweep.cli")

# --------------------------------------------------------------------------- shared options
CampaignArg = Annotated[Path, typer.Argument(help="The campaign YAML file.", show_default=False)]
ResultsOpt = Annotated[Path, typer.Option(
    "--results", envvar="NEMATIC_RESULTS",
    help="Folder holding `results/NAME/` for every campaign.")]
SetOpt = Annotated[list[str] | None, typer.Option(
    "--set", metavar="NAME=VALUE",
    help="Override a base parameter or numerics value (repeatable), e.g. --set resolution=64.")]
SeedsOpt = Annotated[str | None, typer.Option(
    "--seeds", help="Override the seeds: a count (5) or a list (0,1,2).")]
NameOpt = Annotated[str | None, typer.Option(
    "--name", help="Override the campaign name (and so its results folder).")]
VerboseOpt = Annotated[bool, typer.Option(
    "--verbose", "-v", help="Also log details (INFO messages, library warnings).")]
QuietOpt = Annotated[bool, typer.Option(
    "--quiet", "-q", help="Only results and errors: no progress, no warnings.")]


def error(console: Console, message: object) -> None:
    """One error line, ``error: MESSAGE``, the same for every command. The message is
    printed literally (no rich markup: ``[start, stop, num]`` stays as it is)."""
    console.print(f"[bold red]error:[/] {escape(str(message))}", highlight=False,
                  soft_wrap=True)


def _version_callback(value: bool) -> None:
    if value:
        from .provenance import code_version, git_commit

        typer.echo(f"nematic {code_version()} (git {git_commit()})")
        raise typer.Exit()


@app.callback()
def _main(version: Annotated[bool, typer.Option(
        "--version", callback=_version_callback, is_eager=True,
        help="Print the version and exit.")] = False,
          debug: Annotated[bool, typer.Option(
        "--debug", envvar="NEMATIC_DEBUG",
        help="Show the Python traceback of an error (by default one line says what went "
        "wrong).")] = False) -> None:
    """Active nematic solids: run the model, sweep it, aggregate phase diagrams."""
    DEBUG["on"] = debug


def _setup_logging(console: Console, verbose: bool, quiet: bool = False) -> None:
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
    if text is None:
        return None
    value = parse_value(text if "," not in text or "[" in text else f"[{text}]")
    return value  # validated with the rest of the campaign


def _load(console: Console, path: Path, settings: list[str] | None, seeds: str | None,
          name: str | None, scheduler: str | None = None,
          workers: int | None = None) -> Campaign:
    try:
        overrides = Overrides(settings=parse_assignments(settings or []),
                              seeds=_parse_seeds(seeds), name=name, scheduler=scheduler,
                              workers=workers)
        return load_campaign(path, overrides)
    except CampaignError as e:
        error(console, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None


def _err_console() -> Console:
    return Console(stderr=True, highlight=False, soft_wrap=True)


def _fmt_time(seconds: float | None) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "unknown"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
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


# --------------------------------------------------------------------------- validate
@app.command()
def validate(campaign: CampaignArg, results: ResultsOpt = Path("results"),
             set_: SetOpt = None, seeds: SeedsOpt = None, name: NameOpt = None,
             verbose: VerboseOpt = False, quiet: QuietOpt = False) -> None:
    """Check a campaign file without running anything.

    Exit 0 if it is valid (a summary of the grid is printed), 2 with every problem listed
    (file:line, key path, value, what is allowed) otherwise.
    """
    console = Console(highlight=False, soft_wrap=True, quiet=quiet)
    _setup_logging(_err_console(), verbose, quiet)
    c = _load(_err_console(), campaign, set_, seeds, name)
    console.print(f"[green]valid[/]: campaign [bold]{escape(c.name)}[/] ({escape(str(campaign))})")
    for d in c.dims:
        for a in d.axes:
            vals = ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in a.values[:8])
            more = ", ..." if len(a.values) > 8 else ""
            zipped = f" (zipped with {d.name})" if a.name != d.name else ""
            console.print(f"  axis {a.name}{zipped}: {len(a.values)} values "
                          f"{escape(f'[{vals}{more}]')}")
    console.print(f"  seeds: {len(c.seeds)}; grid points: {c.n_points}; runs: {c.n_runs}")
    ex = c.execution
    where = {"local": f"local dask cluster ({ex.workers or 'one per core'} worker(s))",
             "scheduler": f"dask scheduler {ex.scheduler}",
             "cluster": f"dask-jobqueue {ex.cluster.kind if ex.cluster else ''}"}[ex.mode]
    console.print(f"  execution: {where}; results: {results / c.name}")
    if c.fits or c.figures is not None:
        shown = ("every one that applies" if c.figures is None
                 else ", ".join(p.name for p in c.figures) or "none")
        console.print("  fits: " + (", ".join(p.name for p in c.fits) or "none")
                      + "; figures: " + shown)
    if c.refine is not None:  # an adaptive campaign: its first round and a bound (sweep/refine)
        from .refine.report import validation_lines

        for line in validation_lines(c):
            console.print(f"  {line}", markup=False)


# --------------------------------------------------------------------------- run
class _ProgressEvents:
    """Draws the progress bar and prints failures as they happen. Without a terminal (a
    batch job's log) it prints a progress line when a run completes (at most one every
    :data:`LOG_MIN` seconds) and at least every :data:`LOG_EVERY` seconds instead.

    The ETA is the remaining runs times the median run time of the runs completed so far,
    over the number of worker threads: a first run that compiled kernels does not skew it."""

    LOG_EVERY = 30.0
    LOG_MIN = 5.0

    def __init__(self, console: Console, progress: Progress, store: Any, *,
                 clock: Any = time.monotonic):
        self.console, self.progress, self.store = console, progress, store
        self.clock = clock
        self.task: TaskID | None = None
        self.ok = 0
        self.failed = 0
        self.total = self.skipped = 0
        self.workers = 1
        self.run_times: list[float] = []
        self.t0 = self.last_log = clock()
        self._stop = threading.Event()
        self._heartbeat: threading.Thread | None = None
        self._lock = threading.Lock()

    @property
    def terminal(self) -> bool:
        return bool(self.console.is_terminal)

    def planned(self, plan: Any, expansion: Any) -> None:
        c = expansion.campaign
        skipped = " (skipped; --retry-failed redoes them)" if plan.failed else ""
        self.console.print(
            f"campaign [bold]{escape(c.name)}[/]: {len(expansion)} runs ({c.n_points} points "
            f"x {len(c.seeds)} seeds); {len(plan.done)} done, {len(plan.failed)} failed"
            f"{skipped}, {len(plan.todo)} to run -> {escape(str(self.store.root))}",
            soft_wrap=True)
        if plan.unspooled:
            self.console.print(f"moved {plan.unspooled} result(s) that could not be written "
                               "before into the results folder")
        if plan.adopted:
            self.console.print(f"recovered {plan.adopted} unindexed run file(s)")
        if plan.redone:
            self.console.print(f"[yellow]{len(plan.redone)} run(s) will be redone[/] (their "
                               "file is missing, truncated or corrupt):", soft_wrap=True)
            for rid, why in plan.redone[:10]:
                self.console.print(f"  {rid}: {why}", soft_wrap=True, markup=False)
            if len(plan.redone) > 10:
                self.console.print(f"  ... and {len(plan.redone) - 10} more")

    def dashboard(self, link: str | None) -> None:
        if link:
            self.console.print(f"dask dashboard: {escape(link)}", soft_wrap=True)
        else:
            self.console.print("dask dashboard: none answers from here (it needs bokeh "
                               "where the scheduler runs, and its port reachable)",
                               soft_wrap=True)

    def warming(self) -> None:
        self.console.print("preparing the workers: compiled kernels (cached on disk; about a "
                           "minute once per machine, then seconds) ...", soft_wrap=True)

    def warmed(self, infos: list[dict[str, Any]], seconds: float) -> None:
        compiled = sum(int(i.get("compiled", 0)) for i in infos)
        what = (f"{compiled} kernel(s) compiled once, now cached for every worker" if compiled
                else "loaded from the cache")
        self.console.print(f"workers ready in {seconds:.0f} s ({what})", soft_wrap=True)

    def started(self, plan: Any, total: int, workers: int) -> None:
        self.ok = self.failed = 0  # per call: a refined campaign runs one call per round
        self.skipped = len(plan.done) + len(plan.failed)
        self.total = total
        self.workers = max(1, workers)
        self.t0 = self.last_log = self.clock()
        self.task = self.progress.add_task("runs", total=total, completed=self.skipped,
                                           counts=self._counts(), eta="unknown")
        if not self.terminal:
            self._heartbeat = threading.Thread(target=self._beat, daemon=True,
                                               name="nematic-progress")
            self._heartbeat.start()

    def close(self) -> None:
        self._stop.set()
        if self._heartbeat is not None:
            self._heartbeat.join(timeout=5)

    def _beat(self) -> None:
        while not self._stop.wait(1.0):
            if self.clock() - self.last_log >= self.LOG_EVERY:
                self._log_line()

    def _counts(self) -> str:
        return f"[green]{self.ok} ok[/] [red]{self.failed} failed[/]"

    @property
    def remaining(self) -> int:
        return max(0, self.total - self.skipped - self.ok - self.failed)

    def eta(self) -> float | None:
        """Remaining runs x median run time / workers (None before the first run ends)."""
        if not self.remaining:
            return 0.0
        if not self.run_times:
            return None
        return self.remaining * statistics.median(self.run_times[-200:]) / self.workers

    def progress_line(self) -> str:
        done = self.skipped + self.ok + self.failed
        running = min(self.workers, self.remaining)
        return (f"progress: {done}/{self.total} runs ({self.ok} ok, {self.failed} failed, "
                f"{running} running this session), elapsed "
                f"{_fmt_time(self.clock() - self.t0)}, ETA {_fmt_time(self.eta())}")

    def _log_line(self) -> None:
        with self._lock:
            self.last_log = self.clock()
            self.console.print(self.progress_line(), highlight=False, markup=False,
                               soft_wrap=True)

    def finished_run(self, run: Any, record: dict[str, Any]) -> None:
        from .execute import describe_failure

        if record.get("status") == "ok":
            self.ok += 1
        else:
            self.failed += 1
            self.progress.console.print(f"[red]FAILED[/] {escape(describe_failure(run, record))}",
                                        highlight=False, soft_wrap=True)
        wall = record.get("wall_time")
        if isinstance(wall, (int, float)) and math.isfinite(wall):
            self.run_times.append(float(wall))
        if self.task is not None:
            self.progress.update(self.task, advance=1, counts=self._counts(),
                                 eta=_fmt_time(self.eta()))
        if not self.terminal and (self.clock() - self.last_log >= self.LOG_MIN
                                  or not self.remaining):
            self._log_line()


@app.command()
def run(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="Use the dask scheduler at this address (tcp://HOST:PORT) instead "
        "of the campaign's execution section.")] = None,
    workers: Annotated[int | None, typer.Option(
        "--workers", help="Local worker processes (default: the campaign's, else one per "
        "core).")] = None,
    retry_failed: Annotated[bool, typer.Option(
        "--retry-failed", help="Also redo runs that failed before.")] = False,
    verify: Annotated[bool, typer.Option(
        "--verify", help="Checksum every finished run's file (by default only files whose "
        "size or mtime changed are), and redo the corrupt ones.")] = False,
    aggregate: Annotated[bool, typer.Option(
        "--aggregate/--no-aggregate", help="Write phase.nc at the end.")] = True,
    figures: Annotated[bool, typer.Option(
        "--figures/--no-figures", help="After phase.nc, write fits.nc and the figures "
        "(as 'nematic figures' does).")] = True,
    dashboard: Annotated[bool, typer.Option(
        "--dashboard/--no-dashboard", help="Serve the dask dashboard (local cluster: on "
        "127.0.0.1, a free port) and print its link.")] = True,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Run a campaign on dask, resuming where it stopped.

    Finished runs are skipped, the rest run on a local dask cluster (default), a scheduler or
    a dask-jobqueue cluster; one netCDF per run, phase.nc at the end. Exit 0 if every run
    succeeded, 1 if some failed (listed), 2 on bad input or a locked campaign, 130 when
    interrupted (rerun to resume).
    """
    from .aggregate import write_phase
    from .execute import describe_failure, drive
    from .expand import expand
    from .store import CampaignStore

    err = _err_console()
    _setup_logging(err, verbose, quiet)
    c = _load(err, campaign, set_, seeds, name, scheduler, workers)
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
            TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
            TextColumn("{task.fields[counts]}"), TimeElapsedColumn(),
            TextColumn("ETA {task.fields[eta]}"), console=err, transient=False,
            disable=quiet or not err.is_terminal)
        events = _ProgressEvents(say, progress, store)
        try:
            with _sigterm_as_interrupt(), progress:
                try:
                    if c.refine is None:
                        plan, summary = drive(expansion, store, retry_failed=retry_failed,
                                              verify=verify, events=events,
                                              dashboard=dashboard)
                    else:  # an adaptive campaign: rounds planned from the results
                        from .refine.driver import drive_rounds

                        plan, summary, expansion = drive_rounds(
                            c, store, retry_failed=retry_failed, verify=verify, events=events,
                            dashboard=dashboard,
                            say=lambda line: say.print(line, markup=False))
                finally:
                    events.close()
        except (ClusterError, StoreError) as e:
            error(err, e)
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except OSError as e:  # the folder itself (cleaning up, discarding, adopting)
            error(err, _storage_message(store, e))
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except KeyboardInterrupt:  # before any run was submitted
            err.print("[yellow]interrupted[/]; rerun the same command to resume")
            raise typer.Exit(EXIT_INTERRUPTED) from None
        if summary is not None and summary.storage_error is not None:
            kept = [str(rec.get("saved_to")) for _, rec in summary.unsaved
                    if rec.get("saved_to")]
            err.print(f"[bold red]error: results cannot be written[/]: "
                      f"{escape(summary.storage_error)}. "
                      f"Stopped after {summary.completed} stored run(s) this session; the "
                      f"other runs stay pending (not failed). "
                      + (f"{len(kept)} computed result(s) kept in "
                         f"{Path(kept[0]).parent} (moved in by the next run). " if kept
                         else "")
                      + "Fix the storage and rerun the same command.",
                      soft_wrap=True, highlight=False)
            raise typer.Exit(EXIT_BAD_INPUT)
        if summary is not None and summary.interrupted:
            err.print(f"[yellow]interrupted[/] after {summary.completed} run(s) "
                      f"({summary.ok} ok, {len(summary.failed)} failed); rerun the same "
                      "command to resume")
            raise typer.Exit(EXIT_INTERRUPTED)
        if summary is not None and summary.wall_time > 0:
            say.print(f"{summary.completed} run(s) in {_fmt_time(summary.wall_time)} "
                      f"(sum of run times {_fmt_time(summary.run_time)})")
        if aggregate:
            try:
                write_phase(expansion, store)
                say.print(f"phase diagram: {escape(str(store.phase_path))}")
                if figures:
                    repair_products(c, results, err, phase=False)
                    for figure in _regenerate_figures(c, results):
                        say.print(f"figure: {escape(str(figure))}")
            except StoreError as e:
                error(err, f"{e}; the runs are stored, rerun the same command (or nematic "
                      "aggregate) once the folder can be written")
                raise typer.Exit(EXIT_BAD_INPUT) from None
        failures = [] if summary is None else summary.failed
        n_failed = len(failures) + len(plan.failed)
        if summary is not None and summary.lost:
            err.print(f"[yellow]{len(summary.lost)} run(s) were cancelled by dask[/] (the "
                      "scheduler or cluster went away); rerun the same command to do them")
            if not n_failed:
                raise typer.Exit(EXIT_FAILED_RUNS)
        if n_failed:
            err.print(f"[red]{n_failed} run(s) failed[/]:")
            for r, rec in failures[:20]:
                err.print(f"  {describe_failure(r, rec)}", soft_wrap=True, highlight=False,
                          markup=False)
            if len(failures) > 20:
                err.print(f"  ... and {len(failures) - 20} more")
            if plan.failed:
                err.print(f"  ... and {len(plan.failed)} earlier failure(s); "
                          "--retry-failed redoes them")
            err.print(f"details: nematic status {campaign}")
            raise typer.Exit(EXIT_FAILED_RUNS)
    finally:
        lock.release()


def _storage_message(store: Any, e: OSError) -> str:
    from .store import storage_error

    return str(storage_error(Path(e.filename) if e.filename else store.root, e))


def repair_products(campaign: Campaign, results: Path, console: Console, *,
                    phase: bool = True) -> bool:
    """Before fits and figures are drawn: an unreadable ``phase.nc`` is rebuilt from the run
    records (taking the campaign's lock) and an unreadable ``fits.nc`` removed (the fits
    recompute it), each with a message. Returns whether ``fits.nc`` was removed. Raises
    :class:`CampaignLocked` if a driver holds the campaign while phase.nc must be rebuilt."""
    from .aggregate import write_phase
    from .fits import FITS
    from .refine.rounds import expansion_for
    from .store import CampaignStore, netcdf_problem

    store = CampaignStore(results, campaign.name)
    if phase and store.phase_path.exists():
        problem = netcdf_problem(store.phase_path, ("status", "run_id"))
        if problem is not None:
            console.print(f"[yellow]{store.phase_path}: {problem}[/]; rebuilding it from the "
                          "run records", soft_wrap=True, highlight=False)
            lock = store.lock()
            lock.acquire(command=" ".join(sys.argv))
            try:
                write_phase(expansion_for(campaign, store), store)
            finally:
                lock.release()
    fits_path = store.root / FITS
    if fits_path.exists():
        problem = netcdf_problem(fits_path)
        if problem is not None:
            console.print(f"[yellow]{fits_path}: {problem}[/]; removing it (the fits "
                          "recompute it)", soft_wrap=True, highlight=False)
            fits_path.unlink()
            return True
    return False


def _regenerate_figures(campaign: Campaign, results: Path) -> list[Path]:
    """Fits and figures after a run (:func:`sweep.figures.regenerate`, which logs and never
    raises for a figure it cannot draw); nothing while that module does not exist."""
    try:
        from .figures import regenerate
    except ModuleNotFoundError as e:
        if e.name != "sweep.figures":
            raise
        return []
    return list(regenerate(campaign, results))


# --------------------------------------------------------------------------- status
@app.command()
def status(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    workers: Annotated[int | None, typer.Option(
        "--workers", help="Concurrency assumed for the ETA (default: the processes seen "
        "finishing runs under the running driver, else the local worker count).")] = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Show done / failed / pending runs, failure reasons and an ETA.

    Counts are given overall and per sweep value. Only the run records are read (no netCDF),
    so it answers in seconds for 10^5 runs, also while the campaign runs.
    """
    from .refine.rounds import expansion_for
    from .status import campaign_status
    from .store import CampaignStore

    console = Console(highlight=False, soft_wrap=True)
    _setup_logging(_err_console(), verbose, quiet)
    c = _load(_err_console(), campaign, set_, seeds, name)
    store = CampaignStore(results, c.name)
    expansion = expansion_for(c, store)
    report = campaign_status(expansion, store, workers=workers)
    refinement = getattr(expansion, "refinement", None)  # an adaptive campaign's rounds
    if as_json:
        from .refine.rounds import status_dict

        typer.echo(json.dumps({**report.to_dict(), **status_dict(refinement)}, default=str))
        return
    pct = 100.0 * report.done / max(report.total, 1)
    console.print(f"campaign [bold]{report.campaign}[/] ({report.folder}): "
                  f"[green]{report.done} done[/], [red]{report.failed} failed[/], "
                  f"{report.pending} pending of {report.total} ({pct:.0f}% done)")
    if quiet:
        return
    if refinement is not None:
        from .refine.report import status_lines

        for line in status_lines(refinement):
            console.print(line, markup=False)
    if report.running:
        console.print(f"running: pid {report.running.get('pid')} on "
                      f"{report.running.get('host')} since {report.running.get('started')}")
    if report.pending:
        basis = f" ({report.eta_basis})" if report.eta_basis else ""
        console.print(f"ETA: {_fmt_time(report.eta_seconds)}{basis}")
    if report.median_run_time is not None and report.mean_run_time is not None:
        console.print(f"run time: median {report.median_run_time:.3g} s, mean "
                      f"{report.mean_run_time:.3g} s (successful runs)")
    for ax in report.per_axis:
        table = Table(title=f"by {ax.dim}", title_justify="left", show_edge=False)
        for col in (ax.dim, "done", "failed", "pending"):
            table.add_column(col, justify="right")
        for row in zip(ax.labels, ax.done, ax.failed, ax.pending, strict=True):
            table.add_row(*map(str, row))
        console.print(table)
    if report.reasons:
        console.print("[red]failures by reason[/]: "
                      + ", ".join(f"{k}: {v}" for k, v in report.reasons.items()))
        for ex in report.examples:
            coords = ", ".join(f"{k}={v}" for k, v in ex["coords"].items())
            t = ex.get("t_failed")
            at = f" at t = {t:.4g}" if isinstance(t, (int, float)) else ""
            detail = str(ex["detail"]).strip().splitlines()
            console.print(f"  {ex['run_id']} ({coords}): {ex['reason']}{at}"
                          + (f": {detail[-1]}" if detail else ""), soft_wrap=True)
        console.print(f"  (full records with tracebacks: {store.runs_dir}/<run_id>.json)")
    if report.unreadable:
        console.print(f"[yellow]{report.unreadable} run(s) pending because their file is "
                      "missing, truncated or corrupt[/] (the next 'nematic run' redoes them):")
        for ex in report.unreadable_examples:
            console.print(f"  {ex['run_id']}: {ex['problem']}", markup=False)
    if report.foreign_runs:
        console.print(f"{report.foreign_runs} run record(s) in the folder belong to other "
                      "grids (kept, not counted)")


# --------------------------------------------------------------------------- aggregate
@app.command("aggregate")
def aggregate_cmd(
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
    from .aggregate import write_phase
    from .refine.rounds import expansion_for
    from .store import CampaignStore

    err = _err_console()
    _setup_logging(err, verbose, quiet)
    c = _load(err, campaign, set_, seeds, name)
    store = CampaignStore(results, c.name)
    if not store.runs_dir.is_dir():
        error(err, f"no results for campaign {c.name} in {store.root}; run it first "
              f"(nematic run {campaign})")
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
        f"{ds.attrs['n_missing']} missing of {ds.attrs['n_runs']} runs")


# --------------------------------------------------------------------------- other commands
# Commands defined in their own modules, imported here (module -> the function registered
# as the command, or None for a module that registers itself with `@app.command()`):
#   sweep/cli_simulate.py   `nematic simulate`  (registers itself)
#   sweep/cli_stability.py  `nematic stability`
#   sweep/cli_figures.py    `nematic figures`
# A module that is missing is skipped; any other import error is raised.
PLUGIN_MODULES: dict[str, str | None] = {
    "sweep.cli_simulate": None,
    "sweep.cli_stability": "stability",
    "sweep.cli_figures": "figures",
}


def _register_plugins() -> None:
    for module_name, command in PLUGIN_MODULES.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as e:
            if e.name != module_name:
                raise
            continue
        callback = getattr(module, command, None) if command else None
        registered = {getattr(info.callback, "__wrapped__", info.callback)
                      for info in app.registered_commands}
        if callable(callback) and callback not in registered:
            app.command()(callback)


_register_plugins()


def main() -> None:  # pragma: no cover - the console script calls `app` directly
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    app()
