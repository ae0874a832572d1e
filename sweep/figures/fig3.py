r"""Paper Fig. 3: the pattern size against K / (alpha - B - alpha_cr) on log-log axes with the
fitted power law; inset alpha_cr(K) (docs/campaigns/figures.md, "Figures")."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..campaign import AMB
from .common import (
    Results,
    check_options,
    fmt,
    fmt_sci,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIG3_OPTIONS: tuple[str, ...] = ()


def fig3(res: Results, options: Mapping[str, Any]) -> Figure:
    """Paper Fig. 3 (docs/campaigns/figures.md)."""
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.figure import Figure

    check_options("fig3", options, FIG3_OPTIONS)
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
    at_bound = (
        f["alpha_cr_at_bound"].values.astype(bool)
        if "alpha_cr_at_bound" in f
        else np.zeros(K.size, dtype=bool)
    )
    bound = f["alpha_cr"].attrs.get("fit_alpha_cr_min", 0.0)
    n_unpeaked = int(f["alpha_cr"].attrs.get("fit_n_unpeaked", 0))
    n_patterned = int(f["alpha_cr"].attrs.get("fit_n_patterned", 0))

    fig = Figure(figsize=(6.4, 5.0), layout="constrained")
    ax = fig.add_subplot()
    norm = (
        LogNorm(K.min(), K.max())
        if K.size > 1 and K.min() > 0
        else Normalize(K.min() - 1, K.max() + 1)
    )
    cmap = colormaps["viridis"]
    for i, k in enumerate(K):
        colour = cmap(0.9 * norm(k))
        u = used[i]
        if np.any(u):
            err = np.where(np.isfinite(lam_sd[i]), lam_sd[i], 0.0)
            ax.errorbar(
                xgrid[i][u],
                lam[i][u],
                yerr=err[u],
                fmt="o",
                color=colour,
                ms=5,
                capsize=2.5,
                lw=1.1,
                label=rf"$K$ = {fmt_sci(k)}",
            )
        rest = ~u & np.isfinite(xgrid[i]) & np.isfinite(lam[i])
        if np.any(rest):
            ax.plot(xgrid[i][rest], lam[i][rest], "o", mfc="none", mec=colour, ms=5)
        if not np.isfinite(acr[i]) and np.any(np.isfinite(lam[i])):
            # no alpha_cr at this K: show the sizes against K / (alpha - B) instead
            fallback = k / amb
            ok = np.isfinite(lam[i]) & (fallback > 0)
            ax.plot(
                fallback[ok],
                lam[i][ok],
                "^",
                mfc="none",
                mec=colour,
                ms=6,
                label=rf"$K$ = {fmt_sci(k)}: no $\alpha^{{cr}}$, $x = K/(\alpha - B)$",
            )
    xu = xgrid[used]
    if xu.size and math.isfinite(beta):
        xs = np.geomspace(xu.min() / 1.3, xu.max() * 1.3, 50)
        bound_note = (
            "\n" + rf"$\alpha^{{cr}}$ at its bound {fmt(float(bound))} for "
            f"{int(at_bound.sum())} of {K.size} K"
            if np.any(at_bound)
            else ""
        )
        ax.plot(
            xs,
            pref * xs**beta,
            "k-",
            lw=1.5,
            label=(
                rf"fit: $\lambda \propto x^{{\beta}}$, $\beta$ = {beta:.3f} "
                f"[{lo:.3f}, {hi:.3f}]" + bound_note
            ),
        )
        gx = float(np.exp(np.mean(np.log(xu))))
        gy = float(np.exp(np.mean(np.log(lam[used]))))
        ax.plot(
            xs,
            0.75 * gy * (xs / gx) ** 0.5,
            "--",
            color="0.35",
            lw=1.3,
            label="slope 1/2 (paper Eq. 7)",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"$K/(\alpha - B - \alpha^{cr})$")
    ax.set_ylabel(r"pattern size $\lambda$ at the first peak of $\sigma^2_S$ ($L$)")
    n_seeds = int(res.phase.sizes.get("seed", 0))
    left_out = (
        f"\n{n_unpeaked} of {n_patterned} patterned runs left out: first peak of "
        r"$\sigma^2_S$ not reached by $t_{\rm final}$"
        if n_unpeaked
        else ""
    )
    ax.set_title(
        f"{res.name}: paper Fig. 3 (mean ± std over {n_seeds} seeds; "
        f"{int(f['scaling_exponent'].attrs.get('fit_confidence', 0.95) * 100)}% "
        "bootstrap interval)" + left_out,
        fontsize=9,
    )
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
        yerr = np.array(
            [np.where(np.isfinite(alo), acr - alo, 0.0), np.where(np.isfinite(ahi), ahi - acr, 0.0)]
        )[:, okk]
        ins.errorbar(
            K[okk],
            acr[okk],
            yerr=np.maximum(yerr, 0.0),
            fmt="s-",
            color="tab:blue",
            ms=4,
            capsize=2,
            lw=1,
            label=r"from $\lambda$",
        )
        if np.any(at_bound & okk):
            ins.axhline(float(bound), color="0.6", lw=0.8, ls=":")
            ins.plot(
                K[at_bound & okk],
                acr[at_bound & okk],
                "o",
                mfc="none",
                mec="tab:red",
                ms=8,
                mew=1.2,
                label=f"at bound ({fmt(float(bound))})",
            )
    if (
        "transition_location" in f
        and "K" in f["transition_location"].dims
        and f["transition_location"].attrs.get("fit_axis", AMB) == AMB
    ):
        tl = f["transition_location"].sel(K=K, method="nearest").values
        tlo = f["transition_lower"].sel(K=K, method="nearest").values
        thi = f["transition_upper"].sel(K=K, method="nearest").values
        okt = np.isfinite(tl)
        if np.any(okt):
            ins.errorbar(
                K[okt] * 1.08,
                tl[okt],
                yerr=[tl[okt] - tlo[okt], thi[okt] - tl[okt]],
                fmt="o",
                color="0.5",
                ms=3,
                capsize=2,
                lw=0.9,
                label=r"$\sigma^2_S$ jump",
            )
    if K.size > 1 and K.min() > 0:
        from matplotlib.ticker import FixedLocator, NullFormatter

        ins.set_xscale("log")
        ins.xaxis.set_minor_formatter(NullFormatter())
        if K.size <= 5:
            ins.xaxis.set_major_locator(FixedLocator(K.tolist()))
            ins.set_xticklabels([fmt_sci(k) for k in K])
    ins.set_xlabel(r"$K$", fontsize=8, labelpad=1)
    ins.set_ylabel(r"$\alpha^{cr}$", fontsize=8, labelpad=1)
    ins.tick_params(labelsize=7)
    if ins.lines or ins.collections:
        ins.legend(fontsize=6.5, loc="best", handlelength=1.2)
    else:
        ins.remove()
    return fig
