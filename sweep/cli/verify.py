"""``nematic verify``: the campaign's convergence and sensitivity checks (its ``verify:``
section, :mod:`nematic_solids.sweep.verify`), and the lines ``run`` and ``status`` print about
them."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from ..errors import CampaignLocked, ClusterError, StoreError
from .app import (
    EXIT_BAD_INPUT,
    EXIT_FAILED_RUNS,
    EXIT_INTERRUPTED,
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
    sigterm_as_interrupt,
)


def verify(
    campaign: CampaignArg,
    results: ResultsOpt = Path("results"),
    before: Annotated[
        bool,
        typer.Option(
            "--before",
            help="Verify before the full grid is run: the sample is the grid's "
            "corners and the points the section lists (no fits yet), run on the campaign's own "
            "numerics and each variant; a cheap pilot for choosing resolution and tolerance. "
            "The base runs are the campaign's own and count for the grid.",
        ),
    ] = False,
    set_: SetOpt = None,
    seeds: SeedsOpt = None,
    name: NameOpt = None,
    workers: Annotated[
        int | None,
        typer.Option(
            "--workers", help="Local worker processes (default: the campaign's, else one per core)."
        ),
    ] = None,
    dashboard: Annotated[
        bool,
        typer.Option(
            "--dashboard/--no-dashboard", help="Serve the dask dashboard and print its link."
        ),
    ] = False,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Run the campaign's convergence and sensitivity checks (its verify: section).

    Reruns a sample of the campaign's points (by default both sides of each fitted
    transition and the grid's corners, 2 seeds) with each variant (e.g. resolution x2,
    tolerance /10), writes results/NAME/verify.nc (per point, observable and variant: the
    base value, the variant's, the relative change and a verdict) and prints one line per
    point and a summary. Resumable; the variants' runs are stored in results/NAME/verify/.
    Exit 0 when the checks ran (whatever they found), 1 if runs failed, 2 on bad input or a
    locked campaign, 130 when interrupted.
    """
    from ..store import CampaignStore
    from ..verify.driver import run_verification

    err = err_console()
    setup_logging(err, verbose, quiet)
    c = load(err, campaign, set_, seeds, name, None, workers)
    if c.verify is None:
        error(
            err,
            f"{campaign}: the campaign has no verify: section; add one (docs/"
            "campaigns/verification.md), e.g.\n  verify:\n    variants:\n"
            "      - resolution: x2\n      - tolerance: /10",
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    say = Console(stderr=True, highlight=False, soft_wrap=True, quiet=quiet)
    store = CampaignStore(results, c.name)
    if not before and not store.runs_dir.is_dir():
        error(
            err,
            f"no results for campaign {c.name} in {store.root}: run it first, or "
            "verify before the grid with --before",
        )
        raise typer.Exit(EXIT_BAD_INPUT)
    lock = store.lock()
    try:
        store.ensure()
        lock.acquire(command=" ".join(sys.argv))
    except (CampaignLocked, StoreError) as e:
        error(err, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    try:
        with sigterm_as_interrupt():
            outcome = run_verification(
                c,
                store,
                before=before,
                dashboard=dashboard,
                say=lambda line: say.print(line, markup=False),
            )
    except (ClusterError, StoreError) as e:
        error(err, e)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    except KeyboardInterrupt:
        err.print("[yellow]interrupted[/]; rerun the same command to resume")
        raise typer.Exit(EXIT_INTERRUPTED) from None
    finally:
        lock.release()
    if outcome.interrupted:
        err.print(
            "[yellow]interrupted[/]; rerun the same command to resume (finished runs are kept)"
        )
        raise typer.Exit(EXIT_INTERRUPTED)
    out = Console(highlight=False, soft_wrap=True, quiet=quiet)
    for line in dataset_lines(outcome.dataset, outcome.path):
        out.print(line, markup=False)
    if outcome.failed:
        err.print(
            f"[red]{len(outcome.failed)} verification run(s) failed[/]; they count as "
            f"missing in {escape(str(outcome.path))}"
        )
        raise typer.Exit(EXIT_FAILED_RUNS)


def validation_line(v: Any) -> str:
    """What ``nematic validate`` says about a ``verify:`` section."""
    where = (
        "both sides of each fitted transition"
        if v.points is None
        else f"{len(v.points)} selection(s)"
    ) + (" and the corners" if v.corners else "")
    return (
        f"verify: {len(v.variants)} variant(s) ("
        + "; ".join(x.name for x in v.variants)
        + f") at {where}, {v.seeds} seed(s) each"
        + (", before the grid" if v.before else "")
    )


def verify_step(campaign: Any, store: Any, say: Console, *, before: bool) -> bool:
    """``nematic run``'s verification (the caller holds the lock): print its plan and
    summary; ``True`` when verify.nc was written. A cluster or storage problem is printed
    (the campaign's runs are kept) and an interruption exits 130; a failed run leaves the
    verdict missing there."""
    from ..verify.driver import run_verification

    err = err_console()
    try:
        with sigterm_as_interrupt():
            outcome = run_verification(
                campaign, store, before=before, say=lambda line: say.print(line, markup=False)
            )
    except (ClusterError, StoreError) as e:
        error(err, f"verification not done: {e}; rerun, or run 'nematic verify'")
        return False
    except KeyboardInterrupt:
        outcome = None
    if outcome is None or outcome.interrupted:
        err.print(
            "[yellow]interrupted[/] during the verification; rerun the same command to "
            "resume (finished runs are kept)"
        )
        raise typer.Exit(EXIT_INTERRUPTED)
    if outcome.path is not None:
        say.print(f"verification ({outcome.path}): {outcome.summary}", markup=False)
    return outcome.path is not None


def verification_lines(root: Path, *, detail: bool = False) -> list[str]:
    """The verification's summary line (and with ``detail`` one line per point) from
    ``root/verify.nc``; nothing when there is none, one line when it cannot be read. The
    summary alone is its ``summary`` attribute, read without xarray (``status`` stays light)."""
    from ..verify import REQUIRED, VERIFY, stale

    path = root / VERIFY
    if not path.exists():
        return []
    if not detail:
        import netCDF4

        try:
            with netCDF4.Dataset(path) as nc:
                summary = str(nc.getncattr("summary"))
                missing = [n for n in REQUIRED if n not in nc.variables]
        except (OSError, AttributeError) as e:
            return [f"verification: {path} cannot be read: {e}"]
        if missing:
            return [f"verification: {path} cannot be read: {stale(missing)}"]
        return [f"verification ({path}): {summary}"]
    from ..verify.summary import read_verify

    try:
        ds = read_verify(root)
    except (OSError, ValueError) as e:
        return [f"verification: {path} cannot be read: {e}"]
    return [] if ds is None else dataset_lines(ds, path)


def dataset_lines(ds: Any, path: Path | None) -> list[str]:
    """The summary line of a verification's Dataset, one line per point and variant, and the
    variants that could not run."""
    from ..verify.summary import summary_line

    lines = [f"verification ({path}): {summary_line(ds)}", *point_lines(ds)]
    if ds.attrs.get("problems"):
        lines.append(f"  not run: {ds.attrs['problems']}")
    return lines


def point_lines(ds: Any) -> list[str]:
    """One line per sampled point and variant (the verdict and the changes), then one per
    fitted transition and variant."""
    from ..verify.summary import transition_rows, verdict_rows

    out = [
        f"  {r['point']} [{r['why']}] {r['variant']}: {r['verdict']}"
        + (f": {r['changes']}" if r["changes"] else "")
        for r in verdict_rows(ds)
    ]
    out += [f"  {r['transition']} with {r['variant']}: {r['where']}" for r in transition_rows(ds)]
    return out
