"""Print the Swift-Hohenberg chains of docs/model/swift_hohenberg.md ("Measured" sections):
each run through ``MODEL.run`` at 16 x 18 (2 stripe wavelengths by 2 hexagon rows), t = 150 a
run, white noise of 1e-3 added at each start, seed 1.

    python scripts/swift_hohenberg_loops.py loop --g 0.5 --step 0.005 --low -0.04
    python scripts/swift_hohenberg_loops.py loop --g 1.0 --step 0.02 --low -0.2
    python scripts/swift_hohenberg_loops.py band --g 0.25 --step 0.02 --high 0.5
    python scripts/swift_hohenberg_loops.py stripes --g 0.25 0.04 0.06 0.08 0.1
    python scripts/swift_hohenberg_loops.py stripes --g 0.25 --runs 7 0.04 0.06

``loop``: down from hexagons grown from noise at eps = 0.06 (0.06, 0.04, 0.02, 0, then in
steps down to ``--low``), then a fresh chain up from ``--low`` to 0.06 (the slow test
tests/sweep/test_swift_hohenberg_chains.py runs the first). ``band``: one chain up from
hexagons grown from noise at 0.04 to ``--high`` and back down, continuing the same state.
``stripes``: stripes 2 sqrt(eps/3) cos(x) as the start at each eps, ``--runs`` runs of t = 150
each from the previous one's end state.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "sweep"))

from test_swift_hohenberg_chains import chain, pattern, run

from nematic_solids.sweep.models import swift_hohenberg as sh
from nematic_solids.sweep.models.pypde import PDEState


def show(name: str, eps: float, kind: str, amplitude: float, hexagonality: float) -> None:
    print(
        f"{name:5} eps = {eps:+.4f}  {kind:9} rms {amplitude:.3g}  hexagonality {hexagonality:.3f}"
    )


def loop(g: float, step: float, low: float) -> None:
    down = [0.06, 0.04, 0.02, 0.0, *np.round(np.arange(-step, low - 1e-9, -step), 4)]
    up = list(np.round(np.arange(low, 0.06 + 1e-9, step), 4))
    for name, values in (("down", down), ("up", up)):
        for eps, kind, amplitude in chain([float(v) for v in values], g):
            print(f"{name:5} eps = {eps:+.4f}  {kind:9} rms {amplitude:.3g}")


def band(g: float, step: float, high: float) -> None:
    values = [float(v) for v in np.round(np.arange(0.04, high + 1e-9, step), 4)]
    state = None
    for name, seq in (("up", values), ("down", values[::-1])):
        for eps in seq:
            out = run(eps, g, initial=state)
            state = out.end_state
            ds = out.dataset
            show(name, eps, pattern(out), float(ds.amplitude_final), float(ds.hexagonality_final))


def stripes(g: float, values: list[float], runs: int) -> None:
    grid = sh.make_grid(sh.Settings(periods=2, points=8))
    x, _ = np.meshgrid(*grid.axes_coords, indexing="ij")
    for eps in values:
        state: object = PDEState(2 * np.sqrt(eps / 3) * np.cos(x), 0.0)
        for i in range(runs):
            out = run(eps, g, initial=state)
            state = out.end_state
            ds = out.dataset
            t = f"t={150 * (i + 1)}"
            show(t, eps, pattern(out), float(ds.amplitude_final), float(ds.hexagonality_final))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("loop")
    p.add_argument("--g", type=float, required=True)
    p.add_argument("--step", type=float, required=True)
    p.add_argument("--low", type=float, required=True)
    p = sub.add_parser("band")
    p.add_argument("--g", type=float, required=True)
    p.add_argument("--step", type=float, required=True)
    p.add_argument("--high", type=float, required=True)
    p = sub.add_parser("stripes")
    p.add_argument("--g", type=float, required=True)
    p.add_argument("--runs", type=int, default=2, help="runs of t = 150 from each start")
    p.add_argument("eps", type=float, nargs="+")
    args = parser.parse_args()
    if args.what == "loop":
        loop(args.g, args.step, args.low)
    elif args.what == "band":
        band(args.g, args.step, args.high)
    else:
        stripes(args.g, args.eps, args.runs)


if __name__ == "__main__":
    main()
