"""Pattern size and the first-peak rules: a single mode, the Fig. A1 instability's fastest mode,
Fig. 3 patterns, and synthetic sigma2_S(t) series."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nematic_solids.model.fourier import SpectralGrid
from nematic_solids.model.observables import (
    first_peak,
    growth_peak,
    pattern_size,
    pattern_size_mean,
    radial_spectrum,
)
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run
from nematic_solids.model.stability import max_growth_rate

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.mark.parametrize(("mode", "n"), [((3, 4), 64), ((0, 7), 64), ((6, 8), 128), ((1, 1), 32)])
def test_single_mode_on_noise_gives_its_wavelength_within_one_shell(mode, n, rng):
    """S = S0 + a cos(2 pi (i x + j y)) + noise: lambda = L / |(i, j)| within one k-shell,
    although the noise spreads power over every shell (the mean-|k| length does not)."""
    g = SpectralGrid(n)
    x = (np.arange(n) + 0.5) / n
    i, j = mode
    S = 0.3 + 0.05 * np.cos(2 * np.pi * (i * x[:, None] + j * x[None, :]))
    S += 0.01 * rng.standard_normal((n, n))
    kn = np.hypot(i, j)
    lam = pattern_size(S, g)
    assert abs(1.0 / lam - kn) <= 1.0, (lam, 1 / kn)
    E = radial_spectrum(S, g)
    assert int(np.argmax(E)) == round(kn)
    assert np.isnan(pattern_size(np.full((n, n), 0.2), g))
    assert np.isnan(pattern_size_mean(np.full((n, n), 0.2), g))


def test_radial_spectrum_is_parseval():
    """The shells partition the spectrum: sum E(n) = N^2 * N^2 * variance (unnormalised FFT)."""
    g = SpectralGrid(32)
    S = np.random.default_rng(1).random((32, 32))
    E = radial_spectrum(S, g)
    assert E.sum() == pytest.approx(32**4 * np.var(S))


def test_fig_a1_lambda_reaches_the_fastest_growing_mode():
    """Fig. A1's setting above threshold (chi (alpha - B) = 10, eps = 0.15: growth rate 0.16 /
    tau, fastest lattice mode 2 pi (0, 1) by nematic_solids.model.stability): lambda reaches L /
    |(0, 1)| (within 5 % by t = 60) while the mean-|k| length stays far below it."""
    p = Parameters.from_dict(
        dict(
            S0=0.0,
            A0=1.0,
            alpha_minus_B=1.0,
            B=0.5,
            K=1e-4,
            chi=10.0,
            eps=0.15,
            noise_amplitude=1e-3,
            noise_modes=8,
            zeta=1.0,
        )
    )  # campaigns/figA1.yaml's constants
    om, mode = max_growth_rate(p, incompressible=True, nmax=12)
    assert om.real > 0.1
    ds = run(
        p,
        Numerics(
            resolution=32,
            t_final=60,
            save_every=5,
            mechanics="linear",
            incompressible=True,
            tolerance=1e-4,
        ),
        seed=0,
    )
    assert ds.attrs["status"] == "ok"
    assert float(ds["lambda"][-1]) == pytest.approx(1.0 / np.hypot(*mode), rel=0.05)
    assert float(ds["lambda_mean"][-1]) < 0.8
    lam = ds["lambda"].values[1:]
    assert lam[-1] > lam[len(lam) // 2] > lam[0]  # approaches the box mode as it grows


def test_fig3_patterns_are_pinned_neither_to_the_box_nor_to_the_grid():
    """Fig. 3's regime (alpha - B = 1, K = 1e-5, 3e-5, 1e-4, 128^2): at the end of the growth
    phase lambda lies well inside (8 grid spacings, box) and grows with K."""
    lam = []
    for K in (1e-5, 3e-5, 1e-4):
        ds = run(
            Parameters.from_dict({"alpha_minus_B": 1.0, "K": K}),
            Numerics(resolution=128, t_final=60, save_every=1, mechanics="linear"),
            0,
        )
        assert ds.attrs["status"] == "ok"
        assert 5 < float(ds["t_peak"]) < 59  # the growth phase ended inside the run
        # (t = 15 / 24 / 41 for the three K)
        lam.append(float(ds["lambda_peak"]))
        assert 8 / 128 < lam[-1] < 0.75, (K, lam[-1])
    assert lam[0] < lam[1] < lam[2]


def _series(t: np.ndarray, bumps: list[tuple[float, float]], *, overshoot: float = 0.0):
    """A sigma2_S-like curve: decay of the initial noise, logistic growth to a plateau near
    t = 20 with an optional overshoot, and Gaussian bumps (time, height) on the plateau."""
    v = 0.002 * np.exp(-t) + 0.01 / (1 + np.exp(-(t - 12.0) / 1.5)) + 2e-6 * t  # slow creep
    v += overshoot * np.exp(-(((t - 20.0) / 3.0) ** 2))
    for tb, hb in bumps:
        v += hb * np.exp(-(((t - tb) / 6.0) ** 2))
    return v


def test_growth_peak_ignores_bumps_on_a_plateau():
    """A plateau with small coarsening bumps (3 % of it, the first at t = 120): the growth-peak
    rule returns the end of the growth phase (90 % of the logistic rise at t = 15.3, later by the
    creep), the literal rule the first bump."""
    t = np.arange(0.0, 300.0, 1.0)
    v = _series(t, [(120.0, 3e-4), (200.0, 5e-4)])
    assert 13 <= t[growth_peak(v)] <= 20
    assert t[first_peak(v)] == pytest.approx(120.0, abs=2)
    # a late global maximum (+6 %) followed by a decline to below the plateau (as in a 128^2
    # Fig. 2 run at t = 230-300): prominent, but not the growth phase's peak
    late = _series(t, [(230.0, 9e-4)]) - 1.5e-3 * np.clip((t - 240.0) / 60.0, 0.0, 1.0)
    assert 13 <= t[growth_peak(late)] <= 20


def test_growth_peak_takes_a_clean_overshoot():
    """A clear overshoot (30 % above the plateau) is Fig. 3's first peak under both rules."""
    t = np.arange(0.0, 300.0, 1.0)
    v = _series(t, [(150.0, 3e-4)], overshoot=0.003)
    assert t[growth_peak(v)] == pytest.approx(t[first_peak(v)])
    assert 18 <= t[growth_peak(v)] <= 22


