"""Print the joint calibration table of docs/results.md ("Calibration") from the calibration
campaigns' folders (campaigns/calibration.yaml, run by scripts/calibrate.sh): for each setting,
Fig. 2's jump at K = 5e-5, alpha_cr(K) from the sigma2_S jump of every K, and Fig. 3's
lambda_peak at alpha - B = 0.6 and 1.0 for each of Fig. 3's K, with the three targets checked.

    python scripts/calibration_table.py results/calib-band16 results/calib-per_node ...
    python scripts/calibration_table.py --json table.json --figure tradeoff.png results/calib-*
                                        # also as JSON, and the trade-off figure

A run is "patterned" when sigma2_S(t_final) > 1e-6 (relaxed runs end below 1e-12, patterns
above 1e-3); lambda_peak is averaged over the patterned seeds only. Targets (the issue's):
the jump at K = 5e-5 in [0.3, 0.5]; lambda_peak(0.6) / lambda_peak(1.0) >= 1.2 at each of
K = 1e-5, 3e-5, 1e-4 (a K where 0.6 or 1.0 has no patterned seed fails); alpha_cr(K) > 0 and
rising with K (every K has a jump, and the locations increase). A K counts as having a jump
only where some alpha - B has most of its seeds patterned.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

PATTERNED = 1e-6
FIG2_K = 5e-5
FIG3_K = (1e-5, 3e-5, 1e-4)
LOW, HIGH = 0.6, 1.0
JUMP_RANGE = (0.3, 0.5)
RATIO_MIN = 1.2


def _sel(da: xr.DataArray, **coords: float) -> xr.DataArray:
    return da.sel({k: v for k, v in coords.items()}, method="nearest", tolerance=1e-12)


def lambda_at(phase: xr.Dataset, K: float, amb: float) -> tuple[float, float, int, int]:
    """Mean lambda_peak over the patterned seeds at (K, alpha - B), its relative standard
    error, the number of patterned seeds and the number of finished seeds; NaN when the point
    was not run or nothing patterned."""
    try:
        sig = _sel(phase["sigma2_S"], K=K, alpha_minus_B=amb).values
        lam = _sel(phase["lambda_peak"], K=K, alpha_minus_B=amb).values
    except KeyError:
        return math.nan, math.nan, 0, 0
    done = np.isfinite(sig)
    pat = done & (sig > PATTERNED) & np.isfinite(lam)
    n = int(pat.sum())
    if not n:
        return math.nan, math.nan, 0, int(done.sum())
    mean = float(lam[pat].mean())
    rel = float(lam[pat].std(ddof=1) / math.sqrt(n) / mean) if n > 1 else math.nan
    return mean, rel, n, int(done.sum())


def summarise(folder: Path) -> dict[str, Any]:
    """The calibration targets of one setting (one campaign folder)."""
    with xr.open_dataset(folder / "fits.nc") as f, xr.open_dataset(folder / "phase.nc") as p:
        fits, phase = f.load(), p.load()
    loc = fits["transition_location"]
    ks = [float(k) for k in fits["K"].values]
    # a jump counts where the K has a point with most of its seeds patterned (else the
    # fit's largest step is one between relaxed runs' round-off levels: no transition)
    sig = phase["sigma2_S"]
    patterned = (sig > PATTERNED).sum(dim="seed")
    finished = xr.apply_ufunc(np.isfinite, sig).sum(dim="seed")
    most = patterned > 0.5 * finished
    majority = most.any(dim="alpha_minus_B")
    # a K whose lowest alpha - B already patterns has its jump below the grid: its upper
    # bound is that lowest value (alpha_cr > 0 is then not shown, rising can be)
    lowest = float(phase["alpha_minus_B"].min())
    majority_low = most.sel(alpha_minus_B=lowest)
    alpha_cr = {k: float(_sel(loc, K=k)) if bool(_sel(majority, K=k)) else math.nan for k in ks}
    alpha_cr_below = {k: lowest for k in ks if bool(_sel(majority_low, K=k))}
    jump = alpha_cr.get(FIG2_K, math.nan)
    interval = (
        (
            float(_sel(fits["transition_lower"], K=FIG2_K)),
            float(_sel(fits["transition_upper"], K=FIG2_K)),
        )
        if FIG2_K in alpha_cr
        else (math.nan, math.nan)
    )
    lam = {}
    for k in FIG3_K:
        lo, e_lo, n_lo, d_lo = lambda_at(phase, k, LOW)
        hi, e_hi, n_hi, d_hi = lambda_at(phase, k, HIGH)
        ratio = lo / hi if hi > 0 else math.nan
        lam[k] = {
            "low": lo,
            "high": hi,
            "ratio": ratio,
            "ratio_se": ratio * math.hypot(e_lo, e_hi),
            "patterned_low": n_lo,
            "patterned_high": n_hi,
            "runs_low": d_lo,
            "runs_high": d_hi,
        }
    bounds = [
        alpha_cr[k] if math.isfinite(alpha_cr[k]) else alpha_cr_below.get(k, math.nan)
        for k in sorted(alpha_cr)
    ]
    rising = all(math.isfinite(a) and a > 0 for a in bounds) and all(
        b > a for a, b in zip(bounds, bounds[1:], strict=False)
    )
    ok_jump = JUMP_RANGE[0] <= jump <= JUMP_RANGE[1]
    ok_ratio = all(lam[k]["ratio"] >= RATIO_MIN for k in FIG3_K)
    overrides = (
        json.loads(phase.attrs.get("overrides_json", "{}"))
        if "overrides_json" in phase.attrs
        else {}
    )
    return {
        "setting": folder.name.removeprefix("calib-"),
        "folder": str(folder),
        "jump": jump,
        "jump_interval": interval,
        "alpha_cr": alpha_cr,
        "alpha_cr_below": alpha_cr_below,
        "lambda": lam,
        "ok_jump": ok_jump,
        "ok_ratio": ok_ratio,
        "ok_alpha_cr": rising,
        "ok_all": ok_jump and ok_ratio and rising,
        "runs_ok": int(phase.attrs.get("n_ok", -1)),
        "runs_failed": int(phase.attrs.get("n_failed", -1)),
        "overrides": overrides,
    }


def _f(x: float, digits: int = 3) -> str:
    return "-" if not math.isfinite(x) else f"{x:.{digits}g}"


def _mark(ok: bool) -> str:
    return "yes" if ok else "no"


def markdown(rows: list[dict[str, Any]]) -> str:
    head = (
        "| setting | jump at K = 5e-5 [interval] | alpha_cr(K) from the jump, K = "
        "1e-5 / 3e-5 / 5e-5 / 1e-4 | lambda_peak 0.6 / 1.0 (ratio ± its standard error; "
        "patterned seeds) at "
        "K = 1e-5 | at 3e-5 | at 1e-4 | jump in [0.3, 0.5] | ratio >= 1.2 | alpha_cr "
        "rising | runs |"
    )
    lines = [head, "|" + "---|" * 10]
    for r in rows:
        acr = " / ".join(
            f"< {_f(r['alpha_cr_below'][k])}"
            if k in r["alpha_cr_below"] and not math.isfinite(r["alpha_cr"].get(k, math.nan))
            else _f(r["alpha_cr"].get(k, math.nan))
            for k in (1e-5, 3e-5, 5e-5, 1e-4)
        )
        cells = []
        for k in FIG3_K:
            q = r["lambda"][k]
            cells.append(
                f"{_f(q['low'])} / {_f(q['high'])} ({_f(q['ratio'])} "
                f"± {_f(q['ratio_se'], 1)}; "
                f"{q['patterned_low']}/{q['runs_low']}, "
                f"{q['patterned_high']}/{q['runs_high']})"
            )
        lo, hi = r["jump_interval"]
        lines.append(
            f"| {r['setting']} | {_f(r['jump'])} [{_f(lo)}, {_f(hi)}] | {acr} | "
            + " | ".join(cells)
            + f" | {_mark(r['ok_jump'])} | {_mark(r['ok_ratio'])} | "
            f"{_mark(r['ok_alpha_cr'])} | {r['runs_ok']} ok, {r['runs_failed']} failed |"
        )
    return "\n".join(lines)


def tradeoff_figure(rows: list[dict[str, Any]], path: Path, chosen: str | None = None) -> None:
    """Each setting in the plane (Fig. 2's jump at K = 5e-5, Fig. 3's lambda ratio 0.6 / 1.0 at
    K = 1e-5), the targets shaded; marker filled where alpha_cr rises with K, and the ratio at
    K = 3e-5 beside it; the setting named ``chosen`` (the model's defaults) ringed in red. A
    setting without a jump below 1.0 is drawn at the right edge."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 5.2), layout="constrained")
    ax, key = fig.subplots(1, 2, width_ratios=[2.2, 1.0])
    ax.axvspan(*JUMP_RANGE, color="tab:green", alpha=0.10, lw=0)
    ax.axhspan(RATIO_MIN, 3.0, color="tab:green", alpha=0.10, lw=0)
    # the settings near the targets crowd together: drawn again, magnified, in an inset
    zoom = ax.inset_axes((0.06, 0.42, 0.5, 0.5))
    zoom.set_xlim(0.35, 0.55)
    zoom.set_ylim(0.95, 1.23)
    zoom.axhspan(RATIO_MIN, 3.0, color="tab:green", alpha=0.10, lw=0)
    zoom.axvspan(*JUMP_RANGE, color="tab:green", alpha=0.10, lw=0)
    zoom.tick_params(labelsize=7)
    ax.indicate_inset_zoom(zoom, edgecolor="0.5")
    legend = []
    for number, r in enumerate(rows, start=1):
        x = r["jump"] if math.isfinite(r["jump"]) else 1.05
        y = r["lambda"][FIG3_K[0]]["ratio"]
        r3 = r["lambda"][FIG3_K[1]]["ratio"]
        legend.append(
            f"{number:2d}  {r['setting']}  ({_f(r3, 2)})"
            + ("  <- defaults" if r["setting"] == chosen else "")
        )
        if not math.isfinite(y):
            continue
        for axes, size in ((ax, 7), (zoom, 6)):
            axes.plot([x], [y], "o", ms=size, mec="k", mfc="k" if r["ok_alpha_cr"] else "white")
            if r["setting"] == chosen:
                axes.plot(
                    [x],
                    [y],
                    "o",
                    ms=2 * size,
                    mfc="none",
                    mec="tab:red",
                    mew=2,
                    label="the model's defaults" if axes is ax else None,
                )
        ax.annotate(str(number), (x, y), xytext=(5, 3), textcoords="offset points", fontsize=7)
        # in the inset: numbers beside the markers, alternating sides where they crowd
        zoom.annotate(
            str(number),
            (x, y),
            xytext=(6 if number % 2 else -13, -3),
            textcoords="offset points",
            fontsize=7,
            clip_on=True,
        )
    ax.set_xlim(0.2, 1.1)
    ax.set_ylim(0.8, max(2.3, ax.get_ylim()[1]))
    ax.set_xlabel("Fig. 2: jump of sigma2_S(300) at K = 5e-5 (alpha - B; 1.05: none below 1)")
    ax.set_ylabel("Fig. 3: lambda_peak(0.6) / lambda_peak(1.0) at K = 1e-5")
    if chosen is not None:
        ax.legend(loc="lower right", fontsize=8)
    ax.set_title(
        "calibration trade-off: green bands are the targets;\nfilled: alpha_cr rises with K",
        fontsize=9,
        loc="left",
    )
    key.axis("off")
    key.text(
        0.0,
        1.0,
        "setting (ratio at K = 3e-5)\n\n" + "\n".join(legend),
        va="top",
        ha="left",
        family="monospace",
        fontsize=7,
        transform=key.transAxes,
    )
    fig.savefig(path, dpi=110)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("folders", nargs="+", type=Path, help="calibration campaigns' folders")
    parser.add_argument("--json", type=Path, help="also write the table as JSON here")
    parser.add_argument("--figure", type=Path, help="also draw the trade-off figure here")
    parser.add_argument("--chosen", help="the setting to mark in the figure")
    args = parser.parse_args(argv)
    out_json, out_fig, chosen = args.json, args.figure, args.chosen
    folders: list[Path] = args.folders
    rows = []
    for folder in folders:
        if not (folder / "fits.nc").exists() or not (folder / "phase.nc").exists():
            print(f"{folder}: not run (no fits.nc / phase.nc)", file=sys.stderr)
            continue
        rows.append(summarise(folder))
    print(markdown(rows))
    if out_json is not None:
        out_json.write_text(json.dumps(rows, indent=1, default=str) + "\n")
    if out_fig is not None:
        tradeoff_figure(rows, out_fig, chosen)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
