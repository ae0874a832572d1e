"""A collection of campaigns (:mod:`nematic_solids.sweep.spec.collection`, e.g.
``campaigns/paper.yaml``) in the commands that take one: ``validate``, ``run`` (``--dry-run``,
``--detach``), ``status`` and ``stop``. Each member runs as ``nematic run MEMBER`` would, in the
collection's order, with the same options; the collection adds the cost of the whole before anything
runs, a summary at the end, and ``results/NAME/index.html`` linking every member's report and
figures."""

from __future__ import annotations

import contextlib
import html
import io
import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
from rich.markup import escape

from ..campaign import Campaign
from ..errors import CampaignError
from .app import (
    EXIT_BAD_INPUT,
    EXIT_FAILED_RUNS,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_PRODUCTS_FAILED,
    EXIT_TOO_MANY_FAILURES,
    Console,
    err_console,
    error,
    fmt_time,
    load,
)
from .background import launch_detached

if TYPE_CHECKING:  # the spec package (and the model) load only when a command needs them
    from ..spec.collection import Collection

#: exit codes from the most to the least severe: the collection exits with its worst
SEVERITY = (
    EXIT_INTERRUPTED,
    EXIT_BAD_INPUT,
    EXIT_TOO_MANY_FAILURES,
    EXIT_FAILED_RUNS,
    EXIT_PRODUCTS_FAILED,
    EXIT_OK,
)
INDEX = "index.html"


def collection_or_none(path: Path) -> Collection | None:
    """The collection at ``path`` (exit 2 listing its problems), or ``None`` for a campaign
    file."""
    from ..spec.collection import read_collection

    try:
        return read_collection(path)
    except CampaignError as e:
        error(err_console(), e)
        raise typer.Exit(EXIT_BAD_INPUT) from None


def refuse_name(name: str | None) -> None:
    if name is not None:
        error(
            err_console(),
            "--name renames one campaign; the campaigns of a collection keep their own names",
        )
        raise typer.Exit(EXIT_BAD_INPUT)


def load_members(
    coll: Collection,
    set_: list[str] | None,
    seeds: str | None,
    scheduler: str | None = None,
    workers: int | None = None,
) -> list[Campaign]:
    """Every member read and checked; exit 2 after listing the problems of every member
    (and of two members sharing a name)."""
    from ..errors import Problem
    from ..limits import MAX_COLLECTION_POINTS

    err = err_console()
    out: list[Campaign] = []
    bad = False
    points = 0
    for member in coll.members:
        try:
            out.append(load(err, member, set_, seeds, None, scheduler, workers))
        except typer.Exit:
            bad = True
            continue
        points += out[-1].n_points
        if points > MAX_COLLECTION_POINTS:  # the work of checking them is bounded too
            why = (
                f"its campaigns have more than {MAX_COLLECTION_POINTS} grid points in all "
                f"({points} up to {member.name}, each checked by the model before anything "
                "runs); allowed: at most that many: split it into several collections"
            )
            error(err, CampaignError(coll.source, [Problem("campaigns", why, coll.source)]))
            raise typer.Exit(EXIT_BAD_INPUT)
    from ..spec.collection import duplicate_names

    problems = duplicate_names([c.name for c in out], [c.source for c in out])
    if problems:
        error(err, CampaignError(coll.source, problems))
    if bad or problems:
        raise typer.Exit(EXIT_BAD_INPUT)
    return out


def worst(codes: list[int]) -> int:
    known = [c for c in codes if c in SEVERITY]
    if len(known) < len(codes):
        return next(c for c in codes if c not in SEVERITY)
    return min(known, key=SEVERITY.index, default=EXIT_OK)


def exit_code(e: BaseException) -> int:
    if isinstance(e, typer.Exit):
        return e.exit_code
    if isinstance(e, SystemExit):
        return e.code if isinstance(e.code, int) else EXIT_BAD_INPUT
    return EXIT_OK


