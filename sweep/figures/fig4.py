r"""Paper Fig. 4: (a) the phase diagram over chi (alpha - B), K and eps, (b) four
representative snapshots, (c) <cos 2 theta> against eps with the fitted slopes
(docs/campaigns/figures.md, "Figures")."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..analysis.phase import fixed_parameter, is_swept, select, sweep_dims, with_dim
from ..campaign import AMB
from ..errors import FigureError
from .common import (
    LABELS,
    Results,
    check_options,
    default_select,
    fmt,
    fmt_sci,
    mark_verdicts,
    nearest_point,
    ok_run,
    on_slice,
    safe_snapshot,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

FIG4_OPTIONS = ("select", "snapshots")
#: The representative snapshots of the Fig. 4 caption (alpha - B = 1 there).
FIG4_SNAPSHOTS: tuple[dict[str, float], ...] = (
    {"K": 1e-6, "chi": 0.0, "eps": 0.0},
    {"K": 1e-6, "chi": 5.0, "eps": 0.0},
    {"K": 1e-6, "chi": 5.0, "eps": 0.05},
    {"K": 1e-2, "chi": 0.0, "eps": 0.05},
)


def _activity(ds: xr.Dataset) -> tuple[str | None, float]:
    """The sweep dim that carries the activity chi (alpha - B) and its scale factor."""
    if is_swept(ds, "chi"):
        if is_swept(ds, AMB):
            raise FigureError(
                "both chi and alpha - B are swept: fix one with the option "
                "select: {alpha_minus_B: VALUE}"
            )
        return "chi", fixed_parameter(ds, AMB) or 1.0
    if is_swept(ds, AMB):
        return AMB, fixed_parameter(ds, "chi") or 1.0
    return None, 1.0


def _sizes(values: np.ndarray, vmax: float, smin: float = 8.0, smax: float = 260.0) -> np.ndarray:
    v = np.where(np.isfinite(values) & (values > 0), values, 0.0)
    return smin + (smax - smin) * np.sqrt(v / vmax) if vmax > 0 else np.full(v.shape, smin)


def fig4(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. 4 (docs/campaigns/figures.md)."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401 - registers the 3-D projection

    check_options("fig4", options, FIG4_OPTIONS)
    ds = select(res.phase, options.get("select"))
    act, scale = _activity(ds)
    axes = [a for a in (act, "K", "eps") if a is not None and is_swept(ds, a)]
    if len(axes) < 2:
        raise FigureError(
            "fig4 needs at least two of chi (or alpha - B), K and eps swept "
            f"(swept: {', '.join(sweep_dims(ds)) or 'none'})"
        )
    if act is not None and act not in ds.coords:
        ds = with_dim(ds, act)  # alpha - B from a swept alpha or B
    # sweep dims that carry none of the axes (zip groups carry several) are fixed
    carried = {str(ds[a].dims[0]) for a in axes}
    ds = default_select(ds, sorted(carried), None)
    dims = sweep_dims(ds)
    ref = ds["sigma2_S_mean"].transpose(*dims)
    coords = [ds[a].broadcast_like(ref).transpose(*dims).values.astype(float).ravel() for a in axes]
    labels = {act: LABELS["activity"], "K": r"$\log_{10} K$", "eps": r"$\epsilon$"}
    plot_vals = []
    for a, v in zip(axes, coords, strict=True):
        if a == act:
            plot_vals.append(v * scale)
        elif a == "K":
            with np.errstate(divide="ignore"):
                plot_vals.append(np.log10(np.maximum(v, 1e-300)))
        else:
            plot_vals.append(v)
    cos = ds["cos2theta_mean"].transpose(*dims).values.ravel()
    sig = ref.values.ravel()
    if "seed_count" in ds:  # a refined campaign's union grid: only the points run
        ran = ds["seed_count"].transpose(*dims).values.ravel() > 0
        plot_vals = [v[ran] for v in plot_vals]
        cos, sig = cos[ran], sig[ran]
    vmax = (
        float(np.nanmax(np.where(np.isfinite(sig), sig, np.nan)))
        if np.any(np.isfinite(sig))
        else 0.0
    )
    lim = float(np.nanmax(np.abs(cos))) if np.any(np.isfinite(cos)) else 1.0
    lim = max(lim, 0.05)
    norm = Normalize(-lim, lim)
    cmap = colormaps["coolwarm"]
    has_eps = "eps" in axes and "eps" in ds.dims  # panel (c) needs eps as its own dim

    fig = Figure(figsize=(16.0 if has_eps else 12.5, 6.2), layout="constrained")
    gs = fig.add_gridspec(
        2, 4 if has_eps else 3, width_ratios=[2.3, 1, 1, 1.45][: 4 if has_eps else 3]
    )
    three_d = len(axes) == 3
    ax: Any = fig.add_subplot(gs[:, 0], projection="3d" if three_d else None)
    finite = np.isfinite(cos)
    size = _sizes(sig, vmax)
    colours = np.where(finite[:, None], cmap(norm(np.where(finite, cos, 0.0))), (0.7,) * 4)
    if three_d:
        ax.scatter(*plot_vals, s=size, c=colours, edgecolors="k", linewidths=0.4, depthshade=False)
        ax.set_zlabel(labels[axes[2]], labelpad=2)
        ax.view_init(elev=22, azim=-58)
    else:
        ax.scatter(*plot_vals, s=size, c=colours, edgecolors="k", linewidths=0.4)
        ax.margins(0.1)
    marks = []
    for where, verdict in res.verified:
        if all(a in where for a in axes) and on_slice(
            where, ds, sorted(set(map(str, ds.coords)) - set(axes))
        ):
            marks.append(
                (
                    [
                        float(where[a]) * scale
                        if a == act
                        else math.log10(max(float(where[a]), 1e-300))
                        if a == "K"
                        else float(where[a])
                        for a in axes
                    ],
                    verdict,
                )
            )
    framed = mark_verdicts(ax, marks, size=230.0)
    ax.set_xlabel(labels[axes[0]])
    ax.set_ylabel(labels[axes[1]])
    ax.set_title("(a) colour: " + LABELS["cos2theta"] + r", size: $\sigma^2_S$", loc="left")
    from matplotlib.cm import ScalarMappable

    fig.colorbar(
        ScalarMappable(norm=norm, cmap=cmap),
        ax=ax,
        shrink=0.7,
        pad=0.1 if three_d else 0.02,
        label=LABELS["cos2theta"],
    )
    if vmax > 0:
        refs = [vmax * f for f in (1.0, 0.25, 0.02)]
        handles = [
            ax.scatter(
                [],
                [],
                s=float(_sizes(np.array([r]), vmax)[0]),
                c="0.6",
                edgecolors="k",
                linewidths=0.4,
            )
            for r in refs
        ]
        ax.legend(
            [*handles, *framed],
            [f"{r:.2g}" for r in refs] + [h.get_label() for h in framed],
            title=r"marker size: $\sigma^2_S$",
            loc="upper center",
            bbox_to_anchor=(0.5, -0.1 if three_d else -0.09),
            ncol=3,
            fontsize=8,
            borderpad=0.8,
            columnspacing=2.5,
        )
    elif framed:
        ax.legend(loc="upper left", fontsize=7)

    # (b) representative snapshots
    targets = list(options.get("snapshots") or FIG4_SNAPSHOTS)[:4]
    seen: list[tuple[float, ...]] = []
    slots = [gs[0, 1], gs[0, 2], gs[1, 1], gs[1, 2]]
    for n, target in enumerate(targets, start=1):
        if not isinstance(target, Mapping):
            raise FigureError(
                f"fig4: snapshots[{n - 1}] = {target!r}; expected a mapping {{dim: value}}"
            )
        where = {k: v for k, v in target.items() if k in axes}
        # an axis the target does not name (e.g. alpha - B where the snapshots name chi) is
        # taken at its first grid value
        where.update({a: float(ds[a].values.ravel()[0]) for a in axes if a not in where})
        point = nearest_point(ds, where)
        key = tuple(float(point[a]) for a in axes)
        sub = fig.add_subplot(slots[n - 1])
        run, seed = ok_run(res, point)
        title = ", ".join(f"{LABELS.get(a, a)}={fmt_sci(float(point[a]))}" for a in axes)
        if run is None:
            sub.text(
                0.5, 0.5, "no successful run", ha="center", va="center", transform=sub.transAxes
            )
            sub.set_xticks([])
            sub.set_yticks([])
        else:
            safe_snapshot(sub, run, -1, colorbar=False, arrows=20)
            grid = run.attrs.get("num_resolution")
            if grid is not None:  # the run's own grid (resolution: auto gives each its own)
                title += f", {int(grid)}$^2$"
        sub.set_title(f"({n}) {title}", fontsize=8)
        if key not in seen:
            seen.append(key)
            vals = [
                float(point[a]) * (scale if a == act else 1.0)
                if a != "K"
                else math.log10(max(float(point[a]), 1e-300))
                for a in axes
            ]
            if three_d:
                ax.text(*vals, f" {n}", fontsize=9, fontweight="bold")
            else:
                ax.annotate(
                    str(n),
                    (vals[0], vals[1]),
                    textcoords="offset points",
                    xytext=(6, 6),
                    fontsize=9,
                    fontweight="bold",
                )

    # (c) anisotropy trend
    if has_eps:
        axc = fig.add_subplot(gs[:, 3])
        _anisotropy_panel(axc, res, ds, axes, act, scale)
    fig.suptitle(
        f"{res.name}: paper Fig. 4"
        + (f" (alpha - B = {fmt(fixed_parameter(ds, AMB) or math.nan)})" if act == "chi" else ""),
        fontsize=10,
    )
    return fig


def _anisotropy_panel(
    ax: Axes, res: Results, ds: xr.Dataset, axes: Sequence[str], act: str | None, scale: float
) -> None:
    from matplotlib import colormaps

    others = [d for d in sweep_dims(ds) if d != "eps"]  # dims (a zip dim carries several)
    eps = ds["eps"].values.astype(float)
    mean = ds["cos2theta_mean"]
    count = ds["cos2theta_count"]
    sem = ds["cos2theta_std"] / np.sqrt(count.where(count > 0))
    combos = list(np.ndindex(*(ds.sizes[o] for o in others)))
    if len(combos) > 8 and "K" in others:  # keep the smallest and largest K
        ki = others.index("K")
        combos = [c for c in combos if c[ki] in (0, ds.sizes["K"] - 1)]
    cmap = colormaps["plasma"]
    slope = res.fits.get("anisotropy_slope")
    shown = [a for a in axes if a != "eps"]
    for n, combo in enumerate(combos[:12]):
        sel = {o: i for o, i in zip(others, combo, strict=True)}
        point = ds.isel(sel)
        m = mean.isel(sel).transpose("eps").values
        s = sem.isel(sel).transpose("eps").values
        has = np.isfinite(m)  # a refined campaign's line may hold a single strain run
        if has.sum() < 2:
            continue
        label = ", ".join(
            f"{LABELS['activity'] if a == act else LABELS.get(a, a)}="
            f"{fmt_sci(float(point[a]) * (scale if a == act else 1.0))}"
            for a in shown
            if a in point.coords and point[a].ndim == 0
        )
        if slope is not None and all(d in point.coords for d in slope.dims):
            sv = slope.sel({d: float(point[d]) for d in slope.dims}, method="nearest")
            if sv.ndim == 0:
                label += f"; slope {fmt(float(sv))}"
        ax.errorbar(
            eps[has],
            m[has],
            yerr=np.where(np.isfinite(s), s, 0.0)[has],
            fmt="o-",
            ms=3.5,
            lw=1,
            capsize=2,
            color=cmap(0.85 * n / max(len(combos) - 1, 1)),
            label=label,
        )
    ax.axhline(0.0, color="0.6", lw=0.7)
    ax.set_xlabel(r"$\epsilon$")
    ax.set_ylabel(LABELS["cos2theta"])
    ax.set_title("(c) anisotropy vs applied strain", loc="left")
    ax.legend(fontsize=6.5, loc="best")
