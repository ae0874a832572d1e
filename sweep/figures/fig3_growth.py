r"""Fig. 3's mechanism: the pattern size lambda(t) and sigma2_S(t) of one seed for several
alpha - B at one K, the growth peak (where Fig. 3 reads lambda) marked on each curve
(docs/campaigns/figures.md, "Figures").

lambda(t) of the relaxing texture grows at about the same rate at every alpha - B; what
activity changes is when the pattern's growth ends, so lambda_peak falls with activity when
that time does (docs/results.md, "Calibration")."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import FigureError
from ..files import series_time
from .common import Results, activity_line, check_options, describe, fmt, runs_along

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIG3_GROWTH_OPTIONS = ("select", "seed", "curves")


def fig3_growth(res: Results, options: Mapping[str, Any]) -> Figure:
    """lambda(t) and sigma2_S(t) at one K (``select``, default the first), one seed
    (``seed``, default the first that succeeded everywhere it is drawn), at most ``curves``
    values of alpha - B (default 6); the growth peak (t_peak, lambda_peak) is a dot."""
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    check_options("fig3_growth", options, FIG3_GROWTH_OPTIONS)
    ds, others, x = activity_line(res, "fig3_growth", options)

    fig = Figure(figsize=(11.0, 4.3), layout="constrained")
    ax_l, ax_s = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    cmap = colormaps["plasma"]
    drawn_seed = None
    for position, i, run, s in runs_along(
        res, ds, int(options.get("curves", 6)), options.get("seed")
    ):
        drawn_seed = s if drawn_seed is None else drawn_seed
        colour = cmap(0.85 * position)
        times = series_time(run).values
        lam = run["lambda"].values.astype(float)
        sig = run["sigma2_S"].values.astype(float)
        ok = (times > 0) & np.isfinite(sig) & (sig > 0)
        patterned = float(run["sigma2_S_final"]) > 1e-6 if "sigma2_S_final" in run else True
        style = "-" if patterned else ":"
        label = fmt(float(x[i])) + ("" if patterned else " (relaxes)")
        ax_l.plot(
            times[ok & np.isfinite(lam)],
            lam[ok & np.isfinite(lam)],
            style,
            color=colour,
            lw=1.4,
            label=label,
        )
        ax_s.plot(times[ok], sig[ok], style, color=colour, lw=1.4, label=label)
        t_peak = float(run["t_peak"]) if "t_peak" in run else math.nan
        if patterned and math.isfinite(t_peak):
            j = int(np.argmin(np.abs(times - t_peak)))
            ax_l.plot([times[j]], [lam[j]], "o", color=colour, ms=7, mec="k", zorder=4)
            ax_s.plot([times[j]], [sig[j]], "o", color=colour, ms=7, mec="k", zorder=4)
    if not ax_l.lines:
        raise FigureError("fig3_growth: no successful run to draw")
    ax_l.set_xscale("log")
    ax_l.set_yscale("log")
    ax_l.set_xlabel(r"$t/\tau$")
    ax_l.set_ylabel(r"$\lambda$ (units of L)")
    ax_l.set_title(
        r"(a) pattern size $\lambda(t)$; dot: growth peak ($\lambda_{\rm peak}$)",
        loc="left",
        fontsize=10,
    )
    ax_s.set_yscale("log")
    top = max(float(np.nanmax(line.get_ydata())) for line in ax_s.lines)
    ax_s.set_ylim(bottom=1e-4 * top)  # a relaxing run falls to round-off: cut it off
    ax_s.set_xscale("log")
    ax_s.set_xlabel(r"$t/\tau$")
    ax_s.set_ylabel(r"$\sigma^2_S$")
    ax_s.set_title(f"(b) seed {drawn_seed}", loc="left", fontsize=10)
    ax_s.legend(title=r"$\alpha - B$", fontsize=8, loc="best")
    where = describe(ds, others)
    fig.suptitle(
        f"{res.name}: growth of the pattern" + (f" ({where})" if where else ""), fontsize=10
    )
    return fig
