r"""The Swift-Hohenberg equation with a quadratic term, a model built only through the public
API of :mod:`.pypde` (as a user would build theirs):

.. math:: \partial_t u = \epsilon u - (1 + \nabla^2)^2 u + g u^2 - u^3

solved by py-pde's own ``SwiftHohenbergPDE`` (``rate`` = eps, ``kc2`` = 1, ``delta`` = g;
second-order central differences for the Laplacian) on a periodic rectangle that holds
``periods`` stripe wavelengths :math:`2\pi` along x and ``rows`` hexagon rows
:math:`4\pi/\sqrt 3` along y (``rows = round(periods * sqrt(3)/2)``: 4 periods give 3 rows,
a rectangle of aspect 0.87). A square cannot hold a hexagonal lattice exactly (it needs
:math:`L_y/L_x = \sqrt 3\, n/m`); this rectangle holds both the stripes along x and a perfect
hexagonal pattern with :math:`|k| = 1`.

Observables: ``amplitude`` (rms of u), ``mean`` (its spatial mean) and ``hexagonality``
(:func:`hexagonality`: from the power spectrum on the critical ring, the power of the weaker of
the two directions at 60 and 120 degrees to the strongest mode, relative to the strongest
direction's: 1 for hexagons, 0 for stripes). :func:`classify` reads their seed means:
``uniform`` where the amplitude is below :data:`UNIFORM_AMPLITUDE`, else ``hexagons`` where the
hexagonality is at least :data:`HEXAGONAL`, else ``stripes``. The amplitude is the classifying
observable of the threshold rules (``refine:``, ``precision:``, ``verify:``: patterned above
their ``patterned_above``), and the hexagonality's seed mean is taken over the patterned runs
only.

The theory (linear growth rate, amplitude equations, the existence and stability boundaries)
is docs/model/swift_hohenberg.md; the tests are tests/sweep/test_swift_hohenberg.py.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pde
from pde.fields.base import FieldBase

from .interface import Observable, SettingError
from .pypde import FunctionMeasure, Measure, SolverSettings, numerics, parameter, pde_model

#: below this rms amplitude of u at the end a run is uniform (the initial noise is 1e-2 and
#: decays where the uniform state is stable; a pattern's rms is above 0.03 at eps >= 1e-3)
UNIFORM_AMPLITUDE = 1e-2
#: at or above this hexagonality a pattern is hexagons, below it stripes
HEXAGONAL = 0.5
#: The critical ring of the power spectrum, ``|k|`` between these (the linear band at eps < 1;
#: the first harmonics of hexagons, at sqrt(3) and 2, fall outside)
RING = (0.5, 1.5)
#: directions within this angle (radians) of 0, 60 and 120 degrees to the strongest mode
#: count for that direction
DIRECTION_WIDTH = math.radians(15.0)
#: RK4's stability limit on the negative real axis (``|z|`` for ``R(z) = 1`` at z < 0)
RK4_LIMIT = 2.785


@dataclass(frozen=True)
class Settings(SolverSettings):
    """The Swift-Hohenberg model's settings (py-pde's solver settings first)."""

    t_final: float = numerics(200.0, "final time")
    dt: float = numerics(0.01, "time step (RK4 is stable for dt < 2.785 / max |sigma|)")
    save_every: float = numerics(5.0, "time between saves of the observables")
    eps: float = parameter(
        0.1, "distance from onset (linear growth rate at k = 1)", symbol="$\\epsilon$"
    )
    g: float = parameter(0.0, "quadratic coefficient", symbol="$g$")
    periods: int = numerics(4, "stripe wavelengths 2 pi along x (even)")
    points: int = numerics(8, "grid points per wavelength 2 pi")
    noise: float = numerics(0.01, "standard deviation of the initial white noise")
    kick: float = numerics(
        0.0, "standard deviation of white noise added to a given initial state (a chain's start)"
    )


def domain(periods: int) -> tuple[float, float]:
    """The periodic rectangle (Lx, Ly) of ``periods`` stripe wavelengths along x."""
    if periods < 2 or periods % 2:
        raise ValueError(f"periods = {periods} must be even and at least 2 (hexagons need it)")
    rows = round(periods * math.sqrt(3) / 2)
    return 2 * math.pi * periods, 4 * math.pi / math.sqrt(3) * rows


def make_grid(s: Settings) -> pde.CartesianGrid:
    """The periodic grid of ``s``: ``points`` per wavelength 2 pi along x, about as fine along y."""
    if s.points < 4:
        raise ValueError(f"points = {s.points} per wavelength must be at least 4")
    lx, ly = domain(s.periods)
    shape = [s.points * s.periods, round(s.points * ly / (2 * math.pi))]
    return pde.CartesianGrid([(0.0, lx), (0.0, ly)], shape, periodic=True)


def laplacian_symbol(grid: pde.CartesianGrid, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
    """kappa^2: minus the symbol of the five-point Laplacian at wavevector (kx, ky)."""
    dx, dy = grid.discretization
    return (2 / dx * np.sin(kx * dx / 2)) ** 2 + (2 / dy * np.sin(ky * dy / 2)) ** 2


def growth_rate(eps: float, kappa2: np.ndarray | float) -> np.ndarray | float:
    """The linear growth rate eps - (1 - kappa^2)^2 (continuum: ``kappa = |k|``)."""
    return eps - (1 - np.asarray(kappa2)) ** 2


class SwiftHohenbergPDE(pde.SwiftHohenbergPDE):
    """py-pde's Swift-Hohenberg PDE with a faster numpy evolution rate: the same five-point
    Laplacian on a periodic grid, applied to the data with ``numpy.roll`` (py-pde's own numpy
    path builds fields and boundary conditions at every call, much slower on small grids;
    the numba backend compiles anew for every value of eps and g). The two rates agree to
    rounding (tests/sweep/test_swift_hohenberg.py)."""

    def evolution_rate(self, state: pde.ScalarField, t: float = 0) -> pde.ScalarField:  # type: ignore[override]
        u = np.asarray(state.data)
        dx, dy = state.grid.discretization
        lap = five_point_laplacian(u, dx, dy)
        lap2 = five_point_laplacian(lap, dx, dy)
        rate = (self.rate - self.kc2**2) * u - 2 * self.kc2 * lap - lap2
        return pde.ScalarField(state.grid, rate + self.delta * u**2 - u**3)


def five_point_laplacian(u: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """The periodic five-point Laplacian of ``u`` (py-pde's stencil)."""
    along_x = (np.roll(u, 1, 0) - 2 * u + np.roll(u, -1, 0)) / dx**2
    return along_x + (np.roll(u, 1, 1) - 2 * u + np.roll(u, -1, 1)) / dy**2


def theory(g: float, order: str = "leading") -> dict[str, float]:
    """The amplitude equations' boundaries (docs/model/swift_hohenberg.md): hexagons exist
    above ``eps_H``, stripes are stable above ``eps_S``, hexagons below ``eps_X``; the uniform
    state is stable below 0. ``order="leading"``: -g^2/15, 4 g^2/3, 16 g^2/3. ``"next"``: with
    the mean and the harmonics that g u^2 drives slaved, the cubic coefficients become
    3 - 38 g^2/9 and 6 - 5 g^2 (valid while g^2 is small against them)."""
    nu2 = 4 * g**2
    if order == "leading":
        gamma, h = 3.0, 6.0
    elif order == "next":
        gamma, h = 3 - 38 * g**2 / 9, 6 - 5 * g**2
    else:
        raise ValueError(f"order {order!r} is not 'leading' or 'next'")
    return {
        "eps_H": -nu2 / (4 * (gamma + 2 * h)),
        "eps_S": nu2 * gamma / (h - gamma) ** 2,
        "eps_X": nu2 * (2 * gamma + h) / (h - gamma) ** 2,
    }


def check_step(s: Settings) -> None:
    """Refuses a fixed step that RK4 or Euler is unstable at on the grid of ``s`` (the
    fastest decaying mode's rate, ``eps - (1 - kappa^2)^2`` at the grid's largest
    ``kappa^2``, times dt beyond the scheme's limit on the negative real axis)."""
    grid = make_grid(s)
    dx, dy = grid.discretization
    worst = abs(float(growth_rate(s.eps, 4 / dx**2 + 4 / dy**2)))
    limit = (RK4_LIMIT if s.scheme == "runge-kutta" else 2.0) / worst
    if not s.adaptive and s.dt >= limit:
        raise SettingError(
            "dt",
            s.dt,
            f"below the stability limit {limit:.3g} of the {s.scheme} scheme on this grid "
            f"(points = {s.points}, eps = {s.eps:g})",
        )


def make_pde(s: Settings) -> pde.SwiftHohenbergPDE:
    """py-pde's Swift-Hohenberg PDE for ``s``; refuses a step RK4 or Euler is unstable at."""
    check_step(s)
    if s.backend == "numba":
        return pde.SwiftHohenbergPDE(rate=s.eps, kc2=1.0, delta=s.g, bc="periodic")
    return SwiftHohenbergPDE(rate=s.eps, kc2=1.0, delta=s.g, bc="periodic")


def white_noise(grid: pde.GridBase, s: Settings, rng: np.random.Generator) -> pde.ScalarField:
    """The seeded initial state: independent normal values of deviation ``noise``."""
    return pde.ScalarField(grid, s.noise * rng.standard_normal(grid.shape), label="u")


def kick(state: FieldBase, s: Settings, rng: np.random.Generator) -> None:
    """Adds white noise of deviation ``kick`` to a chain's start (the noise of an experiment:
    without it a uniform state that lost all its perturbations stays uniform where it is
    unstable)."""
    if s.kick > 0:
        state.data += s.kick * rng.standard_normal(state.data.shape)


def ring_directions(u: np.ndarray, lengths: tuple[float, float]) -> np.ndarray:
    """The power of u's modes on the critical ring in three directions: within
    :data:`DIRECTION_WIDTH` of the strongest mode's, and of 60 and 120 degrees to it."""
    nx, ny = u.shape
    power = np.abs(np.fft.fft2(u - u.mean())) ** 2
    kx = 2 * np.pi * np.fft.fftfreq(nx, d=lengths[0] / nx)
    ky = 2 * np.pi * np.fft.fftfreq(ny, d=lengths[1] / ny)
    kxx, kyy = np.meshgrid(kx, ky, indexing="ij")
    k = np.hypot(kxx, kyy)
    on_ring = (k > RING[0]) & (k < RING[1])
    if not on_ring.any() or power[on_ring].max() == 0:
        return np.zeros(3)
    angle = np.arctan2(kyy, kxx)
    strongest = angle[on_ring][np.argmax(power[on_ring])]
    rel = np.mod(angle - strongest, np.pi)  # a mode and its conjugate share a direction
    out = np.zeros(3)
    for i, centre in enumerate((0.0, np.pi / 3, 2 * np.pi / 3)):
        d = np.abs(rel - centre)
        d = np.minimum(d, np.pi - d)
        out[i] = power[on_ring & (d < DIRECTION_WIDTH)].sum()
    return out


def hexagonality(u: np.ndarray, lengths: tuple[float, float]) -> float:
    """The weaker of the 60 and 120 degree directions' power over the strongest direction's
    (:func:`ring_directions`), clipped to [0, 1]: 1 for hexagons, 0 for stripes."""
    p = ring_directions(u, lengths)
    if p[0] == 0:
        return 0.0
    return float(min(1.0, min(p[1], p[2]) / p[0]))


class Hexagonality(Measure):
    """The measure of :func:`hexagonality` on the run's grid."""

    observable = Observable(
        "hexagonality",
        "hexagonality_final",
        "power at 60 and 120 degrees over the strongest",
        change="absolute",
        classifies=True,
        pattern=True,
        verify=True,
    )

    def handle(self, state: FieldBase, t: float) -> float:
        lengths = tuple(float(b[1] - b[0]) for b in state.grid.axes_bounds)
        return hexagonality(np.asarray(state.data), (lengths[0], lengths[1]))


def rms(state: FieldBase) -> float:
    return float(np.sqrt(np.mean(np.asarray(state.data) ** 2)))


def mean(state: FieldBase) -> float:
    return float(np.mean(np.asarray(state.data)))


def classify(values: Mapping[str, float]) -> str:
    """``uniform``, ``stripes`` or ``hexagons`` from the seed means of the observables."""
    if values["amplitude"] < UNIFORM_AMPLITUDE:
        return "uniform"
    return "hexagons" if values["hexagonality"] >= HEXAGONAL else "stripes"


MEASURES: tuple[Measure, ...] = (
    FunctionMeasure(
        Observable("amplitude", "amplitude_final", "rms of u", classifies=True, verify=True), rms
    ),
    FunctionMeasure(Observable("mean", "mean_final", "spatial mean of u", change="absolute"), mean),
    Hexagonality(),
)

MODEL = pde_model(
    "swift-hohenberg",
    make_pde,
    Settings,
    make_grid,
    white_noise,
    MEASURES,
    long_name="Swift-Hohenberg equation with a quadratic term (py-pde)",
    classify=classify,
    perturb=kick,
    check=check_step,
)
