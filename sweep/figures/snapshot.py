"""A run's snapshot drawn like the paper's Fig. 2a: director quivers coloured by S over an
I1bar = tr C / J background. Reads only a run Dataset (as written by
``nematic_solids.model.simulate.run``).

The background shows I1bar - 2 (I1bar >= 2 in 2-D, = 2 without shear), scaled by a power of
ten that the colour bar's label states when it is small (I1bar differs from 2 by ~1e-5 in a
weakly strained pattern): the tick labels stay short, without an offset or a multiplier. A
background whose spread is below :data:`UNIFORM` of its scale (the largest |I1bar - 2|) is
structure of rounding, not of the run (a uniformly sheared matrix, stored in float32): it is
drawn as its mean, one grey, in a colour range floored to that fraction around the mean, and
the colour bar's label says so.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..files import series_time

#: |I1bar - 2| below this (or at least BACKGROUND_MAX) is shown times a power of ten.
BACKGROUND_MIN, BACKGROUND_MAX = 1e-2, 1e3
BACKGROUND_NAME = r"$\bar I_1 = \mathrm{tr}\,C / J$"
#: the smallest colour range of the background, as a fraction of its scale
UNIFORM = 1e-3


def background_range(values: np.ndarray) -> tuple[float, float, bool]:
    """``(vmin, vmax, floored)`` of the background ``values``: their range, or, where it is
    below :data:`UNIFORM` of their scale (the largest magnitude), that width around their
    mean (``floored``: drawn uniform)."""
    finite = values[np.isfinite(values)]
    if not finite.size:
        return 0.0, 1.0, False
    lo, hi = float(finite.min()), float(finite.max())
    width = UNIFORM * float(np.abs(finite).max())
    if hi - lo >= width or width == 0.0:
        return lo, hi, False
    mid = 0.5 * (lo + hi)
    return mid - 0.5 * width, mid + 0.5 * width, True


def background(i1: np.ndarray) -> tuple[np.ndarray, str]:
    """The snapshot's background from the I1bar field: ``(values, label)``. The values are
    I1bar - 2, times 10^n when the largest |I1bar - 2| is below :data:`BACKGROUND_MIN` (or
    at least :data:`BACKGROUND_MAX`), so that they lie in [1, 10); the label says what is
    shown (e.g. ``10^{5} (I1bar - 2)``), for the colour bar."""
    values = np.asarray(i1, dtype=float) - 2.0
    finite = values[np.isfinite(values)]
    top = float(np.abs(finite).max()) if finite.size else 0.0
    shown = r"\bar I_1 - 2"
    if top > 0 and not BACKGROUND_MIN <= top < BACKGROUND_MAX:
        n = -math.floor(math.log10(top))
        values = values * 10.0**n
        shown = rf"10^{{{n}}}\,(\bar I_1 - 2)"
    return values, rf"${shown}$, {BACKGROUND_NAME} (background)"


def background_colorbar(fig: Any, image: Any, **kwargs: Any) -> Any:
    """A colour bar for the background ``image`` drawn by :func:`draw_snapshot` (its label
    is the image's label), with at most 5 plain ticks: no offset, no multiplier.
    ``kwargs`` go to ``fig.colorbar`` (``ax``, ``cax``, ``location``, ...)."""
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    cb = fig.colorbar(image, **kwargs)
    label = image.get_label()
    cb.set_label(label if label and not label.startswith("_") else BACKGROUND_NAME)
    cb.locator = MaxNLocator(5)
    formatter = ScalarFormatter(useOffset=False)
    formatter.set_scientific(False)
    cb.formatter = formatter
    cb.update_ticks()
    return cb


def draw_snapshot(ax, ds: xr.Dataset, index: int = -1, *, arrows: int = 32, colorbar: bool = True):
    """Draw snapshot ``index`` of ``ds`` on a matplotlib axes; returns the quiver artist.
    The background image (``ax.images[0]``) is :func:`background` of I1bar; its label is the
    colour-bar label (:func:`background_colorbar`)."""
    q1 = ds["q1"].isel(snapshot_time=index).values.astype(float)
    q2 = ds["q2"].isel(snapshot_time=index).values.astype(float)
    i1 = ds["I1bar"].isel(snapshot_time=index).values.astype(float)
    x = ds["x"].values
    n = len(x)
    values, label = background(i1)
    vmin, vmax, floored = background_range(values)
    if floored:  # rounding, not structure: one grey, the mean
        values = np.where(np.isfinite(values), 0.5 * (vmin + vmax), values)
        label += f": uniform (spread < {UNIFORM:g} of its scale)"
    bg = ax.imshow(
        values.T,
        origin="lower",
        extent=(0, 1, 0, 1),
        cmap="Greys",
        interpolation="nearest",
        label=label,
        vmin=vmin,
        vmax=vmax,
    )
    stride = max(1, n // arrows)
    sl = (slice(stride // 2, None, stride), slice(stride // 2, None, stride))
    S = np.hypot(q1, q2)
    theta = 0.5 * np.arctan2(q2, q1)
    X, Y = np.meshgrid(x, x, indexing="ij")
    Ss = S[sl]
    smax = max(float(S.max()), 1e-12)
    length = Ss / smax
    qv = ax.quiver(
        X[sl],
        Y[sl],
        length * np.cos(theta[sl]),
        length * np.sin(theta[sl]),
        Ss,
        cmap="viridis",
        pivot="middle",
        headwidth=0,
        headlength=0,
        headaxislength=0,
        scale=arrows * 1.1,
        width=0.004,
        clim=(0, smax),
    )
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    t = float(ds["snapshot_time"].values[index])
    ax.set_title(f"t/tau = {t:g}", fontsize=9)
    if colorbar:
        fig = ax.figure
        fig.colorbar(qv, ax=ax, fraction=0.046, pad=0.02, label="S (quivers)")
        background_colorbar(fig, bg, ax=ax, location="bottom", fraction=0.05, pad=0.03)
    return qv


def snapshot_figure(ds: xr.Dataset, path: str | Path, index: int = -1) -> Path:
    """Write a two-panel PNG/PDF: the snapshot and sigma2_S(t)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4.2), gridspec_kw={"width_ratios": [1.35, 1]})
    draw_snapshot(ax, ds, index)
    ax2.plot(series_time(ds).values, ds["sigma2_S"].values, color="C3")
    ax2.set_xlabel("t / tau")
    ax2.set_ylabel(r"$\sigma^2_S$")
    amb = ds.attrs.get("param_alpha_minus_B", float("nan"))
    ax2.set_title(
        f"alpha - B = {amb:g}, seed {ds.attrs.get('seed')}, {ds.attrs.get('num_mechanics')}",
        fontsize=9,
    )
    status = ds.attrs.get("status", "ok")
    if status != "ok":
        ax2.text(
            0.02,
            0.95,
            f"FAILED: {ds.attrs.get('reason')}",
            transform=ax2.transAxes,
            color="red",
            va="top",
        )
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
