"""The initial director textures (model/initial.py, docs/model/texture.md): the band-limited
field and the per-node ("initial random orientation") texture: their statistics, determinism
and what each does across resolutions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from nematic_solids.model.errors import ParameterError
from nematic_solids.model.initial import band_limited_field, initial_fields, per_node_field
from nematic_solids.model.parameters import Numerics, Parameters, check_compatible


def _angles(q1, q2):
    return np.arctan2(q2, q1)  # = 2 theta in (-pi, pi]


@pytest.mark.parametrize("initial", ["band", "per_node"])
def test_both_textures_have_uniform_order_and_are_seeded(initial):
    p = Parameters(initial=initial)
    q1, q2, A = initial_fields(p, 128, seed=3)
    np.testing.assert_allclose(np.hypot(q1, q2), p.S0, rtol=1e-12)  # S = S0 everywhere
    assert not A.any()
    again = initial_fields(p, 128, seed=3)
    np.testing.assert_array_equal(q1, again[0])
    other = initial_fields(p, 128, seed=4)
    assert not np.allclose(q1, other[0])


def test_per_node_angles_are_uniform_and_independent_between_nodes():
    n = 128
    q1, q2, _ = initial_fields(Parameters(initial="per_node"), n, seed=0)
    two_theta = _angles(q1, q2)
    # uniform director angle: Kolmogorov-Smirnov against U(-pi, pi) (16384 samples)
    assert stats.kstest(two_theta.ravel(), stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue > 1e-3
    z = np.exp(1j * two_theta)
    assert abs(z.mean()) < 4 / n  # no net alignment: |<e^{2 i theta}>| ~ 1 / N
    # neighbours are independent: the correlation at lag 1 (and 2) along both axes is
    # zero within a few standard errors (1 / N), where the band texture's is close to 1
    for axis in (0, 1):
        for lag in (1, 2):
            c = (z * np.conj(np.roll(z, lag, axis=axis))).mean()
            assert abs(c) < 4 / n
    qb1, qb2, _ = initial_fields(Parameters(initial="band", noise_modes=16), n, seed=0)
    zb = np.exp(1j * _angles(qb1, qb2))
    assert abs((zb * np.conj(np.roll(zb, 1, axis=0))).mean()) > 0.8


def test_per_node_field_is_white():
    # white noise: the same mean power in the low and the high half of the wavenumbers
    n = 128
    psi = per_node_field(5, n)
    power = np.abs(np.fft.fft2(psi)) ** 2 / n**2
    k = np.hypot(*np.meshgrid(np.fft.fftfreq(n) * n, np.fft.fftfreq(n) * n, indexing="ij"))
    low, high = power[(k > 0) & (k < n / 4)].mean(), power[k >= n / 4].mean()
    assert abs(np.mean(np.abs(psi) ** 2) - 1) < 0.03
    assert 0.9 < low / high < 1.1
    # the band field has no power beyond its band
    band = np.abs(np.fft.fft2(band_limited_field(5, 16, n))) ** 2
    assert band[k > 16.5].sum() < 1e-20 * band.sum()


def test_per_node_amplitude_noise_has_the_requested_rms():
    p = Parameters(initial="per_node", S0=0.0, noise_amplitude=0.01)
    q1, q2, _ = initial_fields(p, 128, seed=1)
    rms = np.sqrt(np.mean(q1**2 + q2**2))
    assert abs(rms - 0.01) < 0.0005


def test_per_node_is_a_different_field_at_every_resolution():
    # (the band texture is one field at every resolution: tests/model/test_dynamics.py)
    pn = Parameters(initial="per_node")
    coarse, fine = initial_fields(pn, 32, 2)[0], initial_fields(pn, 64, 2)[0]
    assert coarse.shape == (32, 32)
    assert fine.shape == (64, 64)
    # the fine grid's field, averaged onto the coarse cells, keeps little of its amplitude
    # (white noise: a quarter of the variance), unlike a smooth field
    block = fine.reshape(32, 2, 32, 2).mean(axis=(1, 3))
    assert np.var(block) < 0.4 * np.var(fine)


def test_only_the_band_texture_needs_its_band_resolved():
    with pytest.raises(ParameterError, match="noise_modes"):
        check_compatible(Parameters(noise_modes=16), Numerics(resolution=32))
    check_compatible(Parameters(initial="per_node", noise_modes=16), Numerics(resolution=32))


def test_unknown_texture_is_refused():
    with pytest.raises(ParameterError, match="band or per_node"):
        Parameters(initial="white")
    with pytest.raises(ParameterError):
        Parameters.from_dict({"initial": 3})
