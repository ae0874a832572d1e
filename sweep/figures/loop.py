r"""A chain's hysteresis loop (``chain:``, nematic_solids.sweep.chains): (a) the observable at
t_final against the chain's axis on both branches, every seed and the seed means, with each branch's
fitted jump and the loop's width; (b) the time each point needed to settle (the early stop's
``t_stopped``; a point not steady by t_final is drawn there, open); (c) one seed's chains as one
history, each point's series after its predecessor's (docs/campaigns/figures.md, "Figures").

A chain over more swept axes than its own draws one row of the three panels per value of the
others (every combination, at most :data:`MAX_ROWS`); option ``select`` (``{axis: value}``,
the nearest grid value) draws fewer."""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..analysis.phase import select, sweep_dims
from ..campaign import BRANCH
from ..errors import FigureError, FitError
from ..files import series_time
from .common import LABELS, Results, check_options, fmt, fmt_sci

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

LOOP_OPTIONS = ("observable", "seed", "yscale", "compare", "select")
COLOURS = {"up": "tab:blue", "down": "tab:red"}
#: the most rows (values of the other swept axes) one loop figure draws
MAX_ROWS = 12


def chain_axis(res: Results) -> str:
    """The chain's axis: the phase diagram's sweep dimension after ``branch``."""
    dims = [d for d in res.phase["status"].dims if d not in (BRANCH, "seed")]
    return str(res.phase.attrs.get("chain_axis") or dims[0])


def loop_rows(phase: xr.Dataset, axis: str) -> list[dict[str, Any]]:
    """The values of the swept axes other than the chain's and the branch: one ``{dim: value}``
    per row of the figure (``[{}]`` when the chain's axis is the only one)."""
    others = [d for d in sweep_dims(phase) if d not in (BRANCH, axis)]
    values = [[v.item() for v in phase[d].values] for d in others]
    return [dict(zip(others, combo, strict=True)) for combo in itertools.product(*values)]


def _at(ds: xr.Dataset, row: Mapping[str, Any]) -> xr.Dataset:
    """``ds`` at the row's values of the dims it has."""
    return ds.sel({k: v for k, v in row.items() if k in ds.dims})


def loop(res: Results, options: Mapping[str, Any]) -> Figure:
    """The hysteresis loop of a chain campaign (see the module docstring)."""
    from matplotlib.figure import Figure

    check_options("loop", options, LOOP_OPTIONS)
    if BRANCH not in res.phase.dims:
        raise FigureError("loop: the campaign has no chain (a 'chain:' section)")
    axis = chain_axis(res)
    try:
        phase = select(res.phase, options.get("select"))
    except FitError as e:  # a select naming no axis
        raise FigureError(f"loop: {e}") from None
    if axis not in phase.dims:
        raise FigureError(f"loop: select fixes the chain's axis {axis}; select the others")
    rows = loop_rows(phase, axis)
    if len(rows) > MAX_ROWS:
        raise FigureError(
            f"loop: {len(rows)} combinations of the other swept axes; at most {MAX_ROWS} "
            "rows: pick some with the option select: {axis: value}"
        )
    fig = Figure(figsize=(13.5, 4.3 * len(rows)), layout="constrained")
    for r, row in enumerate(rows):
        a, b, c = (fig.add_subplot(len(rows), 3, 3 * r + i + 1) for i in range(3))
        _row((a, b, c), res, _at(phase, row), _at(res.fits, row), axis, options, row)
    fig.suptitle(f"{res.name}: hysteresis along {axis}", fontsize=10)
    return fig


