"""The convergence table behind ``resolution: auto`` (docs/model/resolution.md, "Resolution from the
physics"), from the phase.nc of campaigns/resolution_study.yaml (K x chi x resolution x
seeds; several files, e.g. with campaigns/resolution_study_large_K.yaml, are merged into one
table, a parameter a campaign does not sweep read from its attributes): for each (K, chi)
and grid N that has runs there, the seed means of lambda(t_final) and sigma2_S(t_final),
their relative change on the next doubling (N -> 2N; the largest change of a single seed in
brackets), the cells per Frank length sqrt(K / A0) at N, and the coarsest grid whose changes
on doubling are all below the threshold (5 %).

    .venv/bin/python scripts/resolution_table.py results/resolution_study/phase.nc \
        results/resolution_study_large_K/phase.nc
    .venv/bin/python scripts/resolution_table.py PHASE --threshold 0.05 --json table.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys

import numpy as np
import xarray as xr

OBSERVABLES = ("lambda", "sigma2_S")
#: sigma2_S above this: a patterned run (a relaxed one sits at round-off, ~1e-14)
PATTERNED = 1e-6


def change(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Relative change of the seed mean from a to b, and the largest of a single seed."""
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.any():
        return math.nan, math.nan
    mean = abs(b[ok].mean() - a[ok].mean()) / abs(a[ok].mean())
    single = float(np.max(np.abs(b[ok] - a[ok]) / np.abs(a[ok])))
    return float(mean), single


def as_axes(phase: xr.Dataset, axes: list[str]) -> xr.Dataset:
    """The observables of ``phase`` with each of ``axes`` a dimension: a parameter the
    campaign did not sweep becomes an axis of length one, its value from ``param_<name>``."""
    out = phase[list(OBSERVABLES)]
    for name in axes:
        if name not in out.dims:
            value = phase.attrs.get(f"param_{name}")
            if value is None:
                raise ValueError(f"it has no axis {name} and no attribute param_{name}")
            out = out.expand_dims({name: [float(value)]})
    out.attrs["param_A0"] = phase.attrs.get("param_A0", 0.1)
    return out


def merged(phases: list[xr.Dataset]) -> xr.Dataset:
    """One dataset of the observables over the union of the files' axes (runs missing at a
    point and grid are NaN there)."""
    axes = ["K", "chi"] + sorted(
        {str(d) for p in phases for d in p["sigma2_S"].dims} - {"K", "chi", "resolution", "seed"}
    )
    both = xr.merge([as_axes(p, axes) for p in phases], join="outer", compat="no_conflicts")
    both.attrs["param_A0"] = phases[0].attrs.get("param_A0", 0.1)
    return both


