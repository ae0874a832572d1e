r"""Paper Fig. 2: (a) a snapshot, (b) sigma2_S(t) for several alpha - B (one seed), (c)
sigma2_S(t_final) against alpha - B with every seed and the fitted transition
(docs/campaigns/figures.md, "Figures")."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..campaign import AMB
from ..files import series_time
from .common import (
    Results,
    activity_line,
    check_options,
    describe,
    fmt,
    mark_verdicts,
    ok_run,
    on_slice,
    runs_along,
    safe_snapshot,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIG2_OPTIONS = ("select", "seed", "curves", "snapshot", "yscale")


def fig2(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. 2 (docs/campaigns/figures.md)."""
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    check_options("fig2", options, FIG2_OPTIONS)
    yscale = str(options.get("yscale", "linear"))
    ds, others, x = activity_line(res, "fig2", options)
    where = describe(ds, others)

    trans = _transition_row(res, ds, others)
    snap_opt = dict(options.get("snapshot") or {})
    snap_amb = snap_opt.get(AMB)
    if snap_amb is None:
        mean = ds["sigma2_S_mean"].values
        if trans is not None and math.isfinite(trans["upper"]):
            above = [
                (i, v)
                for i, v in enumerate(x)
                if v >= trans["upper"] - 1e-12 and np.isfinite(mean[i])
            ]
            snap_amb = above[0][1] if above else None
        if snap_amb is None and np.any(np.isfinite(mean)):
            snap_amb = x[int(np.nanargmax(np.where(np.isfinite(mean), mean, -np.inf)))]
    snap_run, snap_seed = (None, None)
    snap_point = None
    if snap_amb is not None:
        snap_point = ds.sel({AMB: snap_amb}, method="nearest")
        snap_run, snap_seed = ok_run(res, snap_point, snap_opt.get("seed"))

    fig = Figure(figsize=(13.0, 4.3), layout="constrained")
    gs = fig.add_gridspec(1, 3, width_ratios=[1.0, 1.0, 1.0])
    ax_a, ax_b, ax_c = (fig.add_subplot(gs[0, i]) for i in range(3))

    # (a) snapshot
    if snap_run is not None and snap_point is not None:
        index = -1
        if "time" in snap_opt and snap_run.sizes.get("snapshot_time", 0):
            index = int(
                np.argmin(np.abs(snap_run["snapshot_time"].values - float(snap_opt["time"])))
            )
        safe_snapshot(ax_a, snap_run, index)
        t = (
            float(snap_run["snapshot_time"].values[index])
            if snap_run.sizes.get("snapshot_time", 0)
            else math.nan
        )
        ax_a.set_title(
            rf"(a) $\alpha - B$ = {fmt(float(snap_point[AMB]))}, seed {snap_seed},"
            rf" $t/\tau$ = {t:g}",
            loc="left",
        )
    else:
        ax_a.text(
            0.5,
            0.5,
            "no successful run to draw",
            ha="center",
            va="center",
            transform=ax_a.transAxes,
        )
        ax_a.set_title("(a)", loc="left")

    # (b) sigma2_S(t) for several alpha - B
    cmap = colormaps["viridis"]
    drawn_seed = None
    for position, i, run, s in runs_along(
        res, ds, int(options.get("curves", 8)), options.get("seed")
    ):
        drawn_seed = s if drawn_seed is None else drawn_seed
        colour = cmap(position)
        times, series = series_time(run).values, run["sigma2_S"].values.astype(float)
        # t = 0 is left out: S = S0 is uniform there (sigma2_S = 0 up to round-off)
        ok = np.isfinite(series) & (series > 0) & (times > 0)
        ax_b.plot(times[ok], series[ok], color=colour, lw=1.4, label=fmt(float(x[i])))
    ax_b.set_yscale("log")
    ax_b.set_xlabel(r"$t/\tau$")
    ax_b.set_ylabel(r"$\sigma^2_S$")
    ax_b.set_title(f"(b) seed {drawn_seed}" if drawn_seed is not None else "(b)", loc="left")
    if ax_b.lines:
        ax_b.legend(title=r"$\alpha - B$", ncol=2 if len(ax_b.lines) > 4 else 1, loc="best")

    # (c) sigma2_S(t_final) vs alpha - B
    sig = ds["sigma2_S"].transpose(AMB, "seed").values.astype(float)
    mean, std = ds["sigma2_S_mean"].values, ds["sigma2_S_std"].values
    xs = np.broadcast_to(x[:, None], sig.shape)
    ok = np.isfinite(sig) & (sig > 0)
    ax_c.scatter(xs[ok], sig[ok], s=9, color="0.6", alpha=0.7, lw=0, label="seeds", zorder=2)
    good = np.isfinite(mean) & ((mean > 0) if yscale == "log" else True)
    err = np.where(np.isfinite(std), std, 0.0)
    # on a log axis a bar that would reach zero or below is cut at a tenth of the mean
    lower = np.minimum(err, 0.9 * mean) if yscale == "log" else err
    ax_c.errorbar(
        x[good],
        mean[good],
        yerr=[lower[good], err[good]],
        fmt="o-",
        color="k",
        ms=4.5,
        lw=1.2,
        capsize=2.5,
        label="seed mean ± std",
        zorder=3,
    )
    if trans is not None and math.isfinite(trans["location"]):
        ax_c.axvspan(
            trans["lower"],
            trans["upper"],
            color="tab:red",
            alpha=0.12,
            lw=0,
            label=(
                f"jump at {fmt(trans['location'])} [{fmt(trans['lower'])}, {fmt(trans['upper'])}]"
            ),
        )
    if snap_run is not None and snap_point is not None:
        value = float(snap_run["sigma2_S_final"]) if "sigma2_S_final" in snap_run else math.nan
        if math.isfinite(value) and value > 0:
            ax_c.plot(
                [float(snap_point[AMB])],
                [value],
                "o",
                ms=13,
                mfc="none",
                mec="red",
                mew=1.8,
                zorder=4,
                label="panel (a)",
            )
    marks = []
    for coords, verdict in res.verified:
        if AMB in coords and on_slice(coords, ds, others):
            i = int(np.argmin(np.abs(x - float(coords[AMB]))))
            if np.isfinite(mean[i]) and (mean[i] > 0 or yscale != "log"):
                marks.append(((float(x[i]), float(mean[i])), verdict))
    mark_verdicts(ax_c, marks, size=110.0)
    ax_c.set_yscale(yscale)
    if yscale == "linear":
        ax_c.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    ax_c.set_xlabel(r"$\alpha - B$")
    t_final = res.phase.attrs.get("num_t_final")
    ax_c.set_ylabel(
        rf"$\sigma^2_S$ at $t/\tau$ = {float(t_final):g}"
        if t_final is not None
        else r"$\sigma^2_S(t_{\rm final})$"
    )
    # an adaptive campaign runs different numbers of seeds per point (phase.nc's seed_count)
    counts = (
        ds["seed_count"].values[ds["seed_count"].values > 0]
        if "seed_count" in ds
        else np.array([ds["seed"].size])
    )
    lo, hi = (int(counts.min()), int(counts.max())) if counts.size else (0, 0)
    ax_c.set_title(f"(c) {hi} seeds" if lo == hi else f"(c) {lo}-{hi} seeds per point", loc="left")
    ax_c.legend(loc="lower right" if yscale == "log" else "best")
    fig.suptitle(f"{res.name}: paper Fig. 2" + (f" ({where})" if where else ""), fontsize=10)
    return fig


def _transition_row(res: Results, ds: xr.Dataset, others: Sequence[str]) -> dict[str, float] | None:
    """The fitted transition along alpha - B at the other sweep values of ``ds``."""
    fits = res.fits
    if "transition_location" not in fits:
        return None
    if fits["transition_location"].attrs.get("fit_axis", AMB) != AMB:
        return None
    row = fits
    for d in others:
        if d in row.dims and d in ds.coords:
            row = row.sel({d: float(ds[d])}, method="nearest")
    out = {}
    for n in ("location", "lower", "upper"):
        v = row[f"transition_{n}"]
        if v.ndim:
            return None
        out[n] = float(v)
    return out