def _row(
    axes: tuple[Axes, Axes, Axes],
    res: Results,
    phase: xr.Dataset,
    fits: xr.Dataset,
    axis: str,
    options: Mapping[str, Any],
    row: Mapping[str, Any],
) -> None:
    """The three panels of one row: ``phase`` and ``fits`` at one value of the other axes."""
    ax_a, ax_b, ax_c = axes
    observable = str(options.get("observable", "sigma2_S"))
    yscale = str(options.get("yscale", "log"))
    label = LABELS.get(axis, axis)
    x = phase[axis].values.astype(float)
    order = np.argsort(x)
    t_final = float(phase.attrs.get("num_t_final", math.nan))
    for branch in (str(b) for b in phase[BRANCH].values):
        ds = phase.sel({BRANCH: branch})
        colour = COLOURS.get(branch, "k")
        values = ds[observable].transpose(axis, "seed").values.astype(float)
        xs = np.broadcast_to(x[:, None], values.shape)
        ok = np.isfinite(values) & ((values > 0) if yscale == "log" else True)
        ax_a.scatter(xs[ok], values[ok], s=8, color=colour, alpha=0.35, lw=0)
        mean = ds[f"{observable}_mean"].transpose(axis).values[order]
        ax_a.plot(x[order], mean, "o-", color=colour, ms=4, lw=1.3, label=f"{branch}: seed mean")
        if "transition_location" in fits and BRANCH in fits["transition_location"].dims:
            jump = fits.sel({BRANCH: branch})
            lo, hi = float(jump["transition_lower"]), float(jump["transition_upper"])
            if math.isfinite(lo) and math.isfinite(hi):
                ax_a.axvspan(lo, hi, color=colour, alpha=0.12, lw=0)
        steady = ds["t_stopped"].transpose(axis, "seed").values.astype(float)
        settled = np.where(np.isfinite(steady), steady, t_final)
        with np.errstate(all="ignore"):
            mean_t = np.nanmean(settled, axis=1)[order]
        ax_b.plot(x[order], mean_t, "-", color=colour, lw=1.2, label=branch)
        for j in range(settled.shape[1]):
            fin = np.isfinite(steady[:, j])
            ax_b.scatter(x[fin], settled[fin, j], s=10, color=colour, alpha=0.5, lw=0)
            ax_b.scatter(
                x[~fin], settled[~fin, j], s=14, facecolors="none", edgecolors=colour, lw=0.8
            )
        _history(ax_c, res, ds, axis, branch, colour, options.get("seed"))
    width = ""
    compare = options.get("compare")
    if compare:
        width = _compare(ax_a, res, str(compare), axis, observable, fits, row)
    if not width and "transition_loop_width" in fits:
        w = float(fits["transition_loop_width"])
        lo, hi = (
            float(fits["transition_loop_width_lower"]),
            float(fits["transition_loop_width_upper"]),
        )
        if math.isfinite(w):
            width = f": loop width {fmt(w)} [{fmt(lo)}, {fmt(hi)}]"
        elif why := str(fits["transition_loop_width"].attrs.get("nan_reason", "")):
            width = f": no loop width ({why})"
    where = ", ".join(f"{LABELS.get(k, k)} = {fmt_sci(float(v))}" for k, v in row.items())
    ax_a.set_yscale(yscale)
    ax_a.set_xlabel(label)
    ax_a.set_ylabel(f"{LABELS.get(observable, observable)} at $t/\\tau$ = {t_final:g}")
    ax_a.set_title(
        f"(a) {where + ': ' if where else ''}both branches{width}", loc="left", wrap=True
    )
    ax_a.legend(loc="best")
    ax_b.set_xlabel(label)
    ax_b.set_ylabel(r"time to settle $t/\tau$ (open: not steady by $t_{\rm final}$)")
    ax_b.set_title("(b) settling time per point", loc="left")
    ax_b.legend(loc="best")
    ax_c.set_yscale("log")
    ax_c.set_xlabel(r"time along the chain $t/\tau$")
    ax_c.set_ylabel(r"$\sigma^2_S$")
    ax_c.set_title(f"(c) one seed's chains ({label} of each point at its start)", loc="left")


def _history(ax, res: Results, ds, axis: str, branch: str, colour: str, seed: Any) -> None:
    """One seed's chain as one history: each point's sigma2_S(t) after its predecessor's,
    its value written at its start."""
    seeds = [int(s) for s in ds["seed"].values]
    s = seeds[0] if seed is None else int(seed)
    if s not in seeds:
        return
    x = ds[axis].values.astype(float)
    walk = np.argsort(x) if branch == "up" else np.argsort(-x)
    offset = 0.0
    for i in walk:
        rid = str(ds["run_id"].isel({axis: int(i)}).sel(seed=s).values)
        run = res.run(rid) if rid else None
        if run is None:
            break
        t, v = series_time(run).values.astype(float), run["sigma2_S"].values.astype(float)
        # t = 0 of the seeded texture is left out: S = S0 is uniform there (round-off)
        ok = np.isfinite(v) & (v > 0) & ((t > 0) | (offset > 0))
        ax.plot(t[ok] + offset, v[ok], color=colour, lw=1.0)
        ax.axvline(offset, color="0.85", lw=0.6, zorder=0)
        ax.text(
            offset,
            0.98 if branch == "down" else 0.02,
            f" {fmt(float(x[i]))}",
            transform=ax.get_xaxis_transform(),
            fontsize=6.5,
            color=colour,
            va="top" if branch == "down" else "bottom",
            rotation=90,
        )
        offset += float(t[-1]) if t.size else 0.0


def _compare(
    ax: Axes,
    res: Results,
    name: str,
    axis: str,
    observable: str,
    fits: xr.Dataset,
    row: Mapping[str, Any],
) -> str:
    """Another campaign's seed means along the same axis (option ``compare``: a campaign in
    the same results folder, e.g. Fig. 2's runs each from a fresh texture) at the row's values
    of the other axes, with its fitted jump; the loop width from that jump down to the down
    branch's, or ""."""
    from ..analysis.fits_file import load_fits, load_phase
    from ..errors import FitError

    root = res.root.parent / name
    try:
        other = load_phase(root)
    except FitError:
        ax.text(0.02, 0.02, f"no results of {name} to compare", transform=ax.transAxes)
        return ""
    other = _at(other, row)
    if axis not in other.dims or other[f"{observable}_mean"].ndim != 1:
        ax.text(0.02, 0.02, f"{name} is not one line along {axis}", transform=ax.transAxes)
        return ""
    x = other[axis].values.astype(float)
    order = np.argsort(x)
    mean = other[f"{observable}_mean"].values[order]
    ax.plot(x[order], mean, "s--", color="k", ms=3.5, lw=1.0, label=f"{name}: fresh texture")
    jump = _at(load_fits(root), row)
    if "transition_location" not in jump or jump["transition_location"].ndim:
        return ""
    lo, hi = float(jump["transition_lower"]), float(jump["transition_upper"])
    ax.axvspan(lo, hi, color="k", alpha=0.08, lw=0)
    if "transition_location" not in fits or BRANCH not in fits["transition_location"].dims:
        return ""
    down = fits.sel({BRANCH: "down"}) if "down" in fits[BRANCH].values else None
    if down is None or not math.isfinite(float(down["transition_location"])):
        return ""
    w = float(jump["transition_location"]) - float(down["transition_location"])
    wlo = lo - float(down["transition_upper"])
    whi = hi - float(down["transition_lower"])
    return f": loop width ({name} to down) {fmt(w)} [{fmt(wlo)}, {fmt(whi)}]"
