"""Verification (sweep/verify, ``nematic verify``): the ``verify:`` section and its errors, a
variant's settings at a point, the sample (transition brackets and corners), the verdicts from
known records, the per-node texture carried to a finer grid, and a real tiny campaign run,
verified, resumed and verified before its grid."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.model.initial import (
    band_limited_field,
    initial_fields,
    per_node_field,
    spectral_interpolate,
)
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.sweep.campaign import Variant
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.identity import PointHasher
from nematic_solids.sweep.spec import parse_campaign
from nematic_solids.sweep.spec.verify import resolve
from nematic_solids.sweep.store import Record
from nematic_solids.sweep.verify import CHANGED, CONVERGED, MISSING, NOT_COMPARED
from nematic_solids.sweep.verify.measure import verify_dataset
from nematic_solids.sweep.verify.sample import plan_sample
from nematic_solids.sweep.verify.summary import summary_line

BASE = """\
name: v
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: 2, save_every: 0.5, mechanics: linear}}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.5, 0.9]
    K: [1.0e-4, 1.0e-3]
seeds: 3
fits: [transition]
figures: [fig2]
execution: {{workers: 2}}
{verify}
"""
VERIFY = """\
verify:
  seeds: 2
  variants:
    - resolution: x2
    - tolerance: /10
    - seeds: [7, 8]