# --------------------------------------------------------------------------- cost
def estimate_lines(
    coll: Collection, campaigns: list[Campaign], results: Path, *, retry_failed: bool = False
) -> list[str]:
    """The cost of the whole collection: one line per member (runs to do, CPU and wall time
    of its current round, the later rounds' forecast or bound) and the total, the members
    one after the other."""
    from ..cost.estimate import estimate
    from ..cost.result import fmt_hours, fmt_seconds
    from ..store import CampaignStore

    rows = []
    todo = 0
    cpu = wall_sum = 0.0
    bound = [0, 0.0, 0.0]  # the later rounds' runs, CPU and wall: at most, and expected
    expected = [0, 0.0, 0.0]
    known: list[str] = []
    unknown: list[str] = []
    for c in campaigns:
        e = estimate(c, CampaignStore(results, c.name), retry_failed=retry_failed)
        wall = e.wall[0] + e.overhead if e.to_do else 0.0
        line = f"  {c.name}: {e.total} planned, {e.done} done, {e.to_do} to do" + (
            f": {fmt_hours(e.cpu[0])}, {fmt_seconds(wall)} wall on {e.workers} worker(s)"
            if e.to_do
            else ""
        )
        later = e.later
        if later is not None:
            line += (
                f"; later rounds at most {later.runs} more runs, {fmt_hours(later.cpu)}, "
                f"{fmt_seconds(later.wall)} wall"
            )
            for k, v in enumerate((later.runs, later.cpu, later.wall)):
                bound[k] += v
            x = later.expected
            if x is not None and not x.unknown_points:
                line += (
                    f", expected {x.runs} more, {fmt_hours(x.cpu)}, {fmt_seconds(x.wall)} "
                    f"wall ({x.basis})"
                )
                for k, v in enumerate((x.runs, x.cpu, x.wall)):
                    expected[k] += v
                known.append(c.name)
            else:
                line += ", no expected value yet (no data: no finished runs, no prior)"
                unknown.append(c.name)
        rows.append(line)
        todo += e.to_do
        cpu += e.cpu[0]
        wall_sum += wall
    out = [
        f"collection {coll.name} ({coll.source}): {len(campaigns)} campaign(s), run one "
        "after the other",
        *rows,
        f"  total now: {todo} runs, {fmt_hours(cpu)}, {fmt_seconds(wall_sum)} wall",
    ]
    if known or unknown:
        out.append(
            f"  with the later rounds at most: {todo + bound[0]} runs, "
            f"{fmt_hours(cpu + bound[1])}, {fmt_seconds(wall_sum + bound[2])} wall (the "
            "bound: every run the rules allow)"
        )
    if known and not unknown:
        out.append(
            f"  with the later rounds expected: about {todo + expected[0]} runs, "
            f"{fmt_hours(cpu + expected[1])}, {fmt_seconds(wall_sum + expected[2])} wall "
            "(each campaign's basis above)"
        )
    elif known:
        out.append(
            f"  expected for {', '.join(known)} only: about {expected[0]} more runs, "
            f"{fmt_hours(expected[1])} in their later rounds; {', '.join(unknown)}: no "
            "expected value until their first round has run (or a prior: is given)"
        )
    out.append(
        "  (each campaign's own `nematic run FILE --dry-run` lists its points and the "
        "basis of its estimate)"
    )
    return out


# --------------------------------------------------------------------------- commands
def validate_collection(
    coll: Collection, validate: Callable[..., None], options: dict[str, Any], console: Console
) -> None:
    """``nematic validate COLLECTION``: every member as ``validate`` checks it, then the
    collection's cost with ``--estimate``."""
    campaigns = load_members(coll, options["set_"], options["seeds"])
    console.print(
        f"[green]valid[/]: collection [bold]{escape(coll.name)}[/] ({escape(coll.source)}): "
        f"{len(campaigns)} campaign(s)"
    )
    for member in coll.members:
        validate(member, **{**options, "estimate": False})
    if options["estimate"]:
        for line in estimate_lines(coll, campaigns, options["results"]):
            console.print(line, markup=False)


