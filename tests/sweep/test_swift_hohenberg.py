"""The Swift-Hohenberg model (sweep/models/swift_hohenberg.py) against theory
(docs/model/swift_hohenberg.md): the linear growth rate of single Fourier modes, the classifier
on constructed patterns, determinism per seed, the evolution rate against py-pde's own; and,
marked slow, the patterns of runs from noise and the hysteresis of chains in eps
(tests/sweep/test_swift_hohenberg_chains.py)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pde
import pytest
import xarray as xr

from nematic_solids.sweep.models import swift_hohenberg as sh
from nematic_solids.sweep.models.interface import RunRequest, classifier, defaults
from nematic_solids.sweep.models.pypde import PDEState
from nematic_solids.sweep.models.registry import get_model

MODEL = sh.MODEL
SMALL = {"periods": 2, "points": 8}  # a 16 x 18 grid, 4 pi x 8 pi / sqrt(3)


def request(eps: float, g: float = 0.0, seed: int = 0, **num: object) -> RunRequest:
    numerics = {**defaults(MODEL, "numerics"), **SMALL, **num}
    return RunRequest(parameters={"eps": eps, "g": g}, numerics=numerics, seed=seed)


def small_grid() -> pde.CartesianGrid:
    return sh.make_grid(sh.Settings(periods=2, points=8))


def test_the_registry_gives_the_model() -> None:
    assert get_model("swift-hohenberg") is MODEL
    kinds = {s.name: s.kind for s in MODEL.settings}
    assert kinds["eps"] == kinds["g"] == "parameter"
    assert kinds["points"] == "numerics"
    assert [o.name for o in MODEL.observables] == ["amplitude", "mean", "hexagonality"]
    assert [o.name for o in MODEL.observables if o.classifies] == ["amplitude", "hexagonality"]
    assert classifier(MODEL).name == "amplitude"  # patterned or not: the amplitude


def test_the_domain_holds_stripes_and_hexagons() -> None:
    """k = (1, 0) and (-1/2, +-sqrt(3)/2) are wavevectors of the periodic rectangle."""
    for periods in (2, 4, 6):
        lx, ly = sh.domain(periods)
        for kx, ky in [(1, 0), (-0.5, math.sqrt(3) / 2)]:
            assert kx * lx / (2 * math.pi) == pytest.approx(round(kx * lx / (2 * math.pi)))
            assert ky * ly / (2 * math.pi) == pytest.approx(round(ky * ly / (2 * math.pi)))
    with pytest.raises(ValueError, match="even"):
        sh.domain(3)


def test_the_evolution_rate_is_py_pdes() -> None:
    grid = small_grid()
    u = pde.ScalarField(grid, 0.3 * np.random.default_rng(2).standard_normal(grid.shape))
    ours = sh.SwiftHohenbergPDE(rate=0.2, kc2=1.0, delta=0.7, bc="periodic")
    theirs = pde.SwiftHohenbergPDE(rate=0.2, kc2=1.0, delta=0.7, bc="periodic")
    np.testing.assert_allclose(
        ours.evolution_rate(u).data, theirs.evolution_rate(u).data, rtol=1e-12, atol=1e-12
    )


@pytest.mark.parametrize(("n", "m"), [(1, 0), (2, 0), (3, 0), (1, 2), (0, 2), (4, 0)])
def test_the_linear_growth_rate_of_a_fourier_mode(n: int, m: int) -> None:
    """A mode cos(kx x + ky y) of amplitude 1e-6 (g u^2 and u^3 are 1e-6 of the linear
    terms) grows at RK4's rate log R(sigma dt)/dt with sigma = eps - (1 - kappa^2)^2, kappa^2
    the five-point Laplacian's: equal to 1e-9. Against the continuum eps - (1 - k^2)^2 it
    differs by 2 |1 - k^2| b + b^2 with b = (kx^4 dx^2 + ky^4 dy^2)/12 >= |k^2 - kappa^2|."""
    grid = small_grid()
    (lx, ly), (dx, dy) = sh.domain(2), grid.discretization
    kx, ky = 2 * math.pi * n / lx, 2 * math.pi * m / ly
    x, y = np.meshgrid(*grid.axes_coords, indexing="ij")
    start = PDEState(1e-6 * np.cos(kx * x + ky * y), 0.0)
    eps, dt = 0.1, 0.01
    ds = MODEL.run(
        dataclasses.replace(request(eps, t_final=2.0, save_every=1.0), initial=start)
    ).dataset
    measured = math.log(ds.amplitude.values[-1] / ds.amplitude.values[0]) / 2.0
    kappa2 = float(sh.laplacian_symbol(grid, np.array(kx), np.array(ky)))
    z = float(sh.growth_rate(eps, kappa2)) * dt
    assert measured == pytest.approx(
        math.log(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) / dt, abs=1e-9
    )
    k2 = kx**2 + ky**2
    b = (kx**4 * dx**2 + ky**4 * dy**2) / 12
    assert abs(measured - float(sh.growth_rate(eps, k2))) <= 2 * abs(1 - k2) * b + b**2 + 1e-6


def constructed(kind: str) -> np.ndarray:
    grid = sh.make_grid(sh.Settings(periods=4, points=8))
    x, y = np.meshgrid(*grid.axes_coords, indexing="ij")
    stripes = 0.3 * np.cos(x)
    k2, k3 = (-0.5, math.sqrt(3) / 2), (-0.5, -math.sqrt(3) / 2)
    hexagons = 0.1 * (np.cos(x) + np.cos(k2[0] * x + k2[1] * y) + np.cos(k3[0] * x + k3[1] * y))
    noise = np.random.default_rng(3).standard_normal(x.shape)
    return {
        "stripes": stripes + 0.01 * noise,
        "oblique stripes": 0.3 * np.cos(k2[0] * x + k2[1] * y),
        "hexagons": hexagons + 0.01 * noise,
        "down hexagons": -hexagons,
        "stripes with a weak cross mode": stripes + 0.05 * np.cos(k2[0] * x + k2[1] * y),
        "uniform": 0.001 * noise,
    }[kind]


@pytest.mark.parametrize(
    ("kind", "expected"),
    [
        ("stripes", "stripes"),
        ("oblique stripes", "stripes"),
        ("hexagons", "hexagons"),
        ("down hexagons", "hexagons"),
        ("stripes with a weak cross mode", "stripes"),
        ("uniform", "uniform"),
    ],
)
def test_the_classifier_on_constructed_patterns(kind: str, expected: str) -> None:
    u = constructed(kind)
    values = {
        "amplitude": float(np.sqrt(np.mean(u**2))),
        "hexagonality": sh.hexagonality(u, sh.domain(4)),
    }
    assert MODEL.classify(values) == expected


def test_hexagonality_is_one_for_hexagons_and_zero_for_stripes() -> None:
    assert sh.hexagonality(constructed("hexagons") - 0.0, sh.domain(4)) > 0.9
    assert sh.hexagonality(constructed("oblique stripes"), sh.domain(4)) < 1e-20


def test_runs_are_deterministic_per_seed() -> None:
    a, b, c = (
        MODEL.run(request(0.3, 0.5, seed, t_final=1.0, save_every=0.5)).dataset
        for seed in (1, 1, 2)
    )
    xr.testing.assert_identical(a, b)
    assert not np.array_equal(a.u_final.values, c.u_final.values)


def test_continuation_is_exact() -> None:
    whole = MODEL.run(request(0.3, 0.5, t_final=2.0, save_every=0.5))
    half = MODEL.run(request(0.3, 0.5, t_final=1.0, save_every=0.5))
    rest = MODEL.run(
        dataclasses.replace(request(0.3, 0.5, t_final=2.0, save_every=0.5), start=half.end_state)
    )
    xr.testing.assert_identical(rest.dataset.drop_attrs(), whole.dataset.drop_attrs())


def test_an_unstable_step_is_refused() -> None:
    with pytest.raises(ValueError, match="stability limit"):
        MODEL.run(request(0.1, dt=0.05, save_every=0.5, t_final=1.0))


def amplitude_rates(a: np.ndarray, eps: float, g: float) -> np.ndarray:
    """The three real amplitude equations of docs/model/swift_hohenberg.md."""
    a1, a2, a3 = a
    return np.array(
        [
            eps * a1 + 2 * g * a2 * a3 - 3 * (a1**2 + 2 * a2**2 + 2 * a3**2) * a1,
            eps * a2 + 2 * g * a3 * a1 - 3 * (a2**2 + 2 * a3**2 + 2 * a1**2) * a2,
            eps * a3 + 2 * g * a1 * a2 - 3 * (a3**2 + 2 * a1**2 + 2 * a2**2) * a3,
        ]
    )


def largest_rate(a: np.ndarray, eps: float, g: float) -> float:
    """The largest real part of the eigenvalues of the Jacobian at ``a`` (central
    differences)."""
    h = 1e-7
    jac = np.array(
        [
            (amplitude_rates(a + h * e, eps, g) - amplitude_rates(a - h * e, eps, g)) / (2 * h)
            for e in np.eye(3)
        ]
    ).T
    return float(np.linalg.eigvals(jac).real.max())


@pytest.mark.parametrize("g", [0.3, 0.5, 1.0])
def test_the_amplitude_equation_boundaries(g: float) -> None:
    """theory(g) against the three-mode equations: hexagons R+ exist from eps_H and are
    stable up to eps_X; stripes are stable from eps_S (just inside and outside each bound)."""
    th = sh.theory(g)

    def hexagons(eps: float) -> float:
        r = (g + math.sqrt(g**2 + 15 * eps)) / 15
        np.testing.assert_allclose(amplitude_rates(np.full(3, r), eps, g), 0, atol=1e-14)
        return largest_rate(np.full(3, r), eps, g)

    def stripes(eps: float) -> float:
        return largest_rate(np.array([math.sqrt(eps / 3), 0, 0]), eps, g)

    d = 1e-3 * g**2
    assert hexagons(th["eps_H"] + d) < 0
    with pytest.raises(ValueError, match="math domain"):
        hexagons(th["eps_H"] - d)
    assert hexagons(th["eps_X"] - d) < 0 < hexagons(th["eps_X"] + d)
    assert stripes(th["eps_S"] - d) > 0 > stripes(th["eps_S"] + d)


def test_the_campaign_file_names_the_models_settings() -> None:
    """campaigns/swift_hohenberg.yaml (run by ``nematic run`` once the campaign core runs
    models through the registry): its model is registered, every numerics value and axis
    value is one the model accepts, and its chain walks a sweepable parameter."""
    import yaml

    path = Path(__file__).resolve().parents[2] / "campaigns" / "swift_hohenberg.yaml"
    spec = yaml.safe_load(path.read_text())
    model = get_model(spec["model"])
    settings = {s.name: s for s in model.settings}
    for name, value in spec["numerics"].items():
        assert settings[name].kind == "numerics"
        assert settings[name].accepts(value), (name, value)
    for name, values in spec["sweep"]["axes"].items():
        assert settings[name].kind == "parameter"
        assert settings[name].sweepable
        assert all(settings[name].accepts(v) for v in values)
    assert settings[spec["chain"]["axis"]].kind == "parameter"
    s = sh.Settings(**{**spec["numerics"], "eps": max(spec["sweep"]["axes"]["eps"])})
    sh.make_pde(s)  # its step is below the stability limit on its grid
