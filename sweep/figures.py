r"""The paper's figures from a campaign's results: ``results/<name>/figures/<fig>.{png,pdf}``.

Every figure reads only results files: ``phase.nc``, ``fits.nc`` (written just before by
:func:`regenerate` from the fits the figure needs, :mod:`sweep.fits`) and run files
``runs/<run_id>.nc`` (time series and snapshots). Registered figures (:data:`REGISTRY`; a
campaign lists them under ``figures:``, options as ``{name: {option: value}}``):

``fig2`` (paper Fig. 2)
    (a) a snapshot, director quivers coloured by S over an :math:`\bar I_1` background
    (:func:`sweep.snapshot_plot.draw_snapshot`); (b) :math:`\sigma^2_S(t)` for several
    :math:`\alpha - B` (one seed); (c) :math:`\sigma^2_S(t_{\rm final})` vs :math:`\alpha - B`:
    seed mean with standard-deviation error bars, every seed, the fitted transition and its
    interval, the snapshot's run circled in red. Options: ``select`` ({dim: value} for other
    sweep dims, default their first value), ``seed`` (panel b), ``curves`` (at most this many
    curves in b, default 8), ``snapshot`` ({alpha_minus_B, seed, time}; default the first
    patterned point above the transition, the last snapshot).
``fig3`` (paper Fig. 3)
    :math:`\lambda` (at the first peak of :math:`\sigma^2_S`) vs
    :math:`K/(\alpha - B - \alpha^{cr})` on log-log axes, seed mean and standard deviation per
    point coloured by K, the fitted power law with its exponent and bootstrap interval in the
    legend, the slope-1/2 reference of Eq. (7); inset :math:`\alpha^{cr}(K)` with its interval
    (and the :math:`\sigma^2_S` jump's interval for comparison when fitted), K whose
    :math:`\alpha^{cr}` is at its bound (0) circled and counted in the fit's legend entry.
    Runs whose first peak was not reached by :math:`t_{\rm final}` are left out by the fits
    (:mod:`sweep.fits`); the title says how many.
``fig4`` (paper Fig. 4)
    (a) the phase diagram over the swept ones of :math:`\chi(\alpha - B)`, K and
    :math:`\varepsilon` (3-D when all three are swept): colour :math:`\langle\cos 2\theta\rangle`,
    marker size :math:`\sigma^2_S` (seed means); (b) the caption's four representative
    snapshots (nearest grid points; option ``snapshots``: a list of {dim: value});
    (c) when :math:`\varepsilon` is swept, :math:`\langle\cos 2\theta\rangle` vs
    :math:`\varepsilon` with the fitted slopes (``anisotropy`` fit).
``figA1`` (paper Fig. A1)
    stable / unstable runs in the :math:`(\chi(\alpha - B), \varepsilon)` plane (``stability``
    fit) with the linear-stability boundary (docs/stability.md Eq. S10) and, dashed, the
    paper's Eq. (6) as printed.

Use :func:`regenerate` (``nematic figures CAMPAIGN.yaml``, and at the end of ``nematic run``).
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import xarray as xr

from model.errors import NematicError

from . import fits as F
from .spec import AMB, Campaign
from .store import atomic_path, series_time

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

log = logging.getLogger(__name__)

FIGURES = "figures"
FORMATS = ("png", "pdf")
PNG_DPI = 160
#: The representative snapshots of the Fig. 4 caption (alpha - B = 1 there).
FIG4_SNAPSHOTS: tuple[dict[str, float], ...] = (
    {"K": 1e-6, "chi": 0.0, "eps": 0.0},
    {"K": 1e-6, "chi": 5.0, "eps": 0.0},
    {"K": 1e-6, "chi": 5.0, "eps": 0.05},
    {"K": 1e-2, "chi": 0.0, "eps": 0.05},
)
LABELS = {
    AMB: r"$\alpha - B$", "alpha": r"$\alpha$", "B": r"$B$", "K": r"$K$", "chi": r"$\chi$",
    "eps": r"$\epsilon$", "sigma2_S": r"$\sigma^2_S$", "cos2theta": r"$\langle\cos 2\theta\rangle$",
    "activity": r"$\chi(\alpha - B)$",
}
STYLE = {
    "font.size": 9, "axes.titlesize": 10, "axes.labelsize": 10, "legend.fontsize": 8,
    "xtick.labelsize": 8.5, "ytick.labelsize": 8.5, "legend.framealpha": 0.85,
    "axes.grid": False,
}


class FigureError(NematicError, ValueError):
    """A figure cannot be drawn from these results (missing axis, fit or file; bad option)."""


# --------------------------------------------------------------------------- reading results
class Results:
    """The results folder of one campaign, read-only: phase.nc, fits.nc and the run files."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        try:
            self.phase = F.load_phase(self.root)
        except F.FitError as e:
            raise FigureError(str(e)) from None
        self.fits = F.load_fits(self.root)
        self._runs: dict[str, xr.Dataset | None] = {}

    @property
    def name(self) -> str:
        return str(self.phase.attrs.get("campaign", self.root.name))

    def run(self, run_id: str) -> xr.Dataset | None:
        """``runs/<run_id>.nc`` loaded into memory (cached), or ``None`` if it is missing."""
        if run_id not in self._runs:
            path = self.root / "runs" / f"{run_id}.nc"
            try:
                with xr.open_dataset(path) as ds:
                    self._runs[run_id] = ds.load()
            except (OSError, ValueError) as e:
                log.warning("cannot read run file %s: %s", path, e)
                self._runs[run_id] = None
        return self._runs[run_id]

    def fit(self, *names: str) -> xr.Dataset:
        """The fits Dataset, checked to hold every variable in ``names``."""
        missing = [n for n in names if n not in self.fits]
        if missing:
            raise FigureError(f"{self.root / F.FITS} has no {', '.join(missing)}: "
                              "run `nematic figures` (it writes the fits first)")
        return self.fits


