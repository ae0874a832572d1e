"""Print the fitted Fig. 2 jump of each calibration variant (scripts/calibrate.sh) as a
Markdown table: the constant that differs from the defaults, the transition location with its
interval, and the fraction of patterned seeds along alpha - B.

    python scripts/calibration_table.py results/calib-base results/calib-C-2 ...
"""

from __future__ import annotations

import sys
from pathlib import Path

import xarray as xr


def main(folders: list[str]) -> None:
    print("| variant | jump at alpha - B | interval | runs ok / failed | patterned seeds "
          "along alpha - B |")
    print("|---|---|---|---|---|")
    for folder in map(Path, folders):
        fits, phase = folder / "fits.nc", folder / "phase.nc"
        if not fits.exists() or not phase.exists():
            print(f"| {folder.name} | (not run) | | | |")
            continue
        with xr.open_dataset(fits) as f, xr.open_dataset(phase) as p:
            loc = float(f["transition_location"])
            lo, hi = float(f["transition_lower"]), float(f["transition_upper"])
            frac = f["transition_fraction_high"].values
            x = f["alpha_minus_B"].values
            pattern = ", ".join(f"{a:g}:{v:.2f}" for a, v in zip(x, frac, strict=True))
            print(f"| {folder.name.removeprefix('calib-')} | {loc:.3f} | [{lo:.3f}, {hi:.3f}] | "
                  f"{int(p.attrs['n_ok'])} / {int(p.attrs['n_failed'])} | {pattern} |")


if __name__ == "__main__":
    main(sys.argv[1:])
