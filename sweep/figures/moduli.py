r"""An oscillatory shear's moduli (a ``sine`` of eps; the ``moduli`` fit): (a) the storage
modulus G' and (b) the loss modulus G'' against the sweep's first axis, one line per period and
amplitude (the passive matrix's G' = 1, G'' = 0 dashed); (c) one seed's stress against the
strain over the last period at the axis' lowest and highest value, the Lissajous loop whose
orientation is the sign of G'' (docs/campaigns/figures.md, "Figures")."""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.rheology import sine_of
from ..files import series_time
from .common import LABELS, Results, check_options, fmt

if TYPE_CHECKING:
    from matplotlib.figure import Figure

MODULI_FIGURE_OPTIONS = ("seed",)
NUMBERS = ("eps_amplitude", "eps_period")


def moduli_figure(res: Results, options: Mapping[str, Any]) -> Figure:
    """The moduli of an oscillatory shear campaign (see the module docstring)."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    check_options("moduli", options, MODULI_FIGURE_OPTIONS)
    phase = res.phase
    fits = res.fit("moduli_storage_mean", "moduli_loss_mean")
    axis = str(next(d for d in phase["status"].dims if d not in (*NUMBERS, "seed")))
    x = phase[axis].values.astype(float)
    order = np.argsort(x)
    others = [d for d in NUMBERS if d in phase.dims]
    fig = Figure(figsize=(13.5, 4.3), layout="constrained")
    ax_a, ax_b, ax_c = (fig.add_subplot(1, 3, i + 1) for i in range(3))
    combos = list(itertools.product(*(phase[d].values for d in others)))
    for k, values in enumerate(combos):
        where = dict(zip(others, values, strict=True))
        label = ", ".join(
            f"{'T' if d == 'eps_period' else 'eps0'} = {fmt(float(v))}" for d, v in where.items()
        )
        g1 = fits["moduli_storage_mean"].sel(where).values[order]
        g2 = fits["moduli_loss_mean"].sel(where).values[order]
        for ax, g in ((ax_a, g1), (ax_b, g2)):
            ax.plot(x[order], g, "o-", ms=4, lw=1.2, color=f"C{k}", label=label or None)
    for ax, passive in ((ax_a, 1.0), (ax_b, 0.0)):
        ax.axhline(passive, color="0.5", ls="--", lw=0.8, label="passive matrix")
        ax.set_xlabel(LABELS.get(axis, axis))
        ax.legend(loc="best", fontsize=7)
    ax_a.set_ylabel("storage modulus G'")
    ax_a.set_title("(a) storage modulus", loc="left")
    ax_b.set_ylabel("loss modulus G''")
    ax_b.set_title("(b) loss modulus (< 0: activity does work)", loc="left")
    seed = int(phase["seed"].values[0]) if options.get("seed") is None else int(options["seed"])
    last: dict[str, Any] = {d: phase[d].values[-1] for d in others}
    for value, colour in ((x[order][0], "tab:blue"), (x[order][-1], "tab:red")):
        point = phase.sel({axis: value, **last}).sel(seed=seed)
        run = res.run(str(point["run_id"].values))
        if run is None or "stress_shear" not in run:
            continue
        coords = {axis: value, **{d: point[d].item() for d in others}}
        amplitude, period, start = sine_of(phase, coords)
        t = series_time(run).values.astype(float)
        use = t >= t[-1] - period - 1e-9
        strain = amplitude * np.sin(2 * math.pi * (t[use] - start) / period)
        stress = run["stress_shear"].values.astype(float)[use]
        ax_c.plot(
            strain, stress - stress.mean(), color=colour, lw=1.2, label=f"{fmt(float(value))}"
        )
        ax_c.plot(strain[:1], (stress - stress.mean())[:1], "o", color=colour, ms=3)
    ax_c.xaxis.set_major_locator(MaxNLocator(5))
    ax_c.set_xlabel(r"applied shear $\epsilon$")
    ax_c.set_ylabel(r"$\langle (P_{11} - P_{22})/2 \rangle$ minus its mean")
    ax_c.set_title(f"(c) seed {seed}, the last period", loc="left")
    if ax_c.lines:
        ax_c.legend(title=LABELS.get(axis, axis), loc="best")
    fig.suptitle(f"{res.name}: moduli under an oscillatory shear", fontsize=10)
    return fig
