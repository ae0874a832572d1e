"""A run's snapshot drawn like the paper's Fig. 2a: director quivers coloured by S over an
I1bar = tr C / J background. Reads only a run Dataset (as written by ``model.simulate.run``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr


def draw_snapshot(ax, ds: xr.Dataset, index: int = -1, *, arrows: int = 32,
                  colorbar: bool = True):
    """Draw snapshot ``index`` of ``ds`` on a matplotlib axes; returns the quiver artist."""
    q1 = ds["q1"].isel(snapshot_time=index).values.astype(float)
    q2 = ds["q2"].isel(snapshot_time=index).values.astype(float)
    i1 = ds["I1bar"].isel(snapshot_time=index).values.astype(float)
    x = ds["x"].values
    n = len(x)
    bg = ax.imshow(i1.T, origin="lower", extent=(0, 1, 0, 1), cmap="Greys",
                   interpolation="nearest")
    stride = max(1, n // arrows)
    sl = (slice(stride // 2, None, stride), slice(stride // 2, None, stride))
    S = np.hypot(q1, q2)
    theta = 0.5 * np.arctan2(q2, q1)
    X, Y = np.meshgrid(x, x, indexing="ij")
    Ss = S[sl]
    smax = max(float(S.max()), 1e-12)
    length = Ss / smax
    qv = ax.quiver(X[sl], Y[sl], length * np.cos(theta[sl]), length * np.sin(theta[sl]), Ss,
                   cmap="viridis", pivot="middle", headwidth=0, headlength=0,
                   headaxislength=0, scale=arrows * 1.1, width=0.004, clim=(0, smax))
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
        fig.colorbar(bg, ax=ax, location="bottom", fraction=0.05, pad=0.03,
                     label=r"$\bar I_1 = \mathrm{tr}\,C / J$ (background)")
    return qv


def snapshot_figure(ds: xr.Dataset, path: str | Path, index: int = -1) -> Path:
    """Write a two-panel PNG/PDF: the snapshot and sigma2_S(t)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4.2),
                                  gridspec_kw={"width_ratios": [1.35, 1]})
    draw_snapshot(ax, ds, index)
    ax2.plot(ds["time"].values, ds["sigma2_S"].values, color="C3")
    ax2.set_xlabel("t / tau")
    ax2.set_ylabel(r"$\sigma^2_S$")
    amb = ds.attrs.get("param_alpha_minus_B", float("nan"))
    ax2.set_title(f"alpha - B = {amb:g}, seed {ds.attrs.get('seed')}, "
                  f"{ds.attrs.get('num_mechanics')}", fontsize=9)
    status = ds.attrs.get("status", "ok")
    if status != "ok":
        ax2.text(0.02, 0.95, f"FAILED: {ds.attrs.get('reason')}", transform=ax2.transAxes,
                 color="red", va="top")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