"""


def campaign(verify: str = VERIFY):
    return parse_campaign(BASE.format(verify=verify), "v.yaml")


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


# --------------------------------------------------------------------------- the section
def test_the_section_reads_variants_seeds_and_defaults():
    spec = campaign().verify
    assert spec is not None
    assert [v.name for v in spec.variants] == ["resolution x2", "tolerance /10", "seeds=7,8"]
    assert spec.variants[2].seeds == (7, 8)
    assert not spec.variants[2].settings
    assert (spec.seeds, spec.threshold, spec.points, spec.corners, spec.before) == (
        2,
        0.05,
        None,
        True,
        False,
    )
    assert campaign("").verify is None


@pytest.mark.parametrize(
    ("section", "where", "says"),
    [
        ("verify: {variants: [{resolution: x0.1}]}", "verify.variants[0]", "resolution = 3"),
        ("verify: {variants: [{tolerance: 'x'}]}", "verify.variants[0].tolerance", "factor"),
        (
            "verify: {variants: [{resolutoin: 64}]}",
            "verify.variants[0].resolutoin",
            "did you mean 'resolution'",
        ),
        ("verify: {variants: []}", "verify.variants", "a list of 1 to"),
        ("verify: {variants: [{tolerance: /10}], seeds: 4}", "verify.seeds", "from 1 to 3"),
        (
            "verify: {variants: [{tolerance: /10}], points: [{K: 0.5}]}",
            "verify.points[0].K",
            "a value of the axis",
        ),
        (
            "verify: {variants: [{tolerance: /10}], observables: [lamda]}",
            "verify.observables",
            "did you mean 'lambda'",
        ),
        (
            "verify: {variants: [{tolerance: /10}, {tolerance: /10}]}",
            "verify.variants",
            "given twice",
        ),
        ("verify: {variants: [{tolerance: /10}], thresold: 0.1}", "verify.thresold", "unknown key"),
    ],
)
def test_section_mistakes_are_reported_with_their_key(section, where, says):
    with pytest.raises(CampaignError) as e:
        campaign(section)
    text = str(e.value)
    assert where in text, text
    assert says in text, text


def test_a_variant_scales_or_sets_the_point_own_values():
    p, n = Parameters(noise_modes=8), Numerics(resolution=32, tolerance=1e-3)
    p2, n2 = resolve(Variant("r", {"resolution": "x2", "tolerance": "/10"}), p, n)
    assert (n2.resolution, n2.tolerance, p2) == (64, 1e-4, p)
    p3, _ = resolve(Variant("a", {"alpha_minus_B": "x2"}), p, n)
    assert math.isclose(p3.alpha - p3.B, 2 * (p.alpha - p.B))
    _, n4 = resolve(Variant("m", {"mechanics": "linear"}), p, n)
    assert n4.mechanics == "linear"


# --------------------------------------------------------------------------- the texture
def test_spectral_interpolation_is_exact_for_a_band_limited_field():
    coarse, fine = band_limited_field(3, 8, 32), band_limited_field(3, 8, 96)
    assert np.abs(spectral_interpolate(coarse, 96) - fine).max() < 1e-12
    assert np.abs(spectral_interpolate(coarse, 64) - band_limited_field(3, 8, 64)).max() < 1e-12


def test_the_interpolant_passes_through_the_coarse_values_and_keeps_a_real_field_real():
    white = per_node_field(5, 32)
    fine = spectral_interpolate(white, 96)  # the coarse cell centres are fine centres 3i + 1
    assert np.abs(fine[1::3, 1::3] - white).max() < 1e-12
    assert np.abs(spectral_interpolate(white.real, 96).imag).max() < 1e-12


def test_a_per_node_resolution_variant_starts_from_the_same_physical_field():
    p, n = Parameters(initial="per_node"), Numerics(resolution=32)
    p2, n2 = resolve(Variant("r", {"resolution": "x2"}), p, n)
    assert (p2.texture_resolution, n2.resolution) == (32, 64)
    q1, _, _ = initial_fields(p, 32, 4)
    f1, _, _ = initial_fields(p2, 64, 4)
    # the fine field's modes up to the coarse Nyquist are the coarse field's (the angle map
    # is applied after the interpolation, so compare the psi fields they come from)
    from nematic_solids.model.initial import texture_field

    c, f = texture_field(p, 32, 4), texture_field(p2, 64, 4)
    assert np.abs(spectral_interpolate(c, 64) - f).max() < 1e-12
    assert q1.shape == (32, 32)
    assert f1.shape == (64, 64)
    # and without texture_resolution the per-node field at 64^2 is a different field
    assert np.abs(texture_field(p, 64, 4) - f).max() > 0.5


def test_texture_resolution_zero_keeps_every_earlier_run_id():
    p = Parameters().to_dict()
    n = Numerics().to_dict()
    without = {k: v for k, v in p.items() if k != "texture_resolution"}
    assert PointHasher(p, n)(0) == PointHasher(without, n)(0)
    q = Parameters(initial="per_node", texture_resolution=64).to_dict()
    assert PointHasher(q, n)(0) != PointHasher({**q, "texture_resolution": 0}, n)(0)


# --------------------------------------------------------------------------- the sample
def _fits(c, lower: float, upper: float) -> xr.Dataset:
    k = [a.values for a in c.axes if a.name == "K"][0]
    ds = xr.Dataset(coords={"K": list(k)})
    attrs = {
        "fit_axis": "alpha_minus_B",
        "fit_log": 1,
        "fit_min_jump": 1.0,
        "fit_observable": "sigma2_S",
        "fit_mean": "geometric",
    }
    for name, value in (
        ("location", (lower + upper) / 2),
        ("lower", lower),
        ("upper", upper),
        ("grid_lower", lower),
        ("grid_upper", upper),
    ):
        ds[f"transition_{name}"] = ("K", [value, math.nan])  # no transition at K = 1e-3
        ds[f"transition_{name}"].attrs.update(attrs)
    return ds


def test_the_sample_is_the_transition_bracket_and_the_corners():
    c = campaign()
    ex = expand(c)
    s = plan_sample(c, ex, _fits(c, 0.1, 0.5))
    got = {
        (p.coords["alpha_minus_B"], p.coords["K"]): why
        for p, why in zip(s.points, s.why, strict=True)
    }
    assert got == {
        (0.1, 1e-4): "transition lower, corner",
        (0.5, 1e-4): "transition upper",
        (0.9, 1e-4): "corner",
        (0.1, 1e-3): "corner",
        (0.9, 1e-3): "corner",
    }
    assert len(s.transitions) == 1
    assert s.transitions[0].where == {"K": 1e-4}
    # base runs are the campaign's own runs, seeds 0 and 1
    ids = set(ex.run_ids)
    assert all(r.run_id in ids and r.seed in (0, 1) for r in s.base_list())
    # variant runs: new ids, the variant's numerics, the variant's seeds
    res, tol, seeds = s.variant_runs
    assert all(r.point.numerics.resolution == 64 for runs in res for r in runs or ())
    assert all(math.isclose(r.point.numerics.tolerance, 1e-4) for runs in tol for r in runs or ())
    assert {r.seed for runs in seeds for r in runs or ()} == {7, 8}
    assert not ids & {r.run_id for r in s.variant_list()}
    before = plan_sample(c, ex, None)  # before the grid has fits: the corners only
    assert {p.coords["alpha_minus_B"] for p in before.points} == {0.1, 0.9}


def test_listed_points_select_every_grid_point_with_their_values():
    c = campaign(VERIFY + "  points: [{K: 1.0e-3}]\n  corners: false\n")
    s = plan_sample(c, expand(c), None)
    assert sorted(p.coords["alpha_minus_B"] for p in s.points) == [0.1, 0.5, 0.9]
    assert {p.coords["K"] for p in s.points} == {1e-3}


# --------------------------------------------------------------------------- the verdicts
def _record(value: float, lam: float = 0.2, cos: float = 0.0) -> Record:
    return {
        "status": "ok",
        "scalars": {
            "sigma2_S_final": value,
            "lambda_final": lam,
            "cos2theta_final": cos,
            "lambda_peak": lam,
            "t_peak": 3.0,
        },
    }


def test_verdicts_from_known_records():
    c = campaign()
    s = plan_sample(c, expand(c), _fits(c, 0.1, 0.5))
    label = {i: (p.coords["alpha_minus_B"], p.coords["K"]) for i, p in enumerate(s.points)}
    base: dict[str, Record] = {}
    for i, runs in enumerate(s.base):
        for r in runs:
            # relaxed below the transition, patterned above it
            base[r.run_id] = _record(1e-9 if label[i][0] == 0.1 else 1e-2)
    var: dict[str, Record] = {}
    res, tol, seeds = s.variant_runs
    for i in range(len(s.points)):
        a = label[i][0]
        for r in res[i] or ():  # resolution: lambda moves 20 % at 0.9, 0.5 turns relaxed
            var[r.run_id] = _record(1e-9 if a <= 0.5 else 1e-2, lam=0.24 if a == 0.9 else 0.2)
        for r in tol[i] or ():  # tolerance: 1 % changes only
            var[r.run_id] = _record(1e-9 if a == 0.1 else 1.01e-2, lam=0.202)
        # the seeds variant has no runs yet: missing
    ds = verify_dataset(s, base, var)
    v = {name: i for i, name in enumerate(ds["variant_name"].values)}
    point = {label[i]: i for i in label}
    p01, p05, p09 = point[(0.1, 1e-4)], point[(0.5, 1e-4)], point[(0.9, 1e-4)]
    conv = ds["converged"].values
    assert conv[p01, v["tolerance /10"]] == CONVERGED
    # no pattern at 0.1: sigma2_S and lambda (pattern measures) are not compared
    assert ds["sigma2_S_verdict"].values[p01, v["tolerance /10"]] == NOT_COMPARED
    assert ds["lambda_verdict"].values[p01, v["tolerance /10"]] == NOT_COMPARED
    assert conv[p05, v["resolution x2"]] == CHANGED  # the class changes
    assert ds["patterned"].values[p05, v["resolution x2"]] == 0
    assert ds["lambda_verdict"].values[p09, v["resolution x2"]] == CHANGED
    assert math.isclose(ds["lambda_change"].values[p09, v["resolution x2"]], 0.2)
    assert conv[p09, v["tolerance /10"]] == CONVERGED
    assert (conv[:, v["seeds=7,8"]] == MISSING).all()
    # the transition: resolution x2 loses the jump between 0.1 and 0.5, tolerance keeps it
    assert ds["transition_within"].values[0, v["tolerance /10"]] == 1
    assert math.isclose(ds["transition_location_variant"].values[0, v["tolerance /10"]], 0.3)
    assert ds["transition_within"].values[0, v["resolution x2"]] == 0
    line = summary_line(ds)
    assert line.startswith("0 of 5 sampled points converged (5 with runs missing)")
    assert (
        "alpha_minus_B = 0.5, K = 0.0001: the patterned fraction changes from 1 to 0 with "
        "resolution x2"
    ) in line


# --------------------------------------------------------------------------- real runs
@pytest.fixture(scope="module")
def verified(tmp_path_factory):
    folder = tmp_path_factory.mktemp("verify")
    path = folder / "v.yaml"
    path.write_text(
        BASE.format(
            verify="verify:\n  seeds: 1\n  variants:\n    - resolution: x2\n    - tolerance: /10\n"
        )
    )
    results = folder / "results"
    return path, results, invoke("run", path, "--results", results, "--no-dashboard")


def test_run_verifies_and_writes_verify_nc_with_cf_attributes(verified):
    path, results, result = verified
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "sampled points converged" in text
    ds = xr.open_dataset(results / "v" / "verify.nc")
    assert ds.attrs["Conventions"] == "CF-1.11"
    assert list(ds["variant_name"].values) == ["resolution x2", "tolerance /10"]
    assert set(ds["converged"].values.ravel()) <= {CONVERGED, CHANGED}
    # the variants' runs are stored apart, the campaign keeps its 18 runs
    assert len(list((results / "v" / "verify" / "runs").glob("*.nc"))) == 2 * ds.sizes["point"]
    assert len(list((results / "v" / "runs").glob("*.nc"))) == 18
    # the tolerance variant ran at 1e-4, the resolution variant at 64^2
    files = [xr.open_dataset(p) for p in (results / "v" / "verify" / "runs").glob("*.nc")]
    assert sorted({int(f.attrs["num_resolution"]) for f in files}) == [32, 64]
    # the figure frames the verified points
    assert (results / "v" / "figures" / "fig2.png").exists()


def test_verify_again_runs_nothing_and_status_shows_the_summary(verified):
    path, results, _ = verified
    stamps = {p: p.stat().st_mtime_ns for p in (results / "v" / "verify" / "runs").glob("*.nc")}
    result = invoke("verify", path, "--results", results)
    assert result.exit_code == 0, result.output
    assert "(0 to do)" in result.output
    assert "variant runs (0 to do)" in result.output
    assert stamps == {p: p.stat().st_mtime_ns for p in stamps}
    status = invoke("status", path, "--results", results)
    assert "verification (" in status.output
    assert "sampled points converged" in status.output
    js = json.loads(invoke("status", path, "--results", results, "--json").output)
    assert "sampled points converged" in js["verification"]


def test_verify_before_runs_the_corners_into_the_campaign(tmp_path):
    path = tmp_path / "v.yaml"
    path.write_text(
        BASE.format(
            verify="verify:\n  before: true\n  seeds: 1\n  variants:\n    - tolerance: /10\n"
        )
    )
    results = tmp_path / "results"
    # verify.before: nematic run verifies the corners first, then runs the grid around them
    run = invoke(
        "run", path, "--results", results, "--no-dashboard", "--no-figures", "--seeds", "1"
    )
    assert run.exit_code == 0, run.output
    text = " ".join(run.output.split())
    assert "verify v: 4 points x 1 seeds" in text
    assert "4 base runs (4 to do)" in text
    assert text.index("sampled points converged") < text.index("4 done")  # a head start
    assert len(list((results / "v" / "runs").glob("*.nc"))) == 6
    again = invoke("verify", path, "--before", "--results", results, "--seeds", "1")
    assert again.exit_code == 0, again.output
    assert "variant runs (0 to do)" in again.output


def test_verify_without_a_section_or_results_is_one_error_line(tmp_path):
    path = tmp_path / "v.yaml"
    path.write_text(BASE.format(verify=""))
    result = invoke("verify", path, "--results", tmp_path / "r")
    assert result.exit_code == 2
    assert "no verify: section" in result.output
    path.write_text(BASE.format(verify=VERIFY))
    result = invoke("verify", path, "--results", tmp_path / "r")
    assert result.exit_code == 2
    assert "run it first" in result.output
    assert "Traceback" not in result.output


def test_check_files_keeps_the_former_verify_spelling(verified):
    path, results, _ = verified
    for flag in ("--check-files", "--verify"):
        result = invoke(
            "run",
            path,
            "--results",
            results,
            "--no-dashboard",
            flag,
            "--no-verification",
            "--no-figures",
        )
        assert result.exit_code == 0, result.output
        assert "18 done" in " ".join(result.output.split())
    assert "--verify " not in invoke("run", "--help").output


def test_an_unreadable_verify_nc_is_one_line_in_status_and_the_report(verified, tmp_path):
    from nematic_solids.sweep.report.content import verification

    path, results, _ = verified
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "verify.nc").write_bytes(b"not a netCDF file")
    found = verification(copy)
    assert found is not None
    assert found["summary"].startswith("verify.nc cannot be read")
    assert found["rows"] == []
    from nematic_solids.sweep.cli.verify import verification_lines

    for detail in (False, True):
        (line,) = verification_lines(copy, detail=detail)
        assert "cannot be read" in line
