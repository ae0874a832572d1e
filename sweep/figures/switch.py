r"""Switching activity off and on (a ``pulse`` of alpha - B swept over its ``level`` L and
``duration`` D; the ``recovery`` fit): (a) sigma2_S(t) through the protocol for one seed at
every level, the longest duration; (b) how far the pattern fell while activity was low,
log10 of sigma2_S at the restore time over its value at the switch, with the fraction of seeds
that recovered; (c) its memory, the correlation of S before the switch and at the end
(docs/campaigns/figures.md, "Figures")."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.statistics import finite_mean
from ..files import series_time
from .common import Results, check_options, fmt

if TYPE_CHECKING:
    from matplotlib.figure import Figure

SWITCH_OPTIONS = ("seed",)
LEVEL, DURATION = "alpha_minus_B_level", "alpha_minus_B_duration"


def switch(res: Results, options: Mapping[str, Any]) -> Figure:
    """The switch-off / recovery figure (see the module docstring)."""
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    check_options("switch", options, SWITCH_OPTIONS)
    phase, fits = res.phase, res.fit("recovery_sigma2_restore", "recovery_memory_end_mean")
    levels = phase[LEVEL].values.astype(float)
    durations = phase[DURATION].values.astype(float) if DURATION in phase.dims else np.array([])
    seeds = [int(s) for s in phase["seed"].values]
    seed = seeds[0] if options.get("seed") is None else int(options["seed"])
    fig = Figure(figsize=(14.0, 4.4), layout="constrained")
    ax_a, ax_b, ax_c = (fig.add_subplot(1, 3, i + 1) for i in range(3))
    cmap = colormaps["viridis"]
    longest = {DURATION: float(durations.max())} if durations.size else {}
    for k, level in enumerate(levels):
        point = phase.sel({LEVEL: level, **longest}).sel(seed=seed)
        run = res.run(str(point["run_id"].values))
        if run is None:
            continue
        t, v = series_time(run).values.astype(float), run["sigma2_S"].values.astype(float)
        ok = np.isfinite(v) & (v > 0) & (t > 0)
        colour = cmap(k / max(len(levels) - 1, 1))
        ax_a.plot(t[ok], v[ok], color=colour, lw=1.2, label=f"L = {fmt(level)}")
    if durations.size:
        restore = _restore_time(phase, float(durations.max()))
        if math.isfinite(restore):
            ax_a.axvspan(restore - float(durations.max()), restore, color="0.9", lw=0, zorder=0)
    ax_a.set_yscale("log")
    ax_a.set_xlabel(r"$t/\tau$")
    ax_a.set_ylabel(r"$\sigma^2_S$")
    title = f"(a) seed {seed}" + (f", D = {fmt(float(durations.max()))}" if durations.size else "")
    ax_a.set_title(title + " (grey: activity at L)", loc="left")
    ax_a.legend(loc="best", title=r"$\alpha - B$ held at")

    ratio = fits["recovery_sigma2_restore"] / fits["recovery_sigma2_before"]
    with np.errstate(divide="ignore", invalid="ignore"):  # geometric seed mean
        drop_mean = finite_mean(np.log10(ratio.transpose(LEVEL, DURATION, "seed").values))
    recovered = fits["recovery_recovered_mean"].transpose(LEVEL, DURATION).values
    memory = fits["recovery_memory_end_mean"].transpose(LEVEL, DURATION).values
    _map(ax_b, drop_mean, levels, durations, "coolwarm_r", (-6.0, 6.0), recovered, "recovered")
    ax_b.set_title(r"(b) $\log_{10}$ of $\sigma^2_S$ at restore / at switch", loc="left")
    _map(ax_c, memory, levels, durations, "magma", (0.0, 1.0), memory, "")
    ax_c.set_title("(c) memory: correlation of S at the switch and at the end", loc="left")
    if not np.isfinite(memory).any():
        ax_c.text(0.5, 0.5, "no snapshot at the switch time", ha="center", transform=ax_c.transAxes)
    fig.suptitle(f"{res.name}: activity switched to L for D, then restored", fontsize=10)
    return fig


def _restore_time(phase, duration: float) -> float:
    """The restore time of the pulse of the campaign's protocol with this duration."""
    raw = phase.attrs.get("param_protocol")
    if not raw:
        return math.nan
    pulse = json.loads(str(raw)).get("alpha_minus_B", {}).get("pulse", {})
    start = pulse.get("start")
    return math.nan if start is None else float(start) + duration


def _map(ax, values, levels, durations, cmap, limits, notes, what) -> None:
    """A map over (duration, level) with each cell's number written in it."""
    image = ax.imshow(
        values,
        origin="lower",
        aspect="auto",
        cmap=cmap,
        vmin=limits[0],
        vmax=limits[1],
        extent=(-0.5, len(durations) - 0.5, -0.5, len(levels) - 0.5),
    )
    ax.figure.colorbar(image, ax=ax, shrink=0.85)
    for i in range(len(levels)):
        for j in range(len(durations)):
            note = notes[i, j]
            if math.isfinite(float(note)):
                text = f"{note:.2f}" if not what else f"{what} {note:.0%}"
                ax.text(j, i, text, ha="center", va="center", fontsize=6.5, color="0.1")
    ax.set_xticks(range(len(durations)), [fmt(float(d)) for d in durations])
    ax.set_yticks(range(len(levels)), [fmt(float(v)) for v in levels])
    ax.set_xlabel(r"duration D ($t/\tau$)")
    ax.set_ylabel(r"level L of $\alpha - B$")
