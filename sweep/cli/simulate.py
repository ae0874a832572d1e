"""``nematic simulate``: one run of the model, with a progress bar, a summary and a picture.

Only parses and calls :func:`nematic_solids.model.simulate.run`.
Exit codes: 0 the run succeeded, 1 the run failed (the reason and time are printed), 2 bad input.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import Numerics, Parameters, check_compatible, split_settings
from nematic_solids.model.resolution import is_rule, read_rule

from ..campaign import MAX_SEED
from ..errors import CampaignError, StoreError
from ..limits import available_memory, check_run_memory
from .app import (
    EXIT_BAD_INPUT,
    EXIT_FAILED_RUNS,
    Console,
    QuietOpt,
    VerboseOpt,
    error,
    setup_logging,
)

#: the names ``--set`` accepts, from the dataclasses themselves (so the help cannot drift)
_PARAMETER_NAMES = ", ".join([f.name for f in fields(Parameters)] + ["alpha_minus_B"])
_NUMERICS_NAMES = ", ".join(f.name for f in fields(Numerics))


def output_problem(path: Path) -> str | None:
    """What stops ``path`` from being written (checked before a run, not after it)."""
    from ..files import probe_write, storage_cause

    if path.is_dir():
        return f"--out/--png {path} is a folder; give a file name"
    parent = path.resolve().parent
    if not parent.is_dir():
        return f"the folder of {path} does not exist"
    problem = probe_write(parent)
    if problem is not None:
        return f"cannot write {path}: {storage_cause(path, problem)}"
    return None


def _keep_elsewhere(ds: Any, out: Path) -> Path | None:
    """Write a result whose ``--out`` failed to the temporary folder; its path or ``None``."""
    import tempfile

    from ..files import atomic_to_netcdf

    path = Path(tempfile.gettempdir()) / f"nematic-unsaved-{out.name}"
    try:
        atomic_to_netcdf(ds, path)
    except (OSError, StoreError):
        return None
    return path


def simulate(
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="NAME=VALUE",
            help=f"A model parameter ({_PARAMETER_NAMES}) or numerics field ({_NUMERICS_NAMES}). "
            "Repeatable. resolution=auto chooses the grid from K (docs/model/resolution.md).",
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the random initial director field.")] = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", help="Write the run (time series, snapshots, attributes) to this netCDF."
        ),
    ] = None,
    png: Annotated[
        Path | None,
        typer.Option(
            "--png", help="Draw the final snapshot (Fig. 2a style) and sigma2_S(t) to this PNG."
        ),
    ] = None,
    verbose: VerboseOpt = False,
    quiet: QuietOpt = False,
) -> None:
    """Run one simulation of paper Eqs. (1)-(5) and print sigma2_S, <cos 2 theta>, lambda."""
    console = Console(highlight=False, soft_wrap=True)
    err = Console(stderr=True, highlight=False, soft_wrap=True)
    setup_logging(err, verbose, quiet)
    from ..files import atomic_to_netcdf  # numpy and yaml: not for the help
    from ..spec.yaml_input import parse_assignments

    try:
        settings = parse_assignments(set_ or [])
        pdict, ndict = split_settings(settings)
        params = Parameters.from_dict(pdict)
        rule = read_rule(ndict["resolution"]) if is_rule(ndict.get("resolution")) else None
        if rule is not None:  # resolution=auto: the grid from K (nematic_solids.model.resolution)
            ndict["resolution"] = rule.grid(params.K, params.A0)
        numerics = Numerics.from_dict(ndict)
        check_compatible(params, numerics)
        if not 0 <= seed <= MAX_SEED:
            raise ParameterError("seed", seed, f"an integer between 0 and {MAX_SEED}")
        check_run_memory(numerics, available_memory(), "this machine's available memory")
    except (ParameterError, CampaignError, TypeError) as exc:
        error(err, exc)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    for path in (out, png):
        problem = None if path is None else output_problem(path)
        if problem is not None:
            error(err, problem)
            raise typer.Exit(EXIT_BAD_INPUT)

    if rule is not None and not quiet:
        held = rule.capped(params.K, params.A0)
        note = " (held at the cap: coarser than the rule asks)" if held else ""
        grid = f"{numerics.resolution}^2 at K = {params.K:g}"
        err.print(f"resolution {rule.describe()}: {grid}{note}")
    from nematic_solids.model.simulate import run  # heavy import (py-pde) only when needed

    desc = (
        f"alpha-B={params.alpha_minus_B:g} {numerics.mechanics} {numerics.resolution}^2 seed {seed}"
    )
    try:
        with Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TextColumn("t = {task.fields[t]:>7.2f}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=err,
            disable=quiet,
            transient=False,
        ) as bar:
            task = bar.add_task(desc, total=1.0, t=0.0)

            def progress(fraction: float) -> None:
                bar.update(task, completed=fraction, t=fraction * numerics.t_final)

            ds = run(params, numerics, seed, progress=progress)
    except ParameterError as exc:  # e.g. resolution too low for the initial noise
        error(err, exc)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    if out is not None:
        try:
            atomic_to_netcdf(ds, out)
        except StoreError as exc:
            kept = _keep_elsewhere(ds, out)
            error(
                err,
                f"{exc}; "
                + (
                    f"the result is kept in {kept}"
                    if kept
                    else "it could not be kept elsewhere either"
                ),
            )
            raise typer.Exit(EXIT_BAD_INPUT) from None
    if png is not None and ds.sizes.get("snapshot_time", 0):
        from ..figures.snapshot import snapshot_figure

        try:
            snapshot_figure(ds, png)
        except StoreError as exc:
            error(err, exc)
            raise typer.Exit(EXIT_BAD_INPUT) from None
    last = (
        {k: float(ds[k].values[-1]) for k in ("sigma2_S", "cos2theta", "lambda")}
        if ds.sizes["t"]
        else {}
    )
    summary = ", ".join(f"{k} = {v:.4g}" for k, v in last.items())
    wall = float(ds["wall_time"])
    steps = int(ds.attrs.get("solver_steps", 0))
    if ds.attrs["status"] != "ok":
        t_fail = ds.attrs.get("t_failed", float("nan"))
        err.print(
            f"[red]run failed[/red] at t = {t_fail:.4g}: {ds.attrs['reason']}: "
            f"{ds.attrs['detail']} (last saved: {summary}; {wall:.1f} s)"
        )
        raise typer.Exit(EXIT_FAILED_RUNS)
    console.print(
        f"t = {float(ds['t'].values[-1]):g}: {summary}; {steps} steps, wall time {wall:.2f} s"
    )