def table(phase: xr.Dataset, threshold: float) -> list[dict]:
    A0 = float(phase.attrs.get("param_A0", 0.1))
    # the study's other swept axes (eps in the strained study): a row for each of their values
    other = [str(d) for d in phase["sigma2_S"].dims if d not in ("K", "chi", "resolution", "seed")]
    rows = []
    for K, chi, *values in itertools.product(
        phase["K"].values, phase["chi"].values, *(phase[d].values for d in other)
    ):
        where = {d: float(v) for d, v in zip(other, values, strict=True)}
        at = phase.sel({"K": K, "chi": chi, **where})
        frank = math.sqrt(float(K) / A0)
        row: dict = {
            "K": float(K),
            "chi": float(chi),
            "other": where,
            "frank_length": frank,
            "grids": [],
        }
        ran = np.isfinite(at["sigma2_S"].values).reshape(len(at["resolution"]), -1).any(axis=1)
        grids = [int(n) for n, r in zip(at["resolution"].values, ran, strict=True) if r]
        if not grids:  # a point of one file only, at another's grids: no runs here
            continue
        at = at.sel(resolution=grids)
        above = at["sigma2_S"].values[np.isfinite(at["sigma2_S"].values)] > PATTERNED
        patterned = bool(above.all())
        row["no_pattern"] = not bool(above.any())
        for i, n in enumerate(grids):
            entry = {
                "N": n,
                "cells_per_frank": n * frank,
                **{
                    f"{m}_mean": float(np.nanmean(at[m].sel(resolution=n).values))
                    for m in OBSERVABLES
                },
            }
            if i + 1 < len(grids):
                for m in OBSERVABLES:
                    mean, single = change(
                        at[m].sel(resolution=n).values,
                        at[m].sel(resolution=grids[i + 1]).values,
                    )
                    entry[f"{m}_change"] = mean
                    entry[f"{m}_change_max_seed"] = single
            row["grids"].append(entry)
        row["patterned"] = patterned
        converged = None
        for entry in row["grids"][:-1]:
            changes = [entry[f"{m}_change"] for m in OBSERVABLES]
            if all(math.isfinite(c) and c < threshold for c in changes):
                converged = entry
                break
        row["converged_N"] = None if converged is None else converged["N"]
        row["converged_cells_per_frank"] = (
            None if converged is None else converged["cells_per_frank"]
        )
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "phase",
        nargs="+",
        help="phase.nc of campaigns/resolution_study.yaml (and of resolution_study_large_K.yaml)",
    )
    ap.add_argument("--threshold", type=float, default=0.05)
    ap.add_argument("--json", help="also write the table as JSON here")
    args = ap.parse_args(argv)
    phases = []
    for path in args.phase:
        try:
            with xr.open_dataset(path) as phase:
                phases.append(phase.load())
        except (OSError, ValueError) as err:
            print(f"error: cannot read {path}: {err}", file=sys.stderr)
            return 2
    try:
        rows = table(merged(phases), args.threshold)
    except (KeyError, ValueError) as err:
        print(f"error: cannot make one table of {', '.join(args.phase)}: {err}", file=sys.stderr)
        return 2
    pct = lambda x: "-" if not math.isfinite(x) else f"{100 * x:.1f} %"  # noqa: E731
    other = list(rows[0]["other"]) if rows else []
    print(
        "| K | chi | "
        + "".join(f"{d} | " for d in other)
        + "l_F (L) | N | cells per l_F | lambda (mean) | sigma2_S (mean) | "
        "lambda on 2N (max seed) | sigma2_S on 2N (max seed) |"
    )
    print("|---|---|" + "---|" * len(other) + "---|---|---|---|---|---|---|")
    for row in rows:
        at = "".join(f"{v:g} | " for v in row["other"].values())
        for e in row["grids"]:
            dl = (
                f"{pct(e['lambda_change'])} ({pct(e['lambda_change_max_seed'])})"
                if "lambda_change" in e
                else ""
            )
            ds = (
                f"{pct(e['sigma2_S_change'])} ({pct(e['sigma2_S_change_max_seed'])})"
                if "sigma2_S_change" in e
                else ""
            )
            print(
                f"| {row['K']:.3g} | {row['chi']:g} | {at}{row['frank_length']:.2g} | {e['N']} | "
                f"{e['cells_per_frank']:.2f} | {e['lambda_mean']:.4g} | "
                f"{e['sigma2_S_mean']:.4g} | {dl} | {ds} |"
            )
    print()
    print(f"coarsest grid with both changes on doubling < {100 * args.threshold:g} %:")
    for row in rows:
        n, c = row["converged_N"], row["converged_cells_per_frank"]
        if row["no_pattern"]:
            what = "no pattern on any grid (sigma2_S at round-off: nothing to converge)"
        elif n:
            what = f"{n} ({c:.2f} cells per Frank length)"
        elif not row["patterned"]:
            what = "the pattern class changes between grids or seeds"
        else:
            what = "no grid passes (the finest one run has none to compare with)"
        at = "".join(f", {d} = {v:g}" for d, v in row["other"].items())
        print(f"  K = {row['K']:.3g}, chi = {row['chi']:g}{at}: {what}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
