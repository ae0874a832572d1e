r"""A chain's hysteresis loop (``chain:``, nematic_solids.sweep.chains): (a) the observable at
t_final against the chain's axis on both branches, every seed and the seed means, with each branch's
fitted jump and the loop's width; (b) the time each point needed to settle (the early stop's
``t_stopped``; a point not steady by t_final is drawn there, open); (c) one seed's chains as one
history, each point's series after its predecessor's (docs/campaigns/figures.md, "Figures")."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..campaign import BRANCH
from ..files import series_time
from .common import LABELS, Results, check_options, fmt

if TYPE_CHECKING:
    from matplotlib.figure import Figure

LOOP_OPTIONS = ("observable", "seed", "yscale", "compare")
COLOURS = {"up": "tab:blue", "down": "tab:red"}


def chain_axis(res: Results) -> str:
    """The chain's axis: the phase diagram's sweep dimension after ``branch``."""
    dims = [d for d in res.phase["status"].dims if d not in (BRANCH, "seed")]
    return str(res.phase.attrs.get("chain_axis") or dims[0])


def loop(res: Results, options: Mapping[str, Any]) -> Figure:
    """The hysteresis loop of a chain campaign (see the module docstring)."""
    from matplotlib.figure import Figure

    check_options("loop", options, LOOP_OPTIONS)
    phase = res.phase
    axis = chain_axis(res)
    observable = str(options.get("observable", "sigma2_S"))
    yscale = str(options.get("yscale", "log"))
    label = LABELS.get(axis, axis)
    x = phase[axis].values.astype(float)
    order = np.argsort(x)
    fig = Figure(figsize=(13.5, 4.3), layout="constrained")
    ax_a, ax_b, ax_c = (fig.add_subplot(1, 3, i + 1) for i in range(3))
    t_final = float(phase.attrs.get("num_t_final", math.nan))
    fits = res.fits
    for branch in (str(b) for b in phase[BRANCH].values):
        ds = phase.sel({BRANCH: branch})
        colour = COLOURS.get(branch, "k")
        values = ds[observable].transpose(axis, "seed").values.astype(float)
        xs = np.broadcast_to(x[:, None], values.shape)
        ok = np.isfinite(values) & ((values > 0) if yscale == "log" else True)
        ax_a.scatter(xs[ok], values[ok], s=8, color=colour, alpha=0.35, lw=0)
        mean = ds[f"{observable}_mean"].values[order]
        ax_a.plot(x[order], mean, "o-", color=colour, ms=4, lw=1.3, label=f"{branch}: seed mean")
        if "transition_location" in fits and BRANCH in fits["transition_location"].dims:
            row = fits.sel({BRANCH: branch})
            lo, hi = float(row["transition_lower"]), float(row["transition_upper"])
            if math.isfinite(lo) and math.isfinite(hi):
                ax_a.axvspan(lo, hi, color=colour, alpha=0.12, lw=0)
        steady = ds["t_stopped"].transpose(axis, "seed").values.astype(float)
        settled = np.where(np.isfinite(steady), steady, t_final)
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
        width = _compare(ax_a, res, str(compare), axis, observable, fits)
    if not width and "transition_loop_width" in fits:
        w = float(fits["transition_loop_width"])
        lo, hi = (
            float(fits["transition_loop_width_lower"]),
            float(fits["transition_loop_width_upper"]),
        )
        if math.isfinite(w):
            width = f": loop width {fmt(w)} [{fmt(lo)}, {fmt(hi)}]"
    ax_a.set_yscale(yscale)
    ax_a.set_xlabel(label)
    ax_a.set_ylabel(f"{LABELS.get(observable, observable)} at $t/\\tau$ = {t_final:g}")
    ax_a.set_title(f"(a) both branches{width}", loc="left")
    ax_a.legend(loc="best")
    ax_b.set_xlabel(label)
    ax_b.set_ylabel(r"time to settle $t/\tau$ (open: not steady by $t_{\rm final}$)")
    ax_b.set_title("(b) settling time per point", loc="left")
    ax_b.legend(loc="best")
    ax_c.set_yscale("log")
    ax_c.set_xlabel(r"time along the chain $t/\tau$")
    ax_c.set_ylabel(r"$\sigma^2_S$")
    ax_c.set_title(f"(c) one seed's chains ({label} of each point at its start)", loc="left")
    fig.suptitle(f"{res.name}: hysteresis along {axis}", fontsize=10)
    return fig


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


def _compare(ax, res: Results, name: str, axis: str, observable: str, fits) -> str:
    """Another campaign's seed means along the same axis (option ``compare``: a campaign in
    the same results folder, e.g. Fig. 2's runs each from a fresh texture) with its fitted
    jump; the loop width from that jump down to the down branch's, or ""."""
    from ..analysis.fits_file import load_fits, load_phase
    from ..errors import FitError

    root = res.root.parent / name
    try:
        other = load_phase(root)
    except FitError:
        ax.text(0.02, 0.02, f"no results of {name} to compare", transform=ax.transAxes)
        return ""
    x = other[axis].values.astype(float)
    order = np.argsort(x)
    mean = other[f"{observable}_mean"].values[order]
    ax.plot(x[order], mean, "s--", color="k", ms=3.5, lw=1.0, label=f"{name}: fresh texture")
    jump = load_fits(root)
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
