"""Rheology (nematic_solids.model.observables.macroscopic_stress,
nematic_solids.sweep.analysis.rheology): the macroscopic stress of the passive matrix under a pure
shear is the neo-Hookean one, exactly; the moduli fit gives the passive matrix's G' (the first
Fourier coefficient of that stress) and G'' = 0, and recovers known moduli, drift and harmonics from
a synthetic series; an active campaign's moduli are written to fits.nc."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from scipy.integrate import quad
from typer.testing import CliRunner

from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run
from nematic_solids.sweep.analysis.rheology import fit_moduli
from nematic_solids.sweep.cli import app

PASSIVE = {"noise_modes": 8, "chi": 0.0, "B": 0.0, "alpha": 0.0}


def _neo_hookean_shear(e, kappa):
    """<(P11 - P22)/2> of the 2-D neo-Hookean matrix (G = 1) under F = diag(1 + e, 1 - e):
    half of dW/de, W = (tr C / J - 2)/2 + kappa (J - 1)^2 / 2."""
    return 2 * e / (1 - e**2) ** 2 + kappa * e**3


@pytest.mark.parametrize("mechanics", ["finite", "linear"])
def test_the_passive_stress_and_moduli_are_the_analytic_ones(mechanics):
    eps0, period = 0.05, 8.0
    p = Parameters.from_dict(
        {**PASSIVE, "protocol": {"eps": {"sine": {"amplitude": eps0, "period": period}}}}
    )
    ds = run(p, Numerics(resolution=32, t_final=24, save_every=0.25, mechanics=mechanics), 0)
    t = ds.t.values
    e = eps0 * np.sin(2 * np.pi * t / period)
    exact = _neo_hookean_shear(e, p.kappa) if mechanics == "finite" else 2 * e
    assert np.abs(ds.stress_shear.values - exact).max() < 1e-12
    assert np.abs(ds.stress_xy.values).max() < 1e-12
    got = fit_moduli(t, ds.stress_shear.values, eps0, period, 0.0, period)
    # G' is the first Fourier coefficient of the exact response over 2 eps0
    a1 = quad(
        lambda f: _neo_hookean_shear(eps0 * np.sin(f), p.kappa) * np.sin(f) / np.pi, 0, 2 * np.pi
    )[0]
    want = a1 / (2 * eps0) if mechanics == "finite" else 1.0
    assert got["storage"] == pytest.approx(want, rel=1e-6)
    assert abs(got["loss"]) < 1e-9
    if mechanics == "finite":
        assert got["storage"] > 1.0  # the neo-Hookean matrix stiffens
        assert 1e-3 < got["nonlinearity"] < 0.05
    else:
        assert got["nonlinearity"] < 1e-9


@pytest.mark.parametrize("mechanics", ["linear", "finite"])
@pytest.mark.parametrize("period", [10.0, 50.0])
def test_the_isotropic_state_has_the_analytic_active_moduli(mechanics, period):
    """The uniform isotropic state (S0 = 0) under eps0 sin(w t): the shear orders Q through B
    (gamma q' = -A0 q + B eps), the active stress (alpha - B) q adds to the matrix's 2 eps, and
    A stays 0 (tr sigma = 0): G* = 1 + (alpha - B) B / (2 (A0 + i w gamma)). Its loss modulus
    is negative for alpha - B > 0: the activity does work on the rheometer."""
    eps0, amb = 1e-3, 0.3
    protocol = {"eps": {"sine": {"amplitude": eps0, "period": period}}}
    p = Parameters.from_dict(
        {"S0": 0.0, "noise_modes": 8, "alpha_minus_B": amb, "protocol": protocol}
    )
    num = Numerics(resolution=32, t_final=6 * period, save_every=period / 40, mechanics=mechanics)
    ds = run(p, num, 0)
    got = fit_moduli(ds.t.values, ds.stress_shear.values, eps0, period, 0.0, 3 * period)
    w = 2 * np.pi / period
    want = 1 + amb * p.B / (2 * (p.A0 + 1j * w * p.gamma))
    tol = 2e-4 if mechanics == "linear" else 2e-3  # finite strain: O(eps0) corrections
    assert got["storage"] == pytest.approx(want.real, abs=tol)
    assert got["loss"] == pytest.approx(want.imag, abs=tol)
    assert got["loss"] < 0


def test_the_fit_recovers_known_moduli_drift_and_harmonics():
    t = np.arange(0.0, 60.0, 0.5)
    phi = 2 * np.pi * (t - 5.0) / 10.0
    eps0, g1, g2 = 0.02, 1.7, 0.4
    stress = (
        0.3 + 1e-3 * t + 2 * eps0 * (g1 * np.sin(phi) + g2 * np.cos(phi)) + 1e-4 * np.sin(3 * phi)
    )
    got = fit_moduli(t, stress, eps0, 10.0, 5.0, 15.0)
    assert got["storage"] == pytest.approx(g1, rel=1e-9)
    assert got["loss"] == pytest.approx(g2, rel=1e-9)
    assert got["nonlinearity"] == pytest.approx(1e-4 / (2 * eps0 * np.hypot(g1, g2)), rel=1e-6)
    assert np.isnan(fit_moduli(t[:10], stress[:10], eps0, 10.0, 5.0, 15.0)["storage"])


RHEO = """\
name: rheo
parameters: {noise_modes: 8}
protocol:
  eps: {sine: {start: 4}}
numerics: {resolution: 32, t_final: 16, save_every: 0.5}
sweep:
  axes:
    alpha_minus_B: [0.0, 0.8]
    eps_amplitude: [0.005, 0.01]
    eps_period: [4]
seeds: 1
fits: [{moduli: {skip: 1}}]
figures: [moduli]
execution: {workers: 2}
"""


def test_a_rheology_campaign_writes_the_moduli(tmp_path):
    path = tmp_path / "rheo.yaml"
    path.write_text(RHEO)
    result = CliRunner().invoke(app, ["run", str(path), "--results", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "results" / "rheo" / "figures" / "moduli.png").stat().st_size > 10_000
    fits = xr.open_dataset(tmp_path / "results" / "rheo" / "fits.nc")
    g = fits.moduli_storage_mean
    assert g.dims == ("alpha_minus_B", "eps_amplitude", "eps_period")
    assert np.isfinite(g).all()
    # at alpha - B = 0 (B = 0.5, chi = 10: a passive-like matrix with the nemato-elastic
    # coupling) the response is linear in the amplitude
    zero = g.sel(alpha_minus_B=0.0, eps_period=4.0).values
    assert zero[0] == pytest.approx(zero[1], rel=1e-2)
