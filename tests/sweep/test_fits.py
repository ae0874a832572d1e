"""Fits recover known values from synthetic phase diagrams with noise, within their stated
intervals (sweep/analysis/). Synthetic data are fine here: these test the estimators; the
figures are tested on real runs in tests/sweep/test_figures.py."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from nematic_solids.sweep.analysis.anisotropy import anisotropy
from nematic_solids.sweep.analysis.fits_file import compute_fits, fit_notes, load_fits, write_fits
from nematic_solids.sweep.analysis.registry import option_problems, resolve
from nematic_solids.sweep.analysis.size_laws import (
    alpha_cr_from_sizes,
    patterned_level,
    size_scaling,
)
from nematic_solids.sweep.analysis.sizes import alpha_cr, peak_not_reached, scaling
from nematic_solids.sweep.analysis.statistics import bootstrap_seed_means
from nematic_solids.sweep.analysis.transition import fit_transition, transition
from nematic_solids.sweep.errors import FitError
from nematic_solids.sweep.files import atomic_to_netcdf


def phase(data: dict[str, np.ndarray], coords: dict[str, np.ndarray], **attrs) -> xr.Dataset:
    """A phase.nc-like Dataset: observables over (sweep dims..., seed)."""
    dims = [*coords, "seed"]
    n_seed = next(iter(data.values())).shape[-1]
    ds = xr.Dataset(
        {k: (dims, v) for k, v in data.items()},
        coords={**coords, "seed": np.arange(n_seed)},
        attrs=attrs,
    )
    shape = ds[next(iter(data))].shape
    ds["status"] = (
        dims,
        np.where(np.isfinite(ds[next(iter(data))].values), 1, 2).astype(np.int8).reshape(shape),
    )
    return ds


def subcritical_sigma2(rng, x, x0, n_seeds, spread=0.02):
    """sigma2_S(t_final): each seed jumps from ~1e-12 to ~1e-2 at its own threshold
    x0 + N(0, spread) (a subcritical transition depends on the initial noise)."""
    thr = x0 + spread * rng.standard_normal(n_seeds)
    high = 10 ** (-2 + 0.1 * rng.standard_normal((x.size, n_seeds)))
    low = 10 ** (-12 + 0.5 * rng.standard_normal((x.size, n_seeds)))
    return np.where(x[:, None] > thr[None, :], high, low)


# --------------------------------------------------------------------------- transition
@pytest.mark.parametrize("x0", [0.43, 0.5501, 0.78])
def test_transition_recovers_the_jump_within_its_interval(rng, x0):
    x = np.linspace(0.1, 1.0, 10)
    f = fit_transition(x, subcritical_sigma2(rng, x, x0, 20), n_boot=300, rng=rng)
    assert f.lower <= x0 <= f.upper
    assert f.grid_lower <= x0 <= f.grid_upper
    assert f.upper - f.lower <= 0.2 + 1e-12  # at most two grid cells with this seed spread
    assert f.jump > 8  # decades
    assert f.direction == 1
    assert f.fraction_high[0] == 0
    assert f.fraction_high[-1] == 1


def test_transition_interval_widens_when_seeds_disagree(rng):
    """Seeds whose thresholds straddle a grid value: the bootstrap moves the jump between two
    brackets, so the interval covers both."""
    x = np.linspace(0.1, 1.0, 10)
    v = subcritical_sigma2(rng, x, 0.5, 6, spread=0.08)
    f = fit_transition(x, v, n_boot=500, rng=rng)
    assert f.lower <= 0.5 <= f.upper
    assert np.any((f.fraction_high > 0) & (f.fraction_high < 1))


def test_transition_on_unsorted_axis_and_falling_observable(rng):
    x = np.array([0.3, 0.1, 0.2, 0.5, 0.4])
    v = np.where(x[:, None] < 0.33, 1e-2, 1e-9) * np.exp(0.1 * rng.standard_normal((5, 4)))
    f = fit_transition(x, v, n_boot=100, rng=rng)
    assert (f.grid_lower, f.grid_upper) == (0.3, 0.4)
    assert f.direction == -1
    assert f.location == pytest.approx(0.35)


def test_no_transition_below_min_jump(rng):
    x = np.linspace(0, 1, 6)
    v = 1e-3 * np.exp(0.3 * rng.standard_normal((6, 5)))
    f = fit_transition(x, v, n_boot=50, rng=rng)
    assert np.isnan(f.location)


def test_transition_dataset_fit_per_other_dim(rng):
    """Two values of K with different jumps; missing runs (NaN) are skipped."""
    x = np.linspace(0.1, 1.0, 10)
    truth = {1e-4: 0.43, 1e-3: 0.67}
    sig = np.stack([subcritical_sigma2(rng, x, x0, 8) for x0 in truth.values()])
    sig[0, 3, 2] = np.nan
    ds = phase({"sigma2_S": sig}, {"K": np.array(list(truth)), "alpha_minus_B": x})
    out = transition(ds, {"n_boot": 200})
    assert out["transition_location"].dims == ("K",)
    for k, x0 in truth.items():
        row = out.sel(K=k)
        assert float(row["transition_lower"]) <= x0 <= float(row["transition_upper"])
    assert out["transition_fraction_high"].dims == ("K", "alpha_minus_B")
    assert out["transition_location"].attrs["fit_axis"] == "alpha_minus_B"


# --------------------------------------------------------------------------- alpha_cr, scaling
K_TRUE = np.array([1e-5, 3e-5, 1e-4, 3e-4])
ACR_TRUE = np.array([0.30, 0.35, 0.40, 0.45])
AMB = np.linspace(0.6, 1.6, 6)


def sizes(rng, exponent=0.5, c=2.0, noise=0.05, n_seeds=30):
    """lambda = c (K / (alpha - B - alpha_cr))^exponent with 5 % log-normal noise per seed."""
    x = K_TRUE[:, None] / (AMB[None, :] - ACR_TRUE[:, None])
    return c * x[..., None] ** exponent * np.exp(noise * rng.standard_normal((*x.shape, n_seeds)))


def size_phase(lam, sigma2=None):
    sigma2 = np.full(lam.shape, 1e-2) if sigma2 is None else sigma2
    return phase({"lambda_peak": lam, "sigma2_S": sigma2}, {"K": K_TRUE, "alpha_minus_B": AMB})


@pytest.mark.parametrize("method", ["linear", "nonlinear"])
def test_alpha_cr_recovered_within_interval(rng, method):
    out = alpha_cr(size_phase(sizes(rng)), {"method": method, "n_boot": 200})
    lo, hi = out["alpha_cr_lower"].values, out["alpha_cr_upper"].values
    assert np.all((lo <= ACR_TRUE) & (hi >= ACR_TRUE)), (lo, out["alpha_cr"].values, hi)
    assert np.all(hi - lo < 0.1)
    np.testing.assert_allclose(out["alpha_cr_prefactor"].values, 2.0, rtol=0.1)
    np.testing.assert_array_equal(out["alpha_cr_n_points"].values, AMB.size)


def test_scaling_exponent_recovered_within_bootstrap_interval(rng):
    out = scaling(size_phase(sizes(rng)), {"n_boot": 300})
    beta = float(out["scaling_exponent"])
    lo, hi = float(out["scaling_exponent_lower"]), float(out["scaling_exponent_upper"])
    assert lo <= 0.5 <= hi
    assert lo < beta < hi
    assert hi - lo < 0.1
    assert float(out["scaling_prefactor"]) == pytest.approx(2.0, rel=0.1)
    assert int(out["scaling_used"].sum()) == K_TRUE.size * AMB.size
    assert np.all(
        (out["alpha_cr_lower"].values <= ACR_TRUE) & (out["alpha_cr_upper"].values >= ACR_TRUE)
    )


def test_power_law_fit_recovers_other_exponents(rng):
    """The exponent fit itself is not tied to 1/2: with alpha_cr given, any exponent."""
    for beta in (0.35, 0.5, 0.8):
        lam = sizes(rng, exponent=beta).mean(-1)
        f = size_scaling(K_TRUE, AMB, lam, alpha_cr=ACR_TRUE)
        assert f.exponent == pytest.approx(beta, abs=0.02)


def test_relaxed_runs_are_excluded_from_the_size_fits(rng):
    """Runs below the transition (sigma2_S ~ 1e-12) have meaningless sizes: the automatic
    level drops them, and the fit is unchanged."""
    lam = sizes(rng)
    sigma2 = np.full(lam.shape, 1e-2)
    lam_bad = lam.copy()
    lam_bad[:, 0, :5] = 0.01  # nonsense sizes...
    sigma2[:, 0, :5] = 1e-12  # ...of relaxed runs
    assert patterned_level(sigma2) == pytest.approx(10**-7)
    clean = scaling(size_phase(lam, sigma2), {"n_boot": 100})
    dirty = scaling(size_phase(lam_bad, sigma2), {"n_boot": 100})
    assert float(dirty["scaling_exponent"]) == pytest.approx(
        float(clean["scaling_exponent"]), abs=1e-12
    )
    assert patterned_level(np.full(5, 1e-2)) == 0.0  # no gap: every run counts


def test_size_fit_asks_for_select_when_another_dim_varies(rng):
    lam = sizes(rng, n_seeds=3)
    ds = phase(
        {"lambda_peak": np.stack([lam, lam]), "sigma2_S": np.full((2, *lam.shape), 0.1)},
        {"eps": np.array([0.0, 0.1]), "K": K_TRUE, "alpha_minus_B": AMB},
    )
    with pytest.raises(FitError, match="select"):
        scaling(ds, {"n_boot": 10})
    out = scaling(ds, {"n_boot": 10, "select": {"eps": 0.1}})
    assert np.isfinite(float(out["scaling_exponent"]))


def peaks(lam, t_final=100.0):
    """t_peak of every run: well before t_final (the peak was reached)."""
    return np.full(lam.shape, 0.4 * t_final)


def test_runs_without_a_peak_are_left_out_and_counted(rng):
    """Runs whose first sigma2_S peak is at t_final, or within one save interval of it, have
    a lambda_peak that is only lambda near t_final: left out of alpha_cr and scaling (exactly
    as if they were missing), and counted per point, per K and in total."""
    lam = sizes(rng, n_seeds=6)
    t_peak = peaks(lam)
    sigma2 = np.full(lam.shape, 1e-2)
    bad = lam.copy()
    t_peak[0, 0, :3] = 100.0  # at t_final
    t_peak[1, 2, 1] = 99.5  # within one save interval (save_every = 1)
    t_peak[3, 5, 0] = 99.0  # exactly one save interval before
    t_peak[2, 4, 2] = 98.5  # a peak 1.5 save intervals before t_final: reached, kept
    flagged = t_peak >= 99.0
    bad[flagged] *= 5.0  # still-growing patterns: meaningless sizes
    t_peak[3, 0, 4], sigma2[3, 0, 4] = 100.0, 1e-12  # relaxed run: not patterned anyway
    ds = phase(
        {"lambda_peak": bad, "sigma2_S": sigma2, "t_peak": t_peak},
        {"K": K_TRUE, "alpha_minus_B": AMB},
        num_t_final=100.0,
        num_save_every=1.0,
    )
    out = scaling(ds, {"n_boot": 100})

    expected = flagged.sum(-1)
    expected[3, 0] = 0
    np.testing.assert_array_equal(out["alpha_cr_unpeaked_count"].values, expected)
    assert out["alpha_cr_unpeaked_count"].dims == ("K", "alpha_minus_B")
    assert "t_final" in out["alpha_cr_unpeaked_count"].attrs["long_name"]
    np.testing.assert_array_equal(out["alpha_cr_n_unpeaked"].values, [3, 1, 0, 1])
    for name in ("alpha_cr", "scaling_exponent"):
        assert out[name].attrs["fit_n_unpeaked"] == 5
        assert out[name].attrs["fit_n_patterned"] == lam.size - 1
        assert out[name].attrs["fit_require_peak"] == 1
    np.testing.assert_array_equal(
        out["scaling_lambda_count"].values,
        6 - flagged.sum(-1) - (np.arange(6) == 0)[None, :] * [[0], [0], [0], [1]],
    )

    # the same fit as with those runs missing (NaN) and no peak check
    clean = lam.copy()
    clean[flagged] = np.nan
    clean[3, 0, 4] = np.nan
    ref = scaling(
        phase(
            {"lambda_peak": clean, "sigma2_S": np.full(lam.shape, 1e-2)},
            {"K": K_TRUE, "alpha_minus_B": AMB},
        ),
        {"n_boot": 100},
    )
    for name in (
        "alpha_cr",
        "alpha_cr_lower",
        "alpha_cr_upper",
        "scaling_exponent",
        "scaling_exponent_lower",
        "scaling_exponent_upper",
        "scaling_lambda_mean",
    ):
        np.testing.assert_allclose(out[name].values, ref[name].values, rtol=1e-12, err_msg=name)
    assert np.all(
        (out["alpha_cr_lower"].values <= ACR_TRUE) & (out["alpha_cr_upper"].values >= ACR_TRUE)
    )

    # require_peak: false keeps them (and the fit moves), peak_margin: 0 keeps t < t_final
    kept = scaling(ds, {"n_boot": 10, "require_peak": False})
    assert kept["scaling_exponent"].attrs["fit_n_unpeaked"] == 0
    assert int(kept["alpha_cr_unpeaked_count"].sum()) == 0
    assert float(kept["scaling_exponent"]) != pytest.approx(float(out["scaling_exponent"]))
    strict = alpha_cr(ds, {"n_boot": 10, "peak_margin": 0})
    assert strict["alpha_cr"].attrs["fit_n_unpeaked"] == 3
    # an observable at t_final has no peak to reach: nothing is left out by default
    lam_final = alpha_cr(
        ds.assign(lambda_final=ds["lambda_peak"]), {"n_boot": 10, "observable": "lambda_final"}
    )
    assert lam_final["alpha_cr"].attrs["fit_n_unpeaked"] == 0


def test_peak_check_with_swept_t_final_and_without_t_peak(rng):
    """t_final zipped with K (a coordinate on the K dim) sets each row's limit; a phase.nc
    without t_peak leaves every run in, and says so."""
    lam = sizes(rng, n_seeds=3)
    t_final = np.array([50.0, 100.0, 100.0, 200.0])
    t_peak = np.full(lam.shape, 60.0)  # reached, except where t_final = 50
    ds = phase(
        {"lambda_peak": lam, "sigma2_S": np.full(lam.shape, 1e-2), "t_peak": t_peak},
        {"K": K_TRUE, "alpha_minus_B": AMB},
        num_save_every=2.0,
    )
    ds = ds.assign_coords(t_final=("K", t_final))
    out = alpha_cr(ds, {"n_boot": 10})
    np.testing.assert_array_equal(out["alpha_cr_n_unpeaked"].values, [AMB.size * 3, 0, 0, 0])
    assert np.isnan(out["alpha_cr"].values[0])
    assert np.all(np.isfinite(out["alpha_cr"][1:]))
    assert fit_notes(out)[0].startswith(
        f"alpha_cr/scaling: {AMB.size * 3} of {lam.size} patterned run(s) left out"
    )
    blind = alpha_cr(ds.drop_vars("t_peak"), {"n_boot": 10})
    assert blind["alpha_cr"].attrs["fit_n_unpeaked"] == 0
    assert blind["alpha_cr"].attrs["fit_peak_check"] == "not done: phase.nc has no t_peak"
    assert "not looked for" in fit_notes(blind)[0]
    np.testing.assert_array_equal(
        peak_not_reached([10.0, 98.0, 99.0, 100.0, np.nan], 100.0, 2.0),
        [False, True, True, True, False],
    )


def acr_sizes(rng, acr, n_seeds=30, noise=0.05, amb=AMB):
    """Eq. (7) sizes with the critical activity ``acr`` for every K."""
    x = K_TRUE[:, None] / (amb[None, :] - acr)
    return 2.0 * x[..., None] ** 0.5 * np.exp(noise * rng.standard_normal((*x.shape, n_seeds)))


@pytest.mark.parametrize("method", ["linear", "nonlinear"])
def test_alpha_cr_is_bounded_at_zero(rng, method):
    """Data of a negative critical activity (-0.3): the unbounded fit finds about that, the
    default fit stops at the bound 0 and says so; a true alpha_cr of 0 is found at or just
    above 0, never below."""
    lam = acr_sizes(rng, -0.3)
    free = alpha_cr(size_phase(lam), {"method": method, "n_boot": 100, "alpha_cr_min": None})
    np.testing.assert_allclose(free["alpha_cr"].values, -0.3, atol=0.1)
    assert np.all(free["alpha_cr_upper"].values < 0)  # the data push it below zero
    np.testing.assert_array_equal(free["alpha_cr_at_bound"].values, 0)
    assert free["alpha_cr"].attrs["fit_alpha_cr_min"] == "none"

    out = scaling(size_phase(lam), {"method": method, "n_boot": 100})
    np.testing.assert_array_equal(out["alpha_cr"].values, 0.0)
    np.testing.assert_array_equal(out["alpha_cr_at_bound"].values, 1)
    np.testing.assert_array_equal(out["alpha_cr_lower"].values, 0.0)
    np.testing.assert_allclose(out["alpha_cr_bound_fraction"].values, 1.0)
    assert np.all(np.isfinite(out["alpha_cr_prefactor"].values))
    assert out["alpha_cr"].attrs["fit_alpha_cr_min"] == 0.0
    assert out["scaling_exponent"].attrs["fit_n_alpha_cr_at_bound"] == K_TRUE.size
    assert np.isfinite(float(out["scaling_exponent"]))
    np.testing.assert_allclose(out["scaling_x"].values, K_TRUE[:, None] / AMB[None, :])
    assert fit_notes(out)[-1] == (
        "alpha_cr at its bound 0.0 for K = 1e-05, 3e-05, "
        "0.0001, 0.0003 (the unbounded fit would put it lower)"
    )

    zero = alpha_cr(size_phase(acr_sizes(rng, 0.0, n_seeds=10)), {"method": method, "n_boot": 200})
    assert np.all(zero["alpha_cr"].values >= 0)
    assert np.all(zero["alpha_cr_lower"].values >= 0)
    assert np.all(zero["alpha_cr_lower"].values == 0)  # 0 lies within the interval
    assert np.all(zero["alpha_cr_upper"].values < 0.2)
    assert np.all(
        (zero["alpha_cr_bound_fraction"].values > 0) & (zero["alpha_cr_bound_fraction"].values < 1)
    )


def test_bounded_linear_fit_is_the_constrained_least_squares_optimum(rng):
    """At the bound the linear fit is the line through (alpha_cr_min, 0): no alpha_cr above
    the bound (each with its best slope) fits lambda^-2 better."""
    amb = np.array([0.5, 0.8, 1.1, 1.4, 2.0])
    lam = 2.0 * (1e-4 / (amb + 0.4)) ** 0.5 * np.exp(0.03 * rng.standard_normal(amb.size))
    y = lam**-2.0
    for bound in (0.0, 0.2):
        f = alpha_cr_from_sizes(amb, lam, 1e-4, alpha_cr_min=bound)
        assert f.at_bound
        assert f.alpha_cr == bound
        m = 1.0 / (f.prefactor**2 * 1e-4)

        def rss(acr):
            d = amb - acr
            slope = d @ y / (d @ d)
            return float(((y - slope * d) ** 2).sum())

        assert float(((y - m * (amb - bound)) ** 2).sum()) == pytest.approx(rss(bound))
        assert all(rss(a) >= rss(bound) for a in np.linspace(bound, 0.49, 50))
    free = alpha_cr_from_sizes(amb, lam, 1e-4, alpha_cr_min=None)
    assert free.alpha_cr < 0
    assert not free.at_bound
    inside = alpha_cr_from_sizes(amb, lam, 1e-4, alpha_cr_min=-5.0)
    assert inside == free
    # nonlinear: no admissible alpha_cr when the bound is at or above the smallest alpha - B
    assert np.isnan(
        alpha_cr_from_sizes(amb, lam, 1e-4, method="nonlinear", alpha_cr_min=0.5).alpha_cr
    )


# --------------------------------------------------------------------------- anisotropy
def test_anisotropy_slope_recovered_within_interval(rng):
    eps = np.linspace(0.0, 0.1, 5)
    chi = np.array([0.0, 5.0])
    slopes = np.array([0.5, 4.0])
    cos = slopes[:, None, None] * eps[None, :, None] + 0.02 + 0.03 * rng.standard_normal((2, 5, 20))
    out = anisotropy(phase({"cos2theta": cos}, {"chi": chi, "eps": eps}), {"n_boot": 400})
    lo, hi = out["anisotropy_slope_lower"].values, out["anisotropy_slope_upper"].values
    assert np.all((lo <= slopes) & (slopes <= hi))
    assert np.all(hi - lo < 1.0)
    assert out["anisotropy_mean"].dims == ("chi", "eps")


def test_anisotropy_with_one_seed_has_no_interval(rng):
    """A single seed has no seed-to-seed spread: the interval is NaN, not of zero width."""
    eps = np.linspace(0.0, 0.1, 5)
    cos = 2.0 * eps[None, :, None] + 0.01 * rng.standard_normal((1, 5, 1))
    out = anisotropy(
        phase({"cos2theta": cos}, {"chi": np.array([5.0]), "eps": eps}), {"n_boot": 50}
    )
    assert np.isfinite(out["anisotropy_slope"].values).all()
    assert np.isnan(out["anisotropy_slope_lower"].values).all()
    assert np.isnan(out["anisotropy_slope_upper"].values).all()


# --------------------------------------------------------------------------- plumbing
def test_bootstrap_seed_means_handle_missing_runs(rng):
    v = np.array([[1.0, 2.0, np.nan], [np.nan, np.nan, np.nan], [5.0, 5.0, 5.0]])
    b = bootstrap_seed_means(v, 200, rng)
    assert b.shape == (200, 3)
    assert np.all((b[:, 0] >= 1) & (b[:, 0] <= 2))
    assert set(np.unique(b[:, 0])) == {1.0, 1.5, 2.0}
    assert np.all(np.isnan(b[:, 1]))
    assert np.all(b[:, 2] == 5.0)


def test_same_phase_same_fits(rng):
    ds = size_phase(sizes(rng, n_seeds=5))
    a, _ = compute_fits(ds, [("scaling", {"n_boot": 50})])
    b, _ = compute_fits(ds, [("scaling", {"n_boot": 50})])
    xr.testing.assert_identical(a.drop_attrs(), b.drop_attrs())


def test_resolve_merges_included_fits_and_rejects_unknown():
    out = resolve(
        [
            ("alpha_cr", {"method": "nonlinear"}),
            ("scaling", {"n_boot": 10}),
            ("transition", {}),
            ("transition", {"axis": "chi"}),
        ]
    )
    assert out == [("scaling", {"method": "nonlinear", "n_boot": 10}), ("transition", {})]
    with pytest.raises(FitError, match="unknown fit 'scalling'"):
        resolve([("scalling", {})])


def test_bad_options_are_named(rng):
    ds = size_phase(sizes(rng, n_seeds=3))
    with pytest.raises(FitError, match="unknown option 'n_bot'"):
        scaling(ds, {"n_bot": 10})
    with pytest.raises(FitError, match="method"):
        alpha_cr(ds, {"method": "cubic", "n_boot": 5})
    with pytest.raises(FitError, match="'chi' is neither swept"):
        transition(ds, {"axis": "chi"})


def test_fits_nc_round_trip(rng, tmp_path):
    """Write-then-reopen: fits.nc keeps its variables, dims and attributes; a failing fit is
    recorded, not fatal."""
    ds = size_phase(sizes(rng, n_seeds=4), sigma2=10 ** rng.uniform(-3, -1, (4, 6, 4)))
    atomic_to_netcdf(ds.assign_attrs(campaign="synthetic"), tmp_path / "phase.nc")
    path, failures = write_fits(
        tmp_path,
        [
            ("scaling", {"n_boot": 20}),
            ("transition", {"n_boot": 20, "min_jump": 0.1}),
            ("anisotropy", {}),
        ],
    )
    assert path == tmp_path / "fits.nc"
    assert set(failures) == {"anisotropy"}  # no eps axis and no cos2theta
    back = load_fits(tmp_path)
    assert back["alpha_cr"].dims == ("K",)
    assert back["scaling_x"].dims == ("K", "alpha_minus_B")
    assert back["scaling_exponent"].attrs["fit"] == "scaling"
    assert back.attrs["campaign"] == "synthetic"
    assert "anisotropy" in back.attrs["failed_fits"]
    assert not list(tmp_path.glob(".*tmp"))


def test_option_problems_for_campaign_validation():
    assert option_problems("scaling", {"method": "nonlinear", "n_boot": 50}) == []
    problems = option_problems("transition", {"axes": "chi", "n_boot": 0})
    assert any("unknown option 'axes'" in p for p in problems)
    assert any("n_boot = 0" in p for p in problems)
    problems = option_problems(
        "scaling", {"alpha_cr_min": "zero", "require_peak": 1, "peak_margin": -1}
    )
    assert any("alpha_cr_min = 'zero'" in p for p in problems)
    assert any("require_peak = 1" in p for p in problems)
    assert any("peak_margin = -1" in p for p in problems)
    assert (
        option_problems("alpha_cr", {"alpha_cr_min": None, "require_peak": False, "peak_margin": 0})
        == []
    )
    assert option_problems("nope", {}) == [
        "unknown fit 'nope'; registered: alpha_cr, anisotropy, moduli, recovery, scaling, "
        "stability, "
        "transition"
    ]


def test_a_transition_must_cross_the_level_it_is_given():
    """Without ``crossing`` the largest step of a texture relaxing at round-off level is a
    'jump'; with it, only a step from below the level to above it (or back) is."""
    x = [0.0, 1.0, 2.0, 3.0]
    relaxing = [[1e-12, 2e-12], [1e-14, 1e-14], [1e-15, 1e-15], [1e-18, 1e-18]]
    assert fit_transition(x, relaxing).location == 2.5
    assert np.isnan(fit_transition(x, relaxing, crossing=1e-6).location)
    patterned = [[1e-2, 2e-2], [1e-13, 1e-13], [1e-15, 1e-15], [1e-18, 1e-18]]
    f = fit_transition(x, patterned, crossing=1e-6)
    assert f.location == 0.5
    assert (f.lower, f.upper) == (0.0, 1.0)


def test_a_nan_transition_says_why():
    """One seed of two never patterns: the geometric seed mean (the mean of log10) stays a
    decade below the class threshold 1e-6 on the patterned side and never crosses it, so the
    fit is NaN and says so (naming the arithmetic mean, which does cross); too few points and a
    step below min_jump give their own reasons; a fit over a branch names the branch."""
    x = [0.0, 1.0, 2.0]
    one_seed = [[1e-14, 1e-14], [1e-14, 1e-3], [1e-14, 1e-2]]  # geometric means 1e-8.5, 1e-8
    f = fit_transition(x, one_seed, crossing=1e-6)
    assert np.isnan(f.location)
    assert "never crosses 1e-06, the class threshold" in f.reason
    assert "mean: arithmetic" in f.reason
    g = fit_transition(x, one_seed, crossing=1e-6, mean="arithmetic")
    assert g.location == 0.5
    assert g.reason == ""
    assert (
        "1 grid value(s) with a finite seed mean"
        in fit_transition(x, [[1e-3, 1e-3], [np.nan, np.nan], [np.nan, np.nan]]).reason
    )
    flat = fit_transition(x, [[1e-3, 1e-3], [2e-3, 2e-3], [3e-3, 3e-3]])
    assert "below min_jump 1" in flat.reason
    values = np.array([one_seed, [[1e-14, 1e-14], [1e-3, 1e-3], [1e-2, 1e-2]]])
    ds = phase(
        {"sigma2_S": values},
        {"branch": np.array(["up", "down"]), "alpha_minus_B": np.array(x)},
    )
    out = transition(ds, {"axis": "alpha_minus_B", "crossing": 1e-6, "n_boot": 50})
    assert np.isnan(out.transition_location.sel(branch="up"))
    assert float(out.transition_location.sel(branch="down")) == 0.5
    why = out.transition_location.attrs["nan_reason"]
    assert why.startswith("branch = up: the geometric seed mean")
    assert "branch = down" not in why
    assert np.isnan(float(out.transition_loop_width))
    assert out.transition_loop_width.attrs["nan_reason"].startswith(
        "no transition on a branch: branch = up:"
    )