def test_growth_peak_of_a_monotone_rise_is_at_its_end_and_noise_wiggles_are_skipped():
    """Still growing at t_final: the last samples (not peaked; fits leave such runs out). An
    early wiggle of the decaying noise is no peak either."""
    t = np.arange(0.0, 100.0, 1.0)
    v = 1e-4 * np.exp(t / 20.0)
    assert growth_peak(v) >= len(t) - 3
    w = _series(t, [])
    w[3] += 1e-4  # a wiggle at the noise level
    assert growth_peak(w) > 5
    assert growth_peak(np.array([])) == 0
    with_nan = _series(t, [])
    with_nan[50:] = np.nan  # a failed run's tail
    assert 10 <= growth_peak(with_nan) < 50


def test_growth_peak_skips_an_early_decaying_bump_before_the_main_rise():
    """A fine texture first relaxes: sigma2_S rises to a small maximum at t ~ 1 and decays
    to a trough before the pattern grows; the rule reads the end of the later, main rise."""
    t = np.arange(0.0, 150.0, 0.5)
    bump = 3e-4 * (t / 1.5) * np.exp(1 - t / 1.5)  # rises and decays over a few tau
    main = 1e-2 / (1 + np.exp(-(t - 40.0) / 3.0))
    v = bump + main + 1e-9
    tp = t[growth_peak(v, t)]
    assert 44 <= tp <= 55  # after the logistic's 90 % point (46.6), never at the bump
    assert v[growth_peak(v, t)] > 0.5 * v.max()


def test_growth_peak_skips_a_rise_that_stalls_far_below_the_pattern():
    """The texture's relaxation raises sigma2_S fast to a few % of the pattern's level and
    stalls; the pattern grows later, more slowly: that later growth's end is the peak."""
    t = np.arange(0.0, 200.0, 1.0)
    early = 5e-4 * (1 - np.exp(-t / 1.0))
    main = 1e-2 / (1 + np.exp(-(t - 60.0) / 6.0))
    v = early + main
    assert 70 <= t[growth_peak(v, t)] <= 90


@pytest.mark.parametrize(
    ("name", "window"),
    [
        # real runs (128^2, linear mechanics; the files' headers say how they were made) on
        # which the rule without the main-rise search returned t = 0.75, 3 and 4
        ("per_node_K1e-5_amb1.0_seed0", (35, 50)),
        ("band32_K1e-5_amb0.6_seed0", (35, 50)),
        ("band16_K3e-5_amb0.6_seed0", (28, 45)),
    ],
)
def test_growth_peak_on_real_series_with_early_transients(name, window):
    data = np.loadtxt(DATA / f"growth_{name}.csv", delimiter=",")
    t, s, lam = data.T
    i = growth_peak(s, t)
    assert window[0] <= t[i] <= window[1]
    assert s[i] > 0.5 * s.max()
    assert lam[i] > 0.15  # the pattern's size, not the texture's (~0.02-0.1 L at t < 5)
