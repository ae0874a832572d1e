r"""Paper Fig. A1: stable and unstable runs in the (chi (alpha - B), eps) plane with the
linear-stability boundary (docs/campaigns/figures.md, "Figures")."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..analysis.phase import with_dim
from ..errors import FitError
from .common import (
    LABELS,
    Results,
    check_options,
    mark_verdicts,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIGA1_OPTIONS: tuple[str, ...] = ()


def _ran(phase: xr.Dataset, act: str, strain: str, shape: tuple[int, ...]) -> np.ndarray:
    """Whether any seed was run at each (activity, strain) point (from phase.nc's
    ``seed_count`` where a refined campaign wrote it; every point otherwise)."""
    if "seed_count" not in phase:
        return np.ones(shape, dtype=bool)
    try:
        count = with_dim(with_dim(phase, act), strain)["seed_count"]
        ran = (count > 0).transpose(act, strain).values
    except (KeyError, ValueError, FitError):
        return np.ones(shape, dtype=bool)
    return ran if ran.shape == shape else np.ones(shape, dtype=bool)


def figA1(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. A1 (docs/campaigns/figures.md)."""
    from matplotlib.figure import Figure

    check_options("figA1", options, FIGA1_OPTIONS)
    f = res.fit("stability_fraction_unstable", "stability_theory_fine")
    attrs = f["stability_unstable"].attrs
    act = str(attrs.get("fit_activity", "chi"))
    strain = str(attrs.get("fit_strain", "eps"))
    scale = float(attrs.get("fit_activity_scale", 1.0))
    frac = f["stability_fraction_unstable"].transpose(act, strain).values
    a = f[act].values.astype(float) * scale
    e = f[strain].values.astype(float)
    A, E = np.meshgrid(a, e, indexing="ij")

    fig = Figure(figsize=(6.2, 5.4), layout="constrained")
    ax = fig.add_subplot()
    stable = frac == 0
    unstable = frac == 1
    mixed = (frac > 0) & (frac < 1)
    # "no data": points whose runs are missing or unclassified; points where no seed was
    # planned (a refined campaign's phase.nc: its axis is the union of every value run) are
    # left blank
    unknown = ~np.isfinite(frac) & _ran(res.phase, act, strain, frac.shape)
    ax.scatter(
        A[stable],
        E[stable],
        s=30,
        facecolors="none",
        edgecolors="tab:blue",
        lw=1.1,
        label="stable",
        zorder=3,
    )
    ax.scatter(A[unstable], E[unstable], s=30, color="tab:red", label="unstable", zorder=3)
    if np.any(mixed):
        ax.scatter(
            A[mixed],
            E[mixed],
            s=30,
            color="tab:purple",
            marker="D",
            label="seeds disagree",
            zorder=3,
        )
    if np.any(unknown):
        ax.scatter(A[unknown], E[unknown], s=25, color="0.6", marker="x", label="no data", zorder=3)
    mark_verdicts(
        ax,
        [
            ((float(w[act]) * scale, float(w[strain])), verdict)
            for w, verdict in res.verified
            if act in w and strain in w
        ],
        size=90.0,
    )
    fine = f["activity_fine"].values * scale
    th = f["stability_theory_fine"].values
    ax.plot(
        fine, th, "-", color="tab:orange", lw=2.2, label="linear stability (docs/stability.md S10)"
    )
    if "stability_paper_fine" in f:
        ax.plot(
            fine,
            f["stability_paper_fine"].values,
            "--",
            color="0.45",
            lw=1.2,
            label="paper Eq. (6) as printed",
        )
    ax.set_ylim(e.min() - 0.04 * max(np.ptp(e), 1e-3), e.max() + 0.04 * max(np.ptp(e), 1e-3))
    ax.set_xlim(a.min() - 0.03 * max(np.ptp(a), 1e-3), a.max() + 0.03 * max(np.ptp(a), 1e-3))
    ax.set_xlabel(LABELS["activity"])
    ax.set_ylabel(r"applied strain $\epsilon$")
    mech = str(attrs.get("fit_mechanics", ""))
    inc = "incompressible" if int(attrs.get("fit_incompressible", 0)) else "compressible"
    n_seeds = int(res.phase.sizes.get("seed", 0))
    ax.set_title(
        f"{res.name}: paper Fig. A1 ({mech} mechanics, {inc}; {n_seeds} "
        f"seed{'s' if n_seeds != 1 else ''})",
        fontsize=9,
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=8)
    return fig
