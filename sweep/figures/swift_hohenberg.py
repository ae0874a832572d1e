r"""The Swift-Hohenberg model's phase diagram with both branches of its chain (figure
``sh_phase``, model ``swift-hohenberg``): each point of the (eps, g) plane classed uniform,
stripes or hexagons (the model's :func:`~nematic_solids.sweep.models.swift_hohenberg.classify`
of the seed means) on the up and the down branch, over the amplitude equations' boundaries
(:func:`~nematic_solids.sweep.models.swift_hohenberg.theory`): the onset eps = 0, the hexagons'
saddle-node eps_H at leading and next order (the latter where its cubic coefficient is
positive, g < 0.84), and the stripes' stability eps_S.

:func:`branch_boundaries` reads the measured boundaries off the same data: for each g, the
lowest eps of the down branch that keeps a pattern and the highest eps below it that is
uniform (the saddle-node lies between), and the lowest eps of the up branch that patterned."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..campaign import BRANCH
from ..errors import FigureError
from .common import Results, check_options

if TYPE_CHECKING:
    from matplotlib.figure import Figure

SH_OPTIONS = ()
#: the next order's cubic coefficient 3 - 38 g^2 / 9 is positive below this g: above it the
#: expansion gives no saddle-node (docs/model/swift_hohenberg.md)
NEXT_ORDER_LIMIT = math.sqrt(27 / 38)
COLOURS = {"uniform": "0.8", "stripes": "tab:blue", "hexagons": "tab:red"}


def classes(phase: xr.Dataset) -> xr.DataArray:
    """Each point's class (branch x g x eps) from the seed means of the model's observables."""
    from ..models.swift_hohenberg import MODEL  # py-pde: imported when the figure is drawn

    names = [o.name for o in MODEL.observables]
    missing = [n for n in names if f"{n}_mean" not in phase]
    if missing or BRANCH not in phase.dims or not {"eps", "g"} <= set(phase.dims):
        raise FigureError(
            "sh_phase: a Swift-Hohenberg chain over eps and g is needed (phase.nc has no "
            f"{', '.join(missing) or 'branch, eps or g'})"
        )
    means = phase[[f"{n}_mean" for n in names]].transpose(BRANCH, "g", "eps")
    out = np.empty(means[f"{names[0]}_mean"].shape, dtype=object)
    for index in np.ndindex(out.shape):
        values = {n: float(means[f"{n}_mean"].values[index]) for n in names}
        finite = all(math.isfinite(v) for v in values.values())
        out[index] = MODEL.classify(values) if finite else "missing"
    return xr.DataArray(out, coords=means.coords, dims=means[f"{names[0]}_mean"].dims)


def branch_boundaries(phase: xr.Dataset) -> list[dict[str, Any]]:
    """Per g: the down branch's last patterned eps and the first uniform eps below it
    (``down_pattern``, ``down_uniform``), the up branch's first patterned eps
    (``up_pattern``) and the uniform eps just below it (``up_uniform``), and the amplitude
    equations' eps_H at leading and next order; NaN where the branch has none."""
    from ..models.swift_hohenberg import theory

    c = classes(phase)
    eps = [float(e) for e in c["eps"].values]
    rows = []
    for g in c["g"].values:
        down = [str(x) for x in c.sel(branch="down", g=g).values]
        up = [str(x) for x in c.sel(branch="up", g=g).values]
        row: dict[str, Any] = {"g": float(g)}
        row.update(_edge(eps, down, "down"))
        row.update(_edge(eps, up, "up"))
        row["eps_H_leading"] = theory(float(g))["eps_H"]
        row["eps_H_next"] = theory(float(g), "next")["eps_H"]
        rows.append(row)
    return rows


def _edge(eps: list[float], cls: list[str], branch: str) -> dict[str, float]:
    """The lowest patterned eps of a branch (walking down from the top: the down branch keeps
    its pattern to there; the up branch patterns from there) and the eps just below it."""
    patterned = [i for i, x in enumerate(cls) if x in ("stripes", "hexagons")]
    if branch == "down":  # the pattern from the top, followed down until it is lost
        patterned = _run_from_top(cls)
    if not patterned:
        return {f"{branch}_pattern": math.nan, f"{branch}_uniform": math.nan}
    lowest = min(patterned)
    below = eps[lowest - 1] if lowest > 0 else math.nan
    return {f"{branch}_pattern": eps[lowest], f"{branch}_uniform": below}


def _run_from_top(cls: list[str]) -> list[int]:
    """The indices of the patterned points from the top of the axis down to the first
    uniform one; none where the top is uniform."""
    out = []
    for i in range(len(cls) - 1, -1, -1):
        if cls[i] not in ("stripes", "hexagons"):
            break
        out.append(i)
    return out


def sh_phase(res: Results, options: Mapping[str, Any]) -> Figure:
    """The phase diagram of both branches over the theory (see the module docstring)."""
    from matplotlib.figure import Figure

    from ..models.swift_hohenberg import theory

    check_options("sh_phase", options, SH_OPTIONS)
    c = classes(res.phase)
    eps = np.asarray(c["eps"].values, dtype=float)
    gs = np.asarray(c["g"].values, dtype=float)
    fig = Figure(figsize=(10.5, 4.6), layout="constrained")
    line = np.linspace(0.0, float(gs.max()), 100)
    for k, branch in enumerate(("up", "down")):
        ax = fig.add_subplot(1, 2, k + 1)
        for name, colour in COLOURS.items():
            at = np.argwhere(c.sel(branch=branch).values == name)
            ax.scatter(eps[at[:, 1]], gs[at[:, 0]], s=40, color=colour, label=name, zorder=3)
        ax.axvline(0.0, color="k", lw=0.8, label="onset (eps = 0)")
        for order, style in (("leading", "--"), ("next", ":")):
            valid = line if order == "leading" else line[line < NEXT_ORDER_LIMIT]
            h = [theory(float(g), order)["eps_H"] for g in valid]
            ax.plot(h, valid, "k" + style, lw=1, label=f"eps_H, {order} order")
        s = [theory(float(g))["eps_S"] for g in line]
        ax.plot(s, line, color="tab:blue", ls="--", lw=1, label="eps_S (stripes stable)")
        ax.set_xlim(float(eps.min()) - 0.005, float(eps.max()) + 0.005)
        ax.set_xlabel("eps")
        ax.set_ylabel("g")
        start = f"from eps = {eps.min() if branch == 'up' else eps.max():g}"
        ax.set_title(f"{branch} branch ({start}, each point from the previous)", fontsize=9)
        if k == 1:
            handles, labels = ax.get_legend_handles_labels()
            fig.legend(handles, labels, fontsize=7, loc="outside lower center", ncol=7)
    fig.suptitle(
        f"{res.name}: Swift-Hohenberg patterns against the amplitude equations", fontsize=10
    )
    return fig
