"""What the figures share: the results folder read once (:class:`Results`), picking grid
points and runs, number formats, labels and style, a run's snapshot in a panel, and the
check of a figure's options."""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..analysis.fits_file import FITS, load_fits, load_phase
from ..analysis.phase import is_swept, select, sweep_dims, with_dim
from ..campaign import AMB, same_value
from ..errors import FigureError, FitError
from ..names import NAMES

if TYPE_CHECKING:
    from matplotlib.axes import Axes

log = logging.getLogger(__name__)

FIGURES = "figures"
FORMATS = ("png", "pdf")
PNG_DPI = 160
#: mathtext labels of the quantities (sweep/names.py: the one table the report uses too)
LABELS = {name: n.tex for name, n in NAMES.items()}
STYLE = {
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.labelsize": 10,
    "legend.fontsize": 8,
    "xtick.labelsize": 8.5,
    "ytick.labelsize": 8.5,
    "legend.framealpha": 0.85,
    "axes.grid": False,
}


# --------------------------------------------------------------------------- reading results
class Results:
    """The results folder of one campaign, read-only: phase.nc, fits.nc and the run files."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        try:
            self.phase = load_phase(self.root)
        except FitError as e:
            raise FigureError(str(e)) from None
        self.fits = load_fits(self.root)
        self._runs: dict[str, xr.Dataset | None] = {}

    @property
    def name(self) -> str:
        return str(self.phase.attrs.get("campaign", self.root.name))

    def run(self, run_id: str) -> xr.Dataset | None:
        """``runs/<run_id>.nc`` loaded into memory (cached), or ``None`` if it is missing."""
        if run_id not in self._runs:
            path = self.root / "runs" / f"{run_id}.nc"
            try:
                with xr.open_dataset(path) as ds:
                    self._runs[run_id] = ds.load()
            except (OSError, ValueError) as e:
                log.warning("cannot read run file %s: %s", path, e)
                self._runs[run_id] = None
        return self._runs[run_id]

    @functools.cached_property
    def verified(self) -> list[tuple[dict[str, Any], int]]:
        """The points verify.nc sampled: (swept values, verdict over every variant: 1
        converged, 0 changed, -2 runs missing); empty without a readable verify.nc."""
        from ..verify.summary import read_verify

        try:
            v = read_verify(self.root)
        except (OSError, ValueError) as e:
            log.warning("cannot read the verification in %s: %s", self.root, e)
            return []
        if v is None:
            return []
        conv = v["converged"].values
        axes = [
            str(c)
            for c in v.coords
            if v[c].dims == ("point",) and c not in ("point", "label", "why")
        ]
        out = []
        for p, row in enumerate(conv):
            verdict = 0 if (row == 0).any() else -2 if (row == -2).any() else 1
            out.append(({a: v[a].values[p].item() for a in axes}, verdict))
        return out

    def fit(self, *names: str) -> xr.Dataset:
        """The fits Dataset, checked to hold every variable in ``names``."""
        missing = [n for n in names if n not in self.fits]
        if missing:
            raise FigureError(
                f"{self.root / FITS} has no {', '.join(missing)}: "
                "run `nematic figures` (it writes the fits first)"
            )
        return self.fits


#: How a verification verdict is drawn: a square frame around the point
#: (docs/campaigns/verification.md).
VERDICT_STYLE = {
    1: ("tab:green", "verified: converged"),
    0: ("tab:orange", "verified: changed by a variant"),
    -2: ("0.5", "verified: runs missing"),
}


def mark_verdicts(
    ax: Axes, marks: Sequence[tuple[Sequence[float], int]], size: float = 150.0
) -> list[Any]:
    """Frame the verified points at their plot positions (2 or 3 coordinates) with a square
    coloured by verdict, with one legend entry per verdict shown; returns their artists."""
    drawn = []
    for verdict, (colour, label) in VERDICT_STYLE.items():
        pts = [xy for xy, v in marks if v == verdict]
        if not pts:
            continue
        cols = list(zip(*pts, strict=True))
        plot: Any = ax  # a 2-D or a 3-D Axes
        drawn.append(
            plot.scatter(
                *cols,
                s=size,
                marker="s",
                facecolors="none",
                edgecolors=colour,
                linewidths=1.6,
                label=label,
                zorder=5,
            )
        )
    return drawn


def on_slice(coords: Mapping[str, Any], ds: xr.Dataset, names: Sequence[str]) -> bool:
    """Whether ``coords`` (a verified point's swept values) lie on ``ds``'s slice, whose
    ``names`` are fixed (scalar coordinates)."""
    for name in names:
        if name not in coords or name not in ds.coords or ds[name].size != 1:
            continue
        if not same_value(coords[name], ds[name].values.item()):
            return False
    return True


def nearest_point(ds: xr.Dataset, where: Mapping[str, Any]) -> xr.Dataset:
    """``ds`` at the nearest grid values of ``where`` (names absent from ``ds`` are ignored)."""
    for name, value in where.items():
        if name in ds.coords and ds[name].ndim == 1:
            ds = with_dim(ds, name).sel({name: value}, method="nearest")
    return ds


def ok_run(
    res: Results, point: xr.Dataset, seed: int | None = None
) -> tuple[xr.Dataset | None, int | None]:
    """The run file of ``point`` (a phase.nc slice over seeds) for ``seed`` or the first seed
    that succeeded (and has snapshots)."""
    seeds = point["seed"].values
    order = list(range(seeds.size))
    if seed is not None:
        order = [i for i in order if int(seeds[i]) == int(seed)] + order
    for i in order:
        if int(point["status"].values[i]) != 1:
            continue
        run = res.run(str(point["run_id"].values[i]))
        if run is not None:
            return run, int(seeds[i])
    return None, None


def activity_line(
    res: Results, figure: str, options: Mapping[str, Any]
) -> tuple[xr.Dataset, list[str], np.ndarray]:
    """phase.nc along alpha - B with every other sweep dim fixed (option ``select``, default
    their first values), the names of those other dims and the alpha - B values."""
    if not is_swept(res.phase, AMB):
        raise FigureError(f"{figure} needs alpha_minus_B (or alpha) as a sweep axis")
    ds = with_dim(res.phase, AMB)
    others = [d for d in sweep_dims(ds) if d != AMB]
    ds = default_select(ds, [AMB], options.get("select"))
    return ds, others, ds[AMB].values.astype(float)


def runs_along(
    res: Results, ds: xr.Dataset, curves: int, seed: int | None
) -> Iterator[tuple[float, int, xr.Dataset, int]]:
    """One run per drawn alpha - B of the line ``ds``: at most ``curves`` values spread over
    the line, each ``(position in [0, 1], index, run, seed)``; the run of ``seed``, or of the
    first seed that succeeded at the first drawn point (the same seed is tried everywhere)."""
    n = ds.sizes[AMB]
    picks = np.unique(np.round(np.linspace(0, n - 1, min(curves, n))).astype(int))
    drawn = seed
    for rank, i in enumerate(picks):
        run, s = ok_run(res, ds.isel({AMB: int(i)}), drawn)
        if run is None or s is None:
            continue
        drawn = s if drawn is None else drawn
        yield rank / max(len(picks) - 1, 1), int(i), run, s


def fmt(value: float) -> str:
    if not math.isfinite(value):
        return "nan"
    return f"{value:.3g}"


def fmt_sci(value: float) -> str:
    """``1e-06`` -> ``10^{-6}`` (mathtext), other numbers with 3 significant digits."""
    if value != 0 and math.isfinite(value):
        e = math.log10(abs(value))
        if abs(e - round(e)) < 1e-9 and abs(e) >= 3:
            return rf"$10^{{{int(round(e))}}}$"
        if abs(e) >= 3:
            m, ex = f"{value:.2e}".split("e")
            return rf"${float(m):g}\times10^{{{int(ex)}}}$"
    return f"{value:.3g}"


def describe(ds: xr.Dataset, names: Sequence[str]) -> str:
    parts = []
    for n in names:
        if n in ds.coords and ds[n].ndim == 0:
            parts.append(f"{LABELS.get(n, n)} = {fmt_sci(float(ds[n]))}")
    return ", ".join(parts)


def default_select(
    ds: xr.Dataset, keep: Sequence[str], choice: Mapping[str, Any] | None
) -> xr.Dataset:
    """``ds`` with every sweep dim except ``keep`` fixed: ``choice`` or its first value."""
    ds = select(ds, choice)
    for d in sweep_dims(ds):
        if d not in keep:
            ds = ds.isel({d: 0})
    return ds


def safe_snapshot(
    ax: Axes, run: xr.Dataset, index: int = -1, *, colorbar: bool = True, arrows: int = 24
) -> None:
    """:func:`nematic_solids.sweep.figures.snapshot.draw_snapshot` (without its title), tolerating a
    run without I1bar stored (then a plain background), with compact colour bars: S (quivers) on the
    right, I1bar (background) below."""
    from matplotlib.ticker import MaxNLocator

    from .snapshot import background_colorbar, draw_snapshot

    if run.sizes.get("snapshot_time", 0) == 0 or "q1" not in run or "q2" not in run:
        ax.text(0.5, 0.5, "no snapshot stored", ha="center", va="center", transform=ax.transAxes)
        ax.set_xticks([])
        ax.set_yticks([])
        return
    has_i1 = "I1bar" in run
    if not has_i1:
        run = run.assign(I1bar=xr.zeros_like(run["q1"]) + 2.0)
    quiver = draw_snapshot(ax, run, index, colorbar=False, arrows=arrows)
    ax.set_title("")
    if not colorbar:
        return
    fig = ax.figure
    cb = fig.colorbar(quiver, cax=ax.inset_axes((1.03, 0.1, 0.045, 0.8)))
    cb.set_label("S (quivers)")
    cb.locator = MaxNLocator(5)
    cb.update_ticks()
    if has_i1 and ax.images:
        background_colorbar(
            fig, ax.images[0], cax=ax.inset_axes((0.1, -0.09, 0.8, 0.04)), orientation="horizontal"
        )


def invalid_options(name: str, options: Mapping[str, Any], allowed: Sequence[str]) -> list[str]:
    """What is wrong with the ``options`` of figure ``name``, whose options are ``allowed``:
    one message per problem, empty if none."""
    out = [
        f"unknown option {key!r}; allowed: {', '.join(allowed) or 'none'}"
        for key in options
        if key not in allowed
    ]
    if "yscale" in allowed and options.get("yscale", "linear") not in ("linear", "log"):
        out.append(f"yscale = {options['yscale']!r}; expected 'linear' or 'log'")
    for key in ("select", "snapshot"):
        if options.get(key) is not None and not isinstance(options[key], Mapping):
            out.append(f"{key} = {options[key]!r}; expected a mapping {{sweep axis: value}}")
    snaps = options.get("snapshots")
    if snaps is not None and (
        not isinstance(snaps, Sequence)
        or isinstance(snaps, str)
        or not all(isinstance(t, Mapping) for t in snaps)
    ):
        out.append(f"snapshots = {snaps!r}; expected a list of mappings {{sweep axis: value}}")
    return out


def check_options(name: str, options: Mapping[str, Any], allowed: Sequence[str]) -> None:
    """Raise :class:`FigureError` naming every problem of :func:`invalid_options`."""
    problems = invalid_options(name, options, allowed)
    if problems:
        raise FigureError(f"figure {name!r}: " + "; ".join(problems))
