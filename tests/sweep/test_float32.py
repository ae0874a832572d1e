"""``numerics: {precision: float32}``: its validation, its refusals at the key that sets it
(file:line), and the run identity (float32 enters the id; the default float64 leaves every
shipped run's id as it is: recomputed from the campaign texts stored in docs/results/*/phase.nc)."""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from nematic_solids.model.accelerated_support import check_precision
from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.identity import run_id_for
from nematic_solids.sweep.spec import Overrides, load_campaign
from nematic_solids.sweep.spec.verify import resolve
from nematic_solids.sweep.verify import CONVERGED

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
#: shipped campaigns whose runs are all grid runs of their stored YAML (refined campaigns add
#: points of their own; prior: and initial.from: need files beside them): every stored id must
#: be recomputed from the YAML and the overrides recorded with it
PLAIN = (
    "fig2",
    "fig2_trS",
    "fig3",
    "fig3_trS",
    "fig4",
    "figA1",
    "resolution_study_large_K",
    "resolution_study_strain",
    "switch_off",
)
# rheology: the runs of its T = 10 sine were made before the protocol step bound, which now
# enters their ids (tests/sweep/test_identity.py); fig2_loop: its chain's successors were made
# before the exact first guess of the displacement, which now enters their ids
# (tests/sweep/test_identity_coverage.py)


def overrides(recorded: str) -> Overrides:
    """The ``campaign_overrides`` attribute (``--set k=v; --seeds n; --name x``) as
    :class:`Overrides` (the run ids depend on ``--set`` and ``--seeds`` only)."""
    settings, seeds = {}, None
    for part in filter(None, (p.strip() for p in recorded.split(";"))):
        flag, _, value = part.partition(" ")
        if flag == "--set":
            key, _, text = value.partition("=")
            settings[key] = ast.literal_eval(text)
        elif flag == "--seeds":
            seeds = int(value)
    return Overrides(settings=settings, seeds=seeds)


@pytest.mark.parametrize("name", PLAIN)
def test_the_default_precision_leaves_every_shipped_run_id_as_it_was(name, tmp_path):
    phase = xr.open_dataset(RESULTS / name / "phase.nc")
    stored = {str(r) for r in np.asarray(phase["run_id"]).ravel() if str(r)}
    path = tmp_path / f"{name}.yaml"
    path.write_text(phase.attrs["campaign_yaml"])
    campaign = load_campaign(path, overrides(phase.attrs.get("campaign_overrides", "")))
    assert campaign.numerics.get("precision", "float64") == "float64"
    assert stored
    assert stored <= set(expand(campaign).run_ids)


def test_float32_changes_the_run_id_and_float64_is_the_default():
    p = Parameters()
    default = run_id_for(p, Numerics(), 0)
    assert run_id_for(p, Numerics(precision="float64"), 0) == default
    assert run_id_for(p, Numerics(precision="float32"), 0) != default


@pytest.mark.parametrize("bad", ["float16", "single", 32, None])
def test_a_precision_that_is_not_float64_or_float32_is_refused(bad):
    with pytest.raises(ParameterError, match="precision.*float64 or float32"):
        Numerics(precision=bad)


def test_the_compiled_path_refuses_float32_with_the_reason():
    with pytest.raises(ParameterError, match="accelerated backend only, for now"):
        run(Parameters(noise_modes=4), Numerics(resolution=16, t_final=1.0, precision="float32"), 0)


BASE = """
name: f32
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: 1.0, mechanics: linear{numerics}}}
sweep:
  axes:
    alpha_minus_B: [0.2, 0.4]{axes}
{extra}seeds: 1
execution: {{workers: 1{execution}}}
"""


def campaign_text(numerics="", axes="", extra="", execution="") -> str:
    return textwrap.dedent(
        BASE.format(numerics=numerics, axes=axes, extra=extra, execution=execution)
    )


def refusal(tmp_path: Path, text: str) -> str:
    path = tmp_path / "f32.yaml"
    path.write_text(text)
    with pytest.raises(CampaignError) as info:
        load_campaign(path)
    return str(info.value)


def test_float32_on_the_compiled_backend_is_refused_at_its_line(tmp_path):
    msg = refusal(tmp_path, campaign_text(numerics=", precision: float32"))
    assert "f32.yaml:4: numerics.precision: got 'float32'" in msg
    assert "accelerated backend only, for now" in msg
    swept = campaign_text(axes="\n    precision: [float64, float32]")
    msg = refusal(tmp_path, swept)
    assert "f32.yaml:8: sweep.axes.precision: got 'float32'" in msg


def test_float32_in_a_chain_is_refused(tmp_path):
    pytest.importorskip("jax", reason="the accelerated backend needs JAX")
    text = campaign_text(
        numerics=", precision: float32",
        extra="chain: {axis: alpha_minus_B}\n",
        execution=", backend: accelerated, batch: 2",
    )
    msg = refusal(tmp_path, text)
    assert "numerics.precision: got 'float32'; a chain's runs go one at a time" in msg