def _point(ds: xr.Dataset, where: Mapping[str, Any]) -> xr.Dataset:
    """``ds`` at the nearest grid values of ``where`` (names absent from ``ds`` are ignored)."""
    for name, value in where.items():
        if name in ds.coords and ds[name].ndim == 1:
            ds = F.with_dim(ds, name).sel({name: value}, method="nearest")
    return ds


def _ok_run(res: Results, point: xr.Dataset, seed: int | None = None
            ) -> tuple[xr.Dataset | None, int | None]:
    """The run file of ``point`` (a phase.nc slice over seeds) for ``seed`` or the first seed
    that succeeded (and has snapshots)."""
    seeds = point["seed"].values
    order = list(range(seeds.size))
    if seed is not None:
        order = [i for i in order if int(seeds[i]) == int(seed)] + order
    for i in order:
        if int(point["status"].values[i]) != 1:
            continue
        run = res.run(str(point["run_id"].values[i]))
        if run is not None:
            return run, int(seeds[i])
    return None, None


def _fmt(value: float) -> str:
    if not math.isfinite(value):
        return "nan"
    return f"{value:.3g}"


def _fmt_sci(value: float) -> str:
    """``1e-06`` -> ``10^{-6}`` (mathtext), other numbers with 3 significant digits."""
    if value != 0 and math.isfinite(value):
        e = math.log10(abs(value))
        if abs(e - round(e)) < 1e-9 and abs(e) >= 3:
            return rf"$10^{{{int(round(e))}}}$"
        if abs(e) >= 3:
            m, ex = f"{value:.2e}".split("e")
            return rf"${float(m):g}\times10^{{{int(ex)}}}$"
    return f"{value:.3g}"


def _describe(ds: xr.Dataset, names: Sequence[str]) -> str:
    parts = []
    for n in names:
        if n in ds.coords and ds[n].ndim == 0:
            parts.append(f"{LABELS.get(n, n)} = {_fmt_sci(float(ds[n]))}")
    return ", ".join(parts)


def _default_select(ds: xr.Dataset, keep: Sequence[str], choice: Mapping[str, Any] | None
                    ) -> xr.Dataset:
    """``ds`` with every sweep dim except ``keep`` fixed: ``choice`` or its first value."""
    ds = F.select(ds, choice)
    for d in F.sweep_dims(ds):
        if d not in keep:
            ds = ds.isel({d: 0})
    return ds


def _safe_snapshot(ax: Axes, run: xr.Dataset, index: int = -1, *, colorbar: bool = True,
                   arrows: int = 24) -> None:
    """:func:`sweep.snapshot_plot.draw_snapshot` (without its title), tolerating a run without
    I1bar stored (then a plain background), with compact colour bars: S (quivers) on the
    right, I1bar (background) below."""
    from matplotlib.ticker import MaxNLocator

    from .snapshot_plot import background_colorbar, draw_snapshot

    if run.sizes.get("snapshot_time", 0) == 0 or "q1" not in run or "q2" not in run:
        ax.text(0.5, 0.5, "no snapshot stored", ha="center", va="center",
                transform=ax.transAxes)
        ax.set_xticks([])
        ax.set_yticks([])
        return
    has_i1 = "I1bar" in run
    if not has_i1:
        run = run.assign(I1bar=xr.zeros_like(run["q1"]) + 2.0)
    quiver = draw_snapshot(ax, run, index, colorbar=False, arrows=arrows)
    ax.set_title("")
    if not colorbar:
        return
    fig = ax.figure
    cb = fig.colorbar(quiver, cax=ax.inset_axes((1.03, 0.1, 0.045, 0.8)))
    cb.set_label("S (quivers)")
    cb.locator = MaxNLocator(5)
    cb.update_ticks()
    if has_i1 and ax.images:
        background_colorbar(fig, ax.images[0], cax=ax.inset_axes((0.1, -0.09, 0.8, 0.04)),
                            orientation="horizontal")


