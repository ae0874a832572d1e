"""The snapshot picture (sweep/figures/snapshot.py: fig2 panel (a), `nematic simulate --png`):
the I1bar background's colour bar has plain, short tick labels however close I1bar is to 2
(no offset "+2", no "1e-5" multiplier), and its label says what the numbers are; a background
uniform to rounding is drawn uniform."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from nematic_solids.sweep.figures.snapshot import background, draw_snapshot, snapshot_figure


def run_dataset(i1bar: np.ndarray) -> xr.Dataset:
    """A run Dataset with one snapshot (what nematic_solids.model.simulate.run writes, reduced)."""
    n = i1bar.shape[0]
    x = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(x, x, indexing="ij")
    theta = 0.5 * np.sin(2 * np.pi * X)
    S = 0.1 + 0.05 * np.cos(2 * np.pi * Y)
    t = np.arange(0.0, 11.0)
    field = ("snapshot_time", "x", "y")
    return xr.Dataset(
        {
            "q1": (field, (S * np.cos(2 * theta))[None]),
            "q2": (field, (S * np.sin(2 * theta))[None]),
            "I1bar": (field, i1bar[None].astype(np.float32)),
            "sigma2_S": ("t", 1e-3 * t),
        },
        coords={"x": x, "y": x, "snapshot_time": [10.0], "t": t},
        attrs={"param_alpha_minus_B": 0.5, "seed": 0, "num_mechanics": "linear", "status": "ok"},
    )


def pattern(n: int = 32) -> np.ndarray:
    x = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(x, x, indexing="ij")
    return np.sin(np.pi * X) ** 2 * np.cos(np.pi * Y) ** 2


def test_background_is_i1bar_minus_2_scaled_to_plain_numbers():
    values, label = background(2.0 + 9.3e-5 * pattern())
    assert 1 <= np.abs(values).max() < 10
    assert r"10^{5}\,(\bar I_1 - 2)" in label
    values, label = background(2.0 + 0.04 + 0.003 * pattern())  # strained: no scaling
    np.testing.assert_allclose(values, 0.04 + 0.003 * pattern(), rtol=1e-12)
    assert label.startswith(r"$\bar I_1 - 2$")
    values, label = background(np.full((4, 4), 2.0))  # no deformation at all
    assert np.all(values == 0)
    assert label.startswith(r"$\bar I_1 - 2$")


@pytest.mark.parametrize("amplitude", [3e-6, 9.3e-5, 4.5e-3, 0.07])
def test_background_colorbar_ticks_are_plain(amplitude):
    """The failure this replaces: I1bar = 2 + 1e-5 ... gave tick labels '2.000025' or an
    offset text '+2' with a multiplier '1e-5'."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5, 5))
    ax = fig.add_subplot()
    draw_snapshot(ax, run_dataset(2.0 + amplitude * pattern()))
    fig.draw_without_rendering()  # sets the tick labels and the offset text
    cb = ax.images[0].colorbar
    assert cb is not None
    axis = cb.ax.xaxis  # the background's colour bar is horizontal, below the snapshot
    labels = [t.get_text() for t in axis.get_ticklabels() if t.get_text()]
    assert 2 <= len(labels) <= 6
    for text in labels:
        assert "e" not in text.lower()
        assert "+" not in text
        assert len(text) <= 5, labels
        float(text.replace("\N{MINUS SIGN}", "-"))
    assert axis.get_offset_text().get_text() == ""
    assert r"(\bar I_1 - 2)" in cb.ax.get_xlabel() or r"\bar I_1 - 2" in cb.ax.get_xlabel()
    assert "background" in cb.ax.get_xlabel()


def test_snapshot_figure_writes_a_png(tmp_path):
    path = snapshot_figure(run_dataset(2.0 + 2e-5 * pattern()), tmp_path / "snap.png")
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_a_background_uniform_to_rounding_is_drawn_uniform():
    """Fig. 4's panel (4): I1bar - 2 between 0.0100250 and 0.0100252 (uniform shear, float32):
    drawn as one grey (its mean) in a colour range floored to 1e-3 of the scale, and the label
    says uniform; a pattern's background keeps its own values and range."""
    from matplotlib.figure import Figure

    rng = np.random.default_rng(0)
    flat = 2.0 + 0.010025 + 2e-7 * rng.random((32, 32))
    for field, uniform in ((flat, True), (2.0 + 0.01 + 0.003 * pattern(), False)):
        fig = Figure(figsize=(5, 5))
        ax = fig.add_subplot()
        draw_snapshot(ax, run_dataset(field))
        image = ax.images[0]
        lo, hi = image.get_clim()
        values, _ = background(field.astype(np.float32))
        drawn = np.asarray(image.get_array())
        if uniform:
            assert hi - lo == pytest.approx(1e-3 * np.abs(values).max(), rel=1e-6)
            assert "uniform" in str(image.get_label())
            assert np.ptp(drawn) == 0.0  # one grey: no disc of rounding
            assert drawn.flat[0] == pytest.approx(0.5 * (values.min() + values.max()), rel=1e-6)
            rgba = image.to_rgba(drawn)
            assert np.ptp(rgba, axis=(0, 1)).max() == 0.0
        else:
            assert (lo, hi) == pytest.approx((values.min(), values.max()), rel=1e-6)
            assert "uniform" not in str(image.get_label())
            assert np.ptp(drawn) > 0.5 * (values.max() - values.min())