def run_collection(coll: Collection, run: Callable[..., None], options: dict[str, Any]) -> None:
    """``nematic run COLLECTION``: the cost of the whole first, then every member in order
    (as ``nematic run MEMBER`` with the same options), then a summary and the index page.
    A member that fails or is refused does not stop the others; an interrupt (Ctrl-C,
    SIGTERM, ``nematic stop``) does. Exits with the worst member's code."""
    results: Path = options["results"]
    quiet = options["quiet"]
    say = Console(highlight=False, soft_wrap=True, quiet=quiet)
    campaigns = load_members(
        coll, options["set_"], options["seeds"], options["scheduler"], options["workers"]
    )
    if options["dry_run"]:
        if options["detach"] or options["prune"]:
            error(
                err_console(),
                "--dry-run runs and writes nothing: it does not take "
                + ("--detach" if options["detach"] else "--prune"),
            )
            raise typer.Exit(EXIT_BAD_INPUT)
        say.print(f"dry run of collection {coll.name}: nothing is run or written", markup=False)
        for line in estimate_lines(coll, campaigns, results, retry_failed=options["retry_failed"]):
            say.print(line, markup=False)
        return
    if options["detach"]:
        run_detached(coll, campaigns, results, quiet)
    for line in estimate_lines(coll, campaigns, results, retry_failed=options["retry_failed"]):
        say.print(line, markup=False)
    outcome: list[tuple[Campaign, int, float]] = []
    for k, (member, c) in enumerate(zip(coll.members, campaigns, strict=True)):
        say.print(f"\n== campaign {c.name} ({k + 1} of {len(campaigns)}): {member}", markup=False)
        start = time.monotonic()
        try:
            run(member, **{**options, "name": None, "dry_run": False, "detach": False})
            code = EXIT_OK
        except (typer.Exit, SystemExit) as e:
            code = exit_code(e)
        except KeyboardInterrupt:
            code = EXIT_INTERRUPTED
        outcome.append((c, code, time.monotonic() - start))
        if code == EXIT_INTERRUPTED:
            break
    summary(say, coll, campaigns, outcome, results)
    code = worst([c for _, c, _ in outcome])
    if code != EXIT_OK:
        raise typer.Exit(code)


def summary(
    say: Console,
    coll: Collection,
    campaigns: list[Campaign],
    outcome: list[tuple[Campaign, int, float]],
    results: Path,
) -> None:
    """The end of ``run COLLECTION``: each member's outcome and products, and the index."""
    words = {
        EXIT_OK: "done",
        EXIT_FAILED_RUNS: "some runs failed or were lost",
        EXIT_BAD_INPUT: "refused or stopped (bad input, locked, storage)",
        EXIT_TOO_MANY_FAILURES: "stopped by --max-failures",
        EXIT_PRODUCTS_FAILED: "every run done, but a fit or figure failed",
        EXIT_INTERRUPTED: "interrupted",
    }
    say.print(
        f"\n== collection {coll.name}: {len(outcome)} of {len(campaigns)} campaign(s) run",
        markup=False,
    )
    for c, code, took in outcome:
        say.print(
            f"  {c.name}: {words.get(code, f'exit {code}')} in {fmt_time(took)} "
            f"({results / c.name})",
            markup=False,
        )
    for c in campaigns[len(outcome) :]:
        say.print(f"  {c.name}: not run (rerun the same command to go on)", markup=False)
    try:
        page = write_index(coll, campaigns, results)
    except OSError as e:
        error(err_console(), f"the collection's index page cannot be written: {e}")
        return
    say.print(f"index: {page}", markup=False)