# --------------------------------------------------------------------------- fig2
def fig2(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. 2 (module docstring)."""
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    _check_options("fig2", options)
    yscale = str(options.get("yscale", "linear"))
    if not F.is_swept(res.phase, AMB):
        raise FigureError("fig2 needs alpha_minus_B (or alpha) as a sweep axis")
    ds = F.with_dim(res.phase, AMB)
    others = [d for d in F.sweep_dims(ds) if d != AMB]
    ds = _default_select(ds, [AMB], options.get("select"))
    x = ds[AMB].values.astype(float)
    where = _describe(ds, others)

    trans = _transition_row(res, ds, others)
    snap_opt = dict(options.get("snapshot") or {})
    snap_amb = snap_opt.get(AMB)
    if snap_amb is None:
        mean = ds["sigma2_S_mean"].values
        if trans is not None and math.isfinite(trans["upper"]):
            above = [(i, v) for i, v in enumerate(x) if v >= trans["upper"] - 1e-12
                     and np.isfinite(mean[i])]
            snap_amb = above[0][1] if above else None
        if snap_amb is None and np.any(np.isfinite(mean)):
            snap_amb = x[int(np.nanargmax(np.where(np.isfinite(mean), mean, -np.inf)))]
    snap_run, snap_seed = (None, None)
    snap_point = None
    if snap_amb is not None:
        snap_point = ds.sel({AMB: snap_amb}, method="nearest")
        snap_run, snap_seed = _ok_run(res, snap_point, snap_opt.get("seed"))

    fig = Figure(figsize=(13.0, 4.3), layout="constrained")
    gs = fig.add_gridspec(1, 3, width_ratios=[1.0, 1.0, 1.0])
    ax_a, ax_b, ax_c = (fig.add_subplot(gs[0, i]) for i in range(3))

    # (a) snapshot
    if snap_run is not None and snap_point is not None:
        index = -1
        if "time" in snap_opt and snap_run.sizes.get("snapshot_time", 0):
            index = int(np.argmin(np.abs(snap_run["snapshot_time"].values
                                         - float(snap_opt["time"]))))
        _safe_snapshot(ax_a, snap_run, index)
        t = (float(snap_run["snapshot_time"].values[index])
             if snap_run.sizes.get("snapshot_time", 0) else math.nan)
        ax_a.set_title(rf"(a) $\alpha - B$ = {_fmt(float(snap_point[AMB]))}, seed {snap_seed},"
                       rf" $t/\tau$ = {t:g}", loc="left")
    else:
        ax_a.text(0.5, 0.5, "no successful run to draw", ha="center", va="center",
                  transform=ax_a.transAxes)
        ax_a.set_title("(a)", loc="left")

    # (b) sigma2_S(t) for several alpha - B
    n_curves = int(options.get("curves", 8))
    picks = np.unique(np.round(np.linspace(0, x.size - 1, min(n_curves, x.size))).astype(int))
    cmap = colormaps["viridis"]
    seed_b = options.get("seed")
    drawn_seed = None
    for rank, i in enumerate(picks):
        run, s = _ok_run(res, ds.isel({AMB: int(i)}), seed_b if seed_b is not None
                         else drawn_seed)
        if run is None:
            continue
        drawn_seed = s if drawn_seed is None else drawn_seed
        colour = cmap(rank / max(len(picks) - 1, 1))
        times, series = series_time(run).values, run["sigma2_S"].values.astype(float)
        # t = 0 is left out: S = S0 is uniform there (sigma2_S = 0 up to round-off)
        ok = np.isfinite(series) & (series > 0) & (times > 0)
        ax_b.plot(times[ok], series[ok], color=colour, lw=1.4, label=_fmt(float(x[i])))
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
    ax_c.errorbar(x[good], mean[good], yerr=[lower[good], err[good]], fmt="o-", color="k",
                  ms=4.5, lw=1.2, capsize=2.5, label="seed mean ± std", zorder=3)
    if trans is not None and math.isfinite(trans["location"]):
        ax_c.axvspan(trans["lower"], trans["upper"], color="tab:red", alpha=0.12, lw=0,
                     label=(f"jump at {_fmt(trans['location'])} "
                            f"[{_fmt(trans['lower'])}, {_fmt(trans['upper'])}]"))
    if snap_run is not None and snap_point is not None:
        value = float(snap_run["sigma2_S_final"]) if "sigma2_S_final" in snap_run else math.nan
        if math.isfinite(value) and value > 0:
            ax_c.plot([float(snap_point[AMB])], [value], "o", ms=13, mfc="none", mec="red",
                      mew=1.8, zorder=4, label="panel (a)")
    ax_c.set_yscale(yscale)
    if yscale == "linear":
        ax_c.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    ax_c.set_xlabel(r"$\alpha - B$")
    t_final = res.phase.attrs.get("num_t_final")
    ax_c.set_ylabel(rf"$\sigma^2_S$ at $t/\tau$ = {float(t_final):g}" if t_final is not None
                    else r"$\sigma^2_S(t_{\rm final})$")
    ax_c.set_title(f"(c) {int(ds['seed'].size)} seeds", loc="left")
    ax_c.legend(loc="lower right" if yscale == "log" else "best")
    fig.suptitle(f"{res.name}: paper Fig. 2" + (f" ({where})" if where else ""), fontsize=10)
    return fig


def _transition_row(res: Results, ds: xr.Dataset, others: Sequence[str]
                    ) -> dict[str, float] | None:
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


# --------------------------------------------------------------------------- fig3
def fig3(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. 3 (module docstring)."""
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.figure import Figure

    _check_options("fig3", options)
    f = res.fit("scaling_x", "scaling_lambda_mean", "scaling_exponent", "alpha_cr")
    K = f["K"].values.astype(float)
    xgrid = f["scaling_x"].transpose("K", AMB).values
    lam = f["scaling_lambda_mean"].transpose("K", AMB).values
    lam_sd = f["scaling_lambda_std"].transpose("K", AMB).values
    used = f["scaling_used"].transpose("K", AMB).values.astype(bool)
    beta = float(f["scaling_exponent"])
    lo, hi = float(f["scaling_exponent_lower"]), float(f["scaling_exponent_upper"])
    pref = float(f["scaling_prefactor"])
    acr = f["alpha_cr"].values
    amb = f[AMB].values.astype(float)
    at_bound = (f["alpha_cr_at_bound"].values.astype(bool) if "alpha_cr_at_bound" in f
                else np.zeros(K.size, dtype=bool))
    bound = f["alpha_cr"].attrs.get("fit_alpha_cr_min", 0.0)
    n_unpeaked = int(f["alpha_cr"].attrs.get("fit_n_unpeaked", 0))
    n_patterned = int(f["alpha_cr"].attrs.get("fit_n_patterned", 0))

    fig = Figure(figsize=(6.4, 5.0), layout="constrained")
    ax = fig.add_subplot()
    norm = (LogNorm(K.min(), K.max()) if K.size > 1 and K.min() > 0
            else Normalize(K.min() - 1, K.max() + 1))
    cmap = colormaps["viridis"]
    for i, k in enumerate(K):
        colour = cmap(0.9 * norm(k))
        u = used[i]
        if np.any(u):
            err = np.where(np.isfinite(lam_sd[i]), lam_sd[i], 0.0)
            ax.errorbar(xgrid[i][u], lam[i][u], yerr=err[u], fmt="o", color=colour, ms=5,
                        capsize=2.5, lw=1.1, label=rf"$K$ = {_fmt_sci(k)}")
        rest = ~u & np.isfinite(xgrid[i]) & np.isfinite(lam[i])
        if np.any(rest):
            ax.plot(xgrid[i][rest], lam[i][rest], "o", mfc="none", mec=colour, ms=5)
        if not np.isfinite(acr[i]) and np.any(np.isfinite(lam[i])):
            # no alpha_cr at this K: show the sizes against K / (alpha - B) instead
            fallback = k / amb
            ok = np.isfinite(lam[i]) & (fallback > 0)
            ax.plot(fallback[ok], lam[i][ok], "^", mfc="none", mec=colour, ms=6,
                    label=rf"$K$ = {_fmt_sci(k)}: no $\alpha^{{cr}}$, $x = K/(\alpha - B)$")
    xu = xgrid[used]
    if xu.size and math.isfinite(beta):
        xs = np.geomspace(xu.min() / 1.3, xu.max() * 1.3, 50)
        bound_note = ("\n" + rf"$\alpha^{{cr}}$ at its bound {_fmt(float(bound))} for "
                      f"{int(at_bound.sum())} of {K.size} K" if np.any(at_bound) else "")
        ax.plot(xs, pref * xs**beta, "k-", lw=1.5,
                label=(rf"fit: $\lambda \propto x^{{\beta}}$, $\beta$ = {beta:.3f} "
                       f"[{lo:.3f}, {hi:.3f}]" + bound_note))
        gx = float(np.exp(np.mean(np.log(xu))))
        gy = float(np.exp(np.mean(np.log(lam[used]))))
        ax.plot(xs, 0.75 * gy * (xs / gx) ** 0.5, "--", color="0.35", lw=1.3,
                label="slope 1/2 (paper Eq. 7)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"$K/(\alpha - B - \alpha^{cr})$")
    ax.set_ylabel(r"pattern size $\lambda$ at the first peak of $\sigma^2_S$ ($L$)")
    n_seeds = int(res.phase.sizes.get("seed", 0))
    left_out = (f"\n{n_unpeaked} of {n_patterned} patterned runs left out: first peak of "
                r"$\sigma^2_S$ not reached by $t_{\rm final}$" if n_unpeaked else "")
    ax.set_title(f"{res.name}: paper Fig. 3 (mean ± std over {n_seeds} seeds; "
                 f"{int(f['scaling_exponent'].attrs.get('fit_confidence', 0.95) * 100)}% "
                 "bootstrap interval)" + left_out, fontsize=9)
    ys = [line.get_ydata() for line in ax.lines]
    yall = np.concatenate([np.asarray(y, dtype=float) for y in ys]) if ys else np.array([])
    yall = yall[np.isfinite(yall) & (yall > 0)]
    if yall.size:  # room below the data (which rise to the right) for the inset
        top, bottom = float(yall.max()), float(yall.min())
        span = max(top / bottom, 1.5)
        ax.set_ylim(bottom / span**0.75, top * span**0.3)  # and above it for the legend
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", fontsize=7.5)
    else:
        ax.text(0.5, 0.5, "no patterned run", ha="center", va="center", transform=ax.transAxes)

    # inset: alpha_cr(K)
    ins = ax.inset_axes((0.6, 0.09, 0.36, 0.3))
    alo, ahi = f["alpha_cr_lower"].values, f["alpha_cr_upper"].values
    okk = np.isfinite(acr)
    if np.any(okk):
        yerr = np.array([np.where(np.isfinite(alo), acr - alo, 0.0),
                         np.where(np.isfinite(ahi), ahi - acr, 0.0)])[:, okk]
        ins.errorbar(K[okk], acr[okk], yerr=np.maximum(yerr, 0.0), fmt="s-", color="tab:blue",
                     ms=4, capsize=2, lw=1, label=r"from $\lambda$")
        if np.any(at_bound & okk):
            ins.axhline(float(bound), color="0.6", lw=0.8, ls=":")
            ins.plot(K[at_bound & okk], acr[at_bound & okk], "o", mfc="none", mec="tab:red",
                     ms=8, mew=1.2, label=f"at bound ({_fmt(float(bound))})")
    if ("transition_location" in f and "K" in f["transition_location"].dims
            and f["transition_location"].attrs.get("fit_axis", AMB) == AMB):
        tl = f["transition_location"].sel(K=K, method="nearest").values
        tlo = f["transition_lower"].sel(K=K, method="nearest").values
        thi = f["transition_upper"].sel(K=K, method="nearest").values
        okt = np.isfinite(tl)
        if np.any(okt):
            ins.errorbar(K[okt] * 1.08, tl[okt], yerr=[tl[okt] - tlo[okt], thi[okt] - tl[okt]],
                         fmt="o", color="0.5", ms=3, capsize=2, lw=0.9,
                         label=r"$\sigma^2_S$ jump")
    if K.size > 1 and K.min() > 0:
        from matplotlib.ticker import FixedLocator, NullFormatter

        ins.set_xscale("log")
        ins.xaxis.set_minor_formatter(NullFormatter())
        if K.size <= 5:
            ins.xaxis.set_major_locator(FixedLocator(K.tolist()))
            ins.set_xticklabels([_fmt_sci(k) for k in K])
    ins.set_xlabel(r"$K$", fontsize=8, labelpad=1)
    ins.set_ylabel(r"$\alpha^{cr}$", fontsize=8, labelpad=1)
    ins.tick_params(labelsize=7)
    if ins.lines or ins.collections:
        ins.legend(fontsize=6.5, loc="best", handlelength=1.2)
    else:
        ins.remove()
    return fig


# --------------------------------------------------------------------------- fig4
def _activity(ds: xr.Dataset) -> tuple[str | None, float]:
    """The sweep dim that carries the activity chi (alpha - B) and its scale factor."""
    if F.is_swept(ds, "chi"):
        if F.is_swept(ds, AMB):
            raise FigureError("both chi and alpha - B are swept: fix one with the option "
                              "select: {alpha_minus_B: VALUE}")
        return "chi", F.fixed_parameter(ds, AMB) or 1.0
    if F.is_swept(ds, AMB):
        return AMB, F.fixed_parameter(ds, "chi") or 1.0
    return None, 1.0


def _sizes(values: np.ndarray, vmax: float, smin: float = 8.0, smax: float = 260.0
           ) -> np.ndarray:
    v = np.where(np.isfinite(values) & (values > 0), values, 0.0)
    return smin + (smax - smin) * np.sqrt(v / vmax) if vmax > 0 else np.full(v.shape, smin)


def fig4(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. 4 (module docstring)."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401 - registers the 3-D projection

    _check_options("fig4", options)
    ds = F.select(res.phase, options.get("select"))
    act, scale = _activity(ds)
    axes = [a for a in (act, "K", "eps") if a is not None and F.is_swept(ds, a)]
    if len(axes) < 2:
        raise FigureError("fig4 needs at least two of chi (or alpha - B), K and eps swept "
                          f"(swept: {', '.join(F.sweep_dims(ds)) or 'none'})")
    if act is not None and act not in ds.coords:
        ds = F.with_dim(ds, act)  # alpha - B from a swept alpha or B
    # sweep dims that carry none of the axes (zip groups carry several) are fixed
    carried = {str(ds[a].dims[0]) for a in axes}
    ds = _default_select(ds, sorted(carried), None)
    dims = F.sweep_dims(ds)
    ref = ds["sigma2_S_mean"].transpose(*dims)
    coords = [ds[a].broadcast_like(ref).transpose(*dims).values.astype(float).ravel()
              for a in axes]
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
    vmax = float(np.nanmax(np.where(np.isfinite(sig), sig, np.nan))) if np.any(
        np.isfinite(sig)) else 0.0
    lim = float(np.nanmax(np.abs(cos))) if np.any(np.isfinite(cos)) else 1.0
    lim = max(lim, 0.05)
    norm = Normalize(-lim, lim)
    cmap = colormaps["coolwarm"]
    has_eps = "eps" in axes and "eps" in ds.dims  # panel (c) needs eps as its own dim

    fig = Figure(figsize=(16.0 if has_eps else 12.5, 6.2), layout="constrained")
    gs = fig.add_gridspec(2, 4 if has_eps else 3,
                          width_ratios=[2.3, 1, 1, 1.45][: 4 if has_eps else 3])
    three_d = len(axes) == 3
    ax: Any = fig.add_subplot(gs[:, 0], projection="3d" if three_d else None)
    finite = np.isfinite(cos)
    size = _sizes(sig, vmax)
    colours = np.where(finite[:, None], cmap(norm(np.where(finite, cos, 0.0))), (0.7,) * 4)
    if three_d:
        ax.scatter(*plot_vals, s=size, c=colours, edgecolors="k", linewidths=0.4,
                   depthshade=False)
        ax.set_zlabel(labels[axes[2]], labelpad=2)
        ax.view_init(elev=22, azim=-58)
    else:
        ax.scatter(*plot_vals, s=size, c=colours, edgecolors="k", linewidths=0.4)
        ax.margins(0.1)
    ax.set_xlabel(labels[axes[0]])
    ax.set_ylabel(labels[axes[1]])
    ax.set_title("(a) colour: " + LABELS["cos2theta"] + r", size: $\sigma^2_S$", loc="left")
    from matplotlib.cm import ScalarMappable

    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.7, pad=0.1 if three_d
                 else 0.02, label=LABELS["cos2theta"])
    if vmax > 0:
        refs = [vmax * f for f in (1.0, 0.25, 0.02)]
        handles = [ax.scatter([], [], s=float(_sizes(np.array([r]), vmax)[0]), c="0.6",
                              edgecolors="k", linewidths=0.4) for r in refs]
        ax.legend(handles, [f"{r:.2g}" for r in refs], title=r"marker size: $\sigma^2_S$",
                  loc="upper center", bbox_to_anchor=(0.5, -0.1 if three_d else -0.09),
                  ncol=3, fontsize=8, borderpad=0.8, columnspacing=2.5)

    # (b) representative snapshots
    targets = list(options.get("snapshots") or FIG4_SNAPSHOTS)[:4]
    seen: list[tuple[float, ...]] = []
    slots = [gs[0, 1], gs[0, 2], gs[1, 1], gs[1, 2]]
    for n, target in enumerate(targets, start=1):
        if not isinstance(target, Mapping):
            raise FigureError(f"fig4: snapshots[{n - 1}] = {target!r}; expected a mapping "
                              "{dim: value}")
        point = _point(ds, {k: v for k, v in target.items() if k in axes})
        key = tuple(float(point[a]) for a in axes)
        sub = fig.add_subplot(slots[n - 1])
        run, seed = _ok_run(res, point)
        title = ", ".join(f"{LABELS.get(a, a)}={_fmt_sci(float(point[a]))}" for a in axes)
        if run is None:
            sub.text(0.5, 0.5, "no successful run", ha="center", va="center",
                     transform=sub.transAxes)
            sub.set_xticks([])
            sub.set_yticks([])
        else:
            _safe_snapshot(sub, run, -1, colorbar=False, arrows=20)
        sub.set_title(f"({n}) {title}", fontsize=8)
        if key not in seen:
            seen.append(key)
            vals = [float(point[a]) * (scale if a == act else 1.0) if a != "K"
                    else math.log10(max(float(point[a]), 1e-300)) for a in axes]
            if three_d:
                ax.text(*vals, f" {n}", fontsize=9, fontweight="bold")
            else:
                ax.annotate(str(n), (vals[0], vals[1]), textcoords="offset points", xytext=(6, 6),
                            fontsize=9, fontweight="bold")

    # (c) anisotropy trend
    if has_eps:
        axc = fig.add_subplot(gs[:, 3])
        _anisotropy_panel(axc, res, ds, axes, act, scale)
    fig.suptitle(f"{res.name}: paper Fig. 4" + (
        f" (alpha - B = {_fmt(F.fixed_parameter(ds, AMB) or math.nan)})"
        if act == "chi" else ""), fontsize=10)
    return fig


def _anisotropy_panel(ax: Axes, res: Results, ds: xr.Dataset, axes: Sequence[str],
                      act: str | None, scale: float) -> None:
    from matplotlib import colormaps

    others = [d for d in F.sweep_dims(ds) if d != "eps"]  # dims (a zip dim carries several)
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
        label = ", ".join(
            f"{LABELS['activity'] if a == act else LABELS.get(a, a)}="
            f"{_fmt_sci(float(point[a]) * (scale if a == act else 1.0))}" for a in shown
            if a in point.coords and point[a].ndim == 0)
        if slope is not None and all(d in point.coords for d in slope.dims):
            sv = slope.sel({d: float(point[d]) for d in slope.dims}, method="nearest")
            if sv.ndim == 0:
                label += f"; slope {_fmt(float(sv))}"
        ax.errorbar(eps, m, yerr=np.where(np.isfinite(s), s, 0.0), fmt="o-", ms=3.5, lw=1,
                    capsize=2, color=cmap(0.85 * n / max(len(combos) - 1, 1)), label=label)
    ax.axhline(0.0, color="0.6", lw=0.7)
    ax.set_xlabel(r"$\epsilon$")
    ax.set_ylabel(LABELS["cos2theta"])
    ax.set_title("(c) anisotropy vs applied strain", loc="left")
    ax.legend(fontsize=6.5, loc="best")


# --------------------------------------------------------------------------- figA1
def _ran(phase: xr.Dataset, act: str, strain: str, shape: tuple[int, ...]) -> np.ndarray:
    """Whether any seed was run at each (activity, strain) point (from phase.nc's
    ``seed_count`` where a refined campaign wrote it; every point otherwise)."""
    if "seed_count" not in phase:
        return np.ones(shape, dtype=bool)
    try:
        count = F.with_dim(F.with_dim(phase, act), strain)["seed_count"]
        ran = (count > 0).transpose(act, strain).values
    except (KeyError, ValueError, F.FitError):
        return np.ones(shape, dtype=bool)
    return ran if ran.shape == shape else np.ones(shape, dtype=bool)


def figA1(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. A1 (module docstring)."""
    from matplotlib.figure import Figure

    _check_options("figA1", options)
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
    ax.scatter(A[stable], E[stable], s=30, facecolors="none", edgecolors="tab:blue", lw=1.1,
               label="stable", zorder=3)
    ax.scatter(A[unstable], E[unstable], s=30, color="tab:red", label="unstable", zorder=3)
    if np.any(mixed):
        ax.scatter(A[mixed], E[mixed], s=30, color="tab:purple", marker="D",
                   label="seeds disagree", zorder=3)
    if np.any(unknown):
        ax.scatter(A[unknown], E[unknown], s=25, color="0.6", marker="x", label="no data",
                   zorder=3)
    fine = f["activity_fine"].values * scale
    th = f["stability_theory_fine"].values
    ax.plot(fine, th, "-", color="tab:orange", lw=2.2,
            label="linear stability (docs/stability.md S10)")
    if "stability_paper_fine" in f:
        ax.plot(fine, f["stability_paper_fine"].values, "--", color="0.45", lw=1.2,
                label="paper Eq. (6) as printed")
    ax.set_ylim(e.min() - 0.04 * max(np.ptp(e), 1e-3), e.max() + 0.04 * max(np.ptp(e), 1e-3))
    ax.set_xlim(a.min() - 0.03 * max(np.ptp(a), 1e-3), a.max() + 0.03 * max(np.ptp(a), 1e-3))
    ax.set_xlabel(LABELS["activity"])
    ax.set_ylabel(r"applied strain $\epsilon$")
    mech = str(attrs.get("fit_mechanics", ""))
    inc = "incompressible" if int(attrs.get("fit_incompressible", 0)) else "compressible"
    n_seeds = int(res.phase.sizes.get("seed", 0))
    ax.set_title(f"{res.name}: paper Fig. A1 ({mech} mechanics, {inc}; {n_seeds} "
                 f"seed{'s' if n_seeds != 1 else ''})", fontsize=9)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=8)
    return fig


# --------------------------------------------------------------------------- registry
FigureFunction = Callable[[Results, Mapping[str, Any]], "Figure"]


def _swept_all(*names: str) -> Callable[[xr.Dataset], bool]:
    return lambda phase: all(F.is_swept(phase, n) for n in names)


def _fig4_applies(phase: xr.Dataset) -> bool:
    n = sum(F.is_swept(phase, a) for a in ("chi", "K", "eps"))
    return n >= 2 and str(phase.attrs.get("num_mechanics", "finite")) == "finite"


def _figA1_applies(phase: xr.Dataset) -> bool:
    return (F.is_swept(phase, "eps") and (F.is_swept(phase, "chi") or F.is_swept(phase, AMB))
            and str(phase.attrs.get("num_mechanics", "")) == "linear")


@dataclass(frozen=True)
class FigureSpec:
    """A registered figure: how to draw it, which fits it needs, when it applies."""

    function: FigureFunction
    description: str
    fits: Callable[[xr.Dataset], list[tuple[str, dict[str, Any]]]]
    applies: Callable[[xr.Dataset], bool] = field(default=lambda phase: True)
    options: tuple[str, ...] = ()


def _fig2_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("transition", {"axis": AMB})]


def _fig3_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("scaling", {}), ("transition", {"axis": AMB})]


def _fig4_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("anisotropy", {})] if F.is_swept(phase, "eps") else []


def _figA1_fits(phase: xr.Dataset) -> list[tuple[str, dict[str, Any]]]:
    return [("stability", {})]


REGISTRY: dict[str, FigureSpec] = {
    "fig2": FigureSpec(fig2, "snapshot, sigma2_S(t) and sigma2_S(t_final) vs alpha - B",
                       _fig2_fits, _swept_all(AMB),
                       ("select", "seed", "curves", "snapshot", "yscale")),
    "fig3": FigureSpec(fig3, "pattern size vs K / (alpha - B - alpha_cr), inset alpha_cr(K)",
                       _fig3_fits, _swept_all(AMB, "K")),
    "fig4": FigureSpec(fig4, "phase diagram over chi (alpha - B), K, eps with snapshots",
                       _fig4_fits, _fig4_applies, ("select", "snapshots")),
    "figA1": FigureSpec(figA1, "stable/unstable runs in (chi (alpha - B), eps) and the "
                        "linear-stability boundary", _figA1_fits, _figA1_applies),
}


def option_problems(name: str, options: Mapping[str, Any]) -> list[str]:
    """What is wrong with the options of registered figure ``name`` (empty if nothing), for
    validating a campaign before it runs."""
    if name not in REGISTRY:
        return [f"unknown figure {name!r}; registered: {', '.join(sorted(REGISTRY))}"]
    allowed = REGISTRY[name].options
    out = [f"unknown option {key!r}; allowed: {', '.join(allowed) or 'none'}"
           for key in options if key not in allowed]
    if name == "fig2" and options.get("yscale", "linear") not in ("linear", "log"):
        out.append(f"yscale = {options['yscale']!r}; expected 'linear' or 'log'")
    for key in ("select", "snapshot"):
        if options.get(key) is not None and not isinstance(options[key], Mapping):
            out.append(f"{key} = {options[key]!r}; expected a mapping {{sweep axis: value}}")
    snaps = options.get("snapshots")
    if snaps is not None and (not isinstance(snaps, Sequence) or isinstance(snaps, str)
                              or not all(isinstance(t, Mapping) for t in snaps)):
        out.append(f"snapshots = {snaps!r}; expected a list of mappings {{sweep axis: value}}")
    return out


def _check_options(name: str, options: Mapping[str, Any]) -> None:
    problems = option_problems(name, options)
    if problems:
        raise FigureError(f"figure {name!r}: " + "; ".join(problems))


# --------------------------------------------------------------------------- writing
@contextlib.contextmanager
def _style() -> Iterator[None]:
    import matplotlib as mpl

    with mpl.rc_context(cast(Any, STYLE)), np.errstate(all="ignore"):
        yield


def save_figure(fig: Figure, folder: Path, name: str) -> list[Path]:
    """Write ``folder/name.png`` and ``.pdf`` atomically; return the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in FORMATS:
        path = folder / f"{name}.{fmt}"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=fmt, dpi=PNG_DPI if fmt == "png" else None,
                        metadata={"Title": f"{name} ({folder.parent.name})"} if fmt == "pdf"
                        else None)
        paths.append(path)
    return paths


def draw(name: str, root: str | Path, options: Mapping[str, Any] | None = None,
         results: Results | None = None) -> list[Path]:
    """Draw registered figure ``name`` from ``root`` (results/<campaign>) into
    ``root/figures/``; return the written paths. Raises :class:`FigureError`."""
    if name not in REGISTRY:
        raise FigureError(f"unknown figure {name!r}; registered: {', '.join(sorted(REGISTRY))}")
    res = results or Results(root)
    with _style():
        fig = REGISTRY[name].function(res, dict(options or {}))
        try:
            return save_figure(fig, res.root / FIGURES, name)
        finally:
            fig.clear()


@dataclass
class Outcome:
    """What :func:`produce` did: the figures it set out to draw, files written, fits and
    figures that failed (name -> why), and caveats about the fits written
    (:func:`sweep.fits.fit_notes`)."""

    paths: list[Path] = field(default_factory=list)
    failures: dict[str, str] = field(default_factory=dict)
    fits_path: Path | None = None
    figures: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def plan(campaign: Campaign, phase: xr.Dataset, names: Sequence[str] | None = None
         ) -> tuple[list[tuple[str, dict[str, Any]]], list[tuple[str, dict[str, Any]]]]:
    """(fits, figures) to produce: the figures named (``names``), else the campaign's
    ``figures:`` list (``figures: []``: none), else (no ``figures:`` key) every registered
    figure that applies to this grid; the campaign's fits first (their options win), then
    the fits those figures need."""
    listed = (None if campaign.figures is None
              else {p.name: dict(p.options) for p in campaign.figures})
    if names:
        unknown = [n for n in names if n not in REGISTRY]
        if unknown:
            raise FigureError(f"unknown figure(s) {', '.join(unknown)}; registered: "
                              f"{', '.join(sorted(REGISTRY))}")
        figures = [(n, (listed or {}).get(n, {})) for n in names]
    elif listed is not None:
        figures = list(listed.items())
    else:
        figures = [(n, {}) for n, spec in REGISTRY.items() if spec.applies(phase)]
    fit_requests: list[tuple[str, dict[str, Any]]] = [(p.name, dict(p.options))
                                                      for p in campaign.fits]
    for n, _ in figures:
        fit_requests.extend(REGISTRY[n].fits(phase))
    return fit_requests, figures


def produce(campaign: Campaign, results_dir: str | Path, *, names: Sequence[str] | None = None,
            fits: bool = True) -> Outcome:
    """Write ``fits.nc`` (unless ``fits`` is false) and the figures of ``campaign`` (see
    :func:`plan`) from ``results_dir/<name>/``. Failures are collected, not raised, except
    for a missing phase.nc (:class:`FigureError`)."""
    root = Path(results_dir) / campaign.name
    try:
        phase = F.load_phase(root)
    except F.FitError as e:
        raise FigureError(str(e)) from None
    fit_requests, figures = plan(campaign, phase, names)
    out = Outcome(figures=[n for n, _ in figures])
    if fits and fit_requests:
        try:
            out.fits_path, failed = F.write_fits(root, fit_requests)
        except NematicError as e:
            failed = {"fits": str(e)}
        except Exception as e:  # noqa: BLE001 - nor may the fits
            failed = {"fits": f"{type(e).__name__}: {e}"}
            log.warning("fits not written", exc_info=True)
        out.failures.update({f"fit {k}": v for k, v in failed.items()})
    if out.fits_path is not None:
        out.notes = F.fit_notes(F.load_fits(root))
    if not figures:  # figures: [] in the campaign
        return out
    results = Results(root)
    for name, options in figures:
        try:
            out.paths.extend(draw(name, root, options, results))
        except NematicError as e:
            out.failures[name] = str(e)
            log.warning("figure %s not drawn: %s", name, e)
        except Exception as e:  # noqa: BLE001 - a figure must never sink the run it follows
            out.failures[name] = f"{type(e).__name__}: {e}"
            log.warning("figure %s not drawn", name, exc_info=True)
    return out


def regenerate(campaign: Campaign, results_dir: str | Path) -> list[Path]:
    """Fits and figures of ``campaign`` after a run (the hook of ``nematic run``): writes
    ``fits.nc`` and ``figures/*.png|pdf`` (none with ``figures: []``); returns the figure
    paths. Never raises for a figure that cannot be drawn (it is logged, as are the fits'
    caveats, :func:`sweep.fits.fit_notes`); returns [] when there is no phase.nc."""
    try:
        out = produce(campaign, results_dir)
    except FigureError as e:
        log.warning("no figures: %s", e)
        return []
    for note in out.notes:
        log.warning("fits: %s", note)
    for name, why in out.failures.items():
        log.warning("%s failed: %s", name, why)
    return out.paths
