"""The Swift-Hohenberg model's patterns from noise and its hysteresis in chains, against the
amplitude equations (docs/model/swift_hohenberg.md), at small size (slow: minutes).

Every run goes through ``MODEL.run(RunRequest(...))``; a chain passes each run's end state as
the next run's ``initial``. The measured boundaries are printed (``pytest -s``) and asserted
against theory with the margins the docs page derives: the chain's step in eps, the shift of
the onset by the five-point Laplacian, and on the way up the time a pattern needs to grow from
the chain's noise."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from nematic_solids.sweep.models import swift_hohenberg as sh
from nematic_solids.sweep.models.interface import RunOutcome, RunRequest, defaults

MODEL = sh.MODEL
#: a 16 x 18 grid (2 stripe wavelengths by 2 hexagon rows); dt below RK4's limit 0.0205
NUMERICS = {"periods": 2, "points": 8, "dt": 0.015, "save_every": 3.0, "t_final": 150.0}
KICK = 1e-3


def run(eps: float, g: float, initial: object = None, seed: int = 1) -> RunOutcome:
    numerics = {**defaults(MODEL, "numerics"), **NUMERICS, "kick": KICK}
    req = RunRequest(parameters={"eps": eps, "g": g}, numerics=numerics, seed=seed)
    return MODEL.run(dataclasses.replace(req, initial=initial))


def pattern(out: RunOutcome) -> str:
    ds = out.dataset
    return MODEL.classify({o.name: float(ds[o.scalar]) for o in MODEL.observables})


def chain(values: list[float], g: float) -> list[tuple[float, str, float]]:
    """(eps, pattern, amplitude) along a chain in eps that starts from noise."""
    out, state = [], None
    for eps in values:
        result = run(eps, g, initial=state)
        state = result.end_state
        out.append((eps, pattern(result), float(result.dataset.amplitude_final)))
    return out


def onset_shift() -> dict[str, float]:
    """The five-point Laplacian's shift (1 - kappa^2)^2 of the growth rate of the hexagon
    triad's modes on this grid, and the smallest shift of any grid mode (the onset)."""
    s = sh.Settings(periods=2, points=8)
    grid = sh.make_grid(s)
    lx, ly = sh.domain(2)
    triad = [(1.0, 0.0), (-0.5, math.sqrt(3) / 2)]
    shifts = [
        (1 - float(sh.laplacian_symbol(grid, np.array(a), np.array(b)))) ** 2 for a, b in triad
    ]
    nx, ny = grid.shape
    kx = 2 * np.pi * np.fft.fftfreq(nx, d=lx / nx)
    ky = 2 * np.pi * np.fft.fftfreq(ny, d=ly / ny)
    kxx, kyy = np.meshgrid(kx, ky, indexing="ij")
    onset = float(np.min((1 - sh.laplacian_symbol(grid, kxx, kyy)) ** 2))
    return {
        "x": shifts[0],
        "oblique": shifts[1],
        "triad": (shifts[0] + 2 * shifts[1]) / 3,
        "onset": onset,
    }


@pytest.mark.slow
@pytest.mark.parametrize(
    ("eps", "g", "expected"),
    [(0.3, 0.0, "stripes"), (0.05, 0.5, "hexagons"), (-0.05, 0.5, "uniform")],
)
def test_runs_from_noise_give_the_stable_pattern(eps: float, g: float, expected: str) -> None:
    """eps = 0.3 > 4 g^2/3 = 0 (stripes stable, hexagons absent at g = 0); eps = 0.05 inside
    (-g^2/15, 4 g^2/3) = (-0.017, 0.33) where only hexagons are stable; eps = -0.05 below the
    hexagons' existence at -g^2/15 = -0.017."""
    assert pattern(run(eps, g)) == expected


def lowest(branch: list[tuple[float, str, float]], kind: str) -> float:
    """The smallest eps of a branch whose run ended in ``kind``."""
    return min(eps for eps, p, _ in branch if p == kind)


@pytest.mark.slow
def test_a_chain_down_and_up_in_eps_shows_the_hysteresis_loop() -> None:
    """g = 0.5, steps of 0.005 in eps, each run to t = 150 from the previous end state (plus
    white noise of 1e-3, ``kick``). Down from hexagons at eps = 0.06: hexagons persist below
    onset to the saddle-node, between the amplitude equations' leading-order value -g^2/15 and
    the value with the quadratic harmonics, -g^2/(15 - 128 g^2/9), each shifted by the grid's
    0.0016 (docs/model/swift_hohenberg.md); one chain step wider on each side, and one more
    below for the slow passage past the saddle-node within t = 150. Up from uniform at
    eps = -0.04: uniform up to the grid's onset 0.0011, the pattern appearing once the noise's
    critical modes grow past the uniform threshold within t = 150."""
    g, step = 0.5, 0.005
    shift = onset_shift()
    down_values = [0.06, 0.04, 0.02, 0.0, *np.round(np.arange(-step, -0.04 - 1e-9, -step), 4)]
    down = chain(list(down_values), g)
    up = chain(list(np.round(np.arange(-0.04, 0.06 + 1e-9, step), 4)), g)
    for name, branch in (("down", down), ("up", up)):
        print(name, [(float(e), p, f"{a:.3g}") for e, p, a in branch])
    eps_down = lowest(down, "hexagons")
    eps_up = lowest(up, "hexagons")
    leading = sh.theory(g)["eps_H"] + shift["triad"]
    corrected = sh.theory(g, "next")["eps_H"] + shift["triad"]
    print(f"hexagons down to {eps_down}: theory {leading:.4f} (leading), {corrected:.4f} (next)")
    last_uniform = max(e for e, p, _ in up if p == "uniform")
    print(f"uniform up to {last_uniform}, hexagons from {eps_up}: onset {shift['onset']:.4f}")
    assert all(p == "hexagons" for e, p, _ in down if e >= 0)
    assert corrected - 2 * step <= eps_down <= leading + step
    assert all(p == "uniform" for e, p, _ in down if e < eps_down)
    assert all(p == "uniform" for e, p, _ in up if e <= shift["onset"])
    assert eps_up > 0
    assert all(p != "uniform" for e, p, _ in up if e >= eps_up)
    assert eps_up - eps_down >= 2 * step  # a loop: the two branches differ