def write_index(coll: Collection, campaigns: list[Campaign], results: Path) -> Path:
    """``results/NAME/index.html``: each member's description, a link to its report and its
    figures (the PNGs in its ``figures/``), relative links, written atomically."""
    from ..files import atomic_write_text

    root = results / coll.name
    root.mkdir(parents=True, exist_ok=True)
    parts = [f"<h1>{html.escape(coll.name)}</h1>"]
    if coll.description:
        parts.append(f"<p>{html.escape(coll.description)}</p>")
    for c in campaigns:
        folder = results / c.name
        rel = os.path.relpath(folder, root)
        parts.append(f"<h2>{html.escape(c.name)}</h2>")
        if c.description:
            parts.append(f"<p>{html.escape(c.description)}</p>")
        if (folder / "report.html").is_file():
            parts.append(f'<p><a href="{html.escape(rel)}/report.html">report</a></p>')
        else:
            parts.append("<p>no report yet</p>")
        for png in sorted((folder / "figures").glob("*.png")):
            src = html.escape(f"{rel}/figures/{png.name}")
            parts.append(
                f'<a href="{src}"><img src="{src}" alt="{html.escape(png.stem)}" '
                'style="max-width:48%"></a>'
            )
    page = root / INDEX
    atomic_write_text(
        page,
        '<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>'
        f"{html.escape(coll.name)}</title></head><body>\n"
        + "\n".join(parts)
        + "\n</body></html>\n",
    )
    return page


def run_detached(coll: Collection, campaigns: list[Campaign], results: Path, quiet: bool) -> None:
    """``nematic run COLLECTION --detach``: the collection's driver in the background, its
    output in ``results/NAME/driver.log``; exits."""
    from ..lock import read_lock_holder
    from ..run.detach import DRIVER_LOG
    from ..store import CampaignStore

    err = err_console()
    for c in campaigns:
        holder = read_lock_holder(CampaignStore(results, c.name).lock_path)
        if holder is not None:
            error(
                err,
                f"campaign {c.name} of the collection is in use by another driver "
                f"(pid {holder.get('pid', '?')} on {holder.get('host', '?')}); "
                f"'nematic stop {coll.source}' stops it",
            )
            raise typer.Exit(EXIT_BAD_INPUT)
    launch_detached(
        results / coll.name / DRIVER_LOG,
        CampaignStore(results, campaigns[0].name).lock_path,
        who="the collection's driver",
        title=f"collection {coll.name}",
        status_target=coll.source,
        stop_target=coll.source,
        results=results,
        quiet=quiet,
    )


def status_collection(
    coll: Collection, status: Callable[..., None], options: dict[str, Any]
) -> None:
    """``nematic status COLLECTION``: every member's status in turn; with ``--json`` one
    object ``{"collection": NAME, "campaigns": {NAME: status}}``."""
    campaigns = load_members(coll, options["set_"], options["seeds"])
    say = Console(highlight=False, soft_wrap=True)
    if not options["as_json"]:
        for member, c in zip(coll.members, campaigns, strict=True):
            say.print(f"== campaign {c.name}: {member}", markup=False)
            status(member, **{**options, "name": None})
        return
    out: dict[str, Any] = {}
    for member, c in zip(coll.members, campaigns, strict=True):
        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            status(member, **{**options, "name": None})
        out[c.name] = json.loads(buffer.getvalue())
    print(json.dumps({"collection": coll.name, "campaigns": out}, indent=1))


def stop_collection(coll: Collection, stop: Callable[..., None], options: dict[str, Any]) -> None:
    """``nematic stop COLLECTION``: stop the driver of each member that has one (the
    collection's driver holds one member's lock at a time; stopping it ends the collection);
    exit 1 if none was running."""
    from ..lock import read_lock_holder
    from ..store import CampaignStore

    campaigns = load_members(coll, None, None)
    running = [
        c
        for c in campaigns
        if read_lock_holder(CampaignStore(options["results"], c.name).lock_path)
    ]
    if not running:
        Console(highlight=False, soft_wrap=True, quiet=options["quiet"]).print(
            f"no driver is running a campaign of collection {coll.name}: nothing to stop",
            markup=False,
        )
        raise typer.Exit(EXIT_FAILED_RUNS)
    for c in running:
        stop(c.name, **options)