def test_float32_on_the_accelerated_backend_is_accepted(tmp_path):
    pytest.importorskip("jax", reason="the accelerated backend needs JAX")
    path = tmp_path / "ok.yaml"
    path.write_text(
        campaign_text(
            axes="\n    precision: [float64, float32]", execution=", backend: accelerated, batch: 2"
        )
    )
    e = expand(load_campaign(path))
    by_precision = {r.point.numerics.precision for r in e}
    assert by_precision == {"float64", "float32"}
    assert len(set(e.run_ids)) == 4


VERIFY = """\
verify:
  seeds: 1
  corners: true
  variants:
    - precision: {variant}
"""


def test_a_float32_campaign_verifies_against_a_float64_variant(tmp_path):
    pytest.importorskip("jax", reason="the accelerated backend needs JAX")
    path = tmp_path / "f32.yaml"
    path.write_text(
        campaign_text(
            numerics=", precision: float32",
            execution=", backend: accelerated, batch: 2",
        )
        + VERIFY.format(variant="float64")
    )
    c = load_campaign(path)
    assert c.verify is not None
    (variant,) = c.verify.variants
    assert variant.name == "precision=float64"
    point = next(iter(expand(c))).point
    p64, n64 = resolve(variant, point.parameters, point.numerics)
    assert (point.numerics.precision, n64.precision) == ("float32", "float64")
    assert n64 == point.numerics.replace(precision="float64")
    assert run_id_for(p64, n64, 0) != run_id_for(point.parameters, point.numerics, 0)


def test_a_float32_variant_on_the_compiled_backend_is_refused_at_its_line(tmp_path):
    msg = refusal(tmp_path, campaign_text() + VERIFY.format(variant="float32"))
    assert "f32.yaml:14: verify.variants[0].precision: got 'float32'" in msg
    assert "accelerated backend only, for now" in msg


@pytest.mark.slow  # (minutes: the small-strain batch compiles in both precisions, dask starts)
def test_a_float32_campaign_runs_and_reports_its_verdict_against_float64(tmp_path):
    pytest.importorskip("jax", reason="the accelerated backend needs JAX")
    from typer.testing import CliRunner

    from nematic_solids.sweep.cli import app

    path = tmp_path / "f32.yaml"
    path.write_text(
        campaign_text(
            numerics=", precision: float32, save_every: 0.5",
            execution=", backend: accelerated, batch: 2",
        ).replace("t_final: 1.0", "t_final: 2.0")
        + VERIFY.format(variant="float64")
    )
    results = tmp_path / "results"
    args = ["run", str(path), "--results", str(results), "--no-dashboard", "--no-figures"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    result = CliRunner().invoke(app, ["verify", str(path), "--results", str(results)])
    assert result.exit_code == 0, result.output
    base = [xr.open_dataset(p) for p in (results / "f32" / "runs").glob("*.nc")]
    variant = [xr.open_dataset(p) for p in (results / "f32" / "verify" / "runs").glob("*.nc")]
    assert {f.attrs["num_precision"] for f in base} == {"float32"}
    assert {f.attrs["num_precision"] for f in variant} == {"float64"}
    ds = xr.open_dataset(results / "f32" / "verify.nc")
    assert list(ds["variant_name"].values) == ["precision=float64"]
    # float32 agrees with float64 far inside the verification's 5 % threshold
    assert set(ds["converged"].values.ravel()) == {CONVERGED}
    assert "sampled points converged" in " ".join(result.output.split())


def test_the_stability_analysis_refuses_float32():
    from typer.testing import CliRunner

    from nematic_solids.sweep.cli import app

    result = CliRunner().invoke(app, ["stability", "--set", "precision=float32"])
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert "invalid value for 'precision'" in text
    assert "eigenvalues in float64 only" in text


def test_a_newton_tolerance_below_the_float32_floor_is_refused(tmp_path):
    # float32's Newton stalls at a residual of 9e-7 (benchmarks/float32_newton_floor.json)
    with pytest.raises(ParameterError, match="at least 1e-06 with precision float32"):
        check_precision(Numerics(mechanics="finite", precision="float32", newton_tol=1e-7))
    check_precision(Numerics(mechanics="finite", precision="float32", newton_tol=1e-6))
    check_precision(Numerics(mechanics="linear", precision="float32", newton_tol=1e-7))
    check_precision(Numerics(mechanics="finite", precision="float64", newton_tol=1e-7))
    pytest.importorskip("jax", reason="the accelerated backend needs JAX")
    text = campaign_text(
        numerics=", precision: float32, newton_tol: 1.0e-7",
        execution=", backend: accelerated, batch: 2",
    ).replace("mechanics: linear", "mechanics: finite")
    msg = refusal(tmp_path, text)
    assert "f32.yaml:4: numerics.newton_tol: got 1e-07" in msg
