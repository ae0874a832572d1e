"""A campaign's ``protocol:`` (nematic_solids.sweep.protocols): its numbers as sweep axes, every
mistake at its file:line, the identity covering the protocol (a constant one is the plain
parameter's run), and a campaign whose runs follow their protocols, with the axes in phase.nc."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.model.parameters import Parameters
from nematic_solids.model.simulate import run as simulate
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.spec import parse_campaign

HEAD = """\
name: pulses
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 6, save_every: 1}
"""

PULSES = (
    HEAD
    + """\
protocol:
  alpha_minus_B: {pulse: {base: 1.0, start: 2}}
  eps: {sine: {amplitude: 0.01, period: 3}}
sweep:
  axes:
    alpha_minus_B_level: [0.05, 0.5]
    alpha_minus_B_duration: [1, 2.5]
seeds: 1
execution: {workers: 2}
"""
)


def test_protocol_numbers_are_axes_and_each_point_has_its_protocol():
    expansion = expand(parse_campaign(PULSES))
    assert len(expansion) == 4
    seen = set()
    for spec in expansion:
        p = spec.point.parameters
        level, duration = (
            spec.coords[k] for k in ("alpha_minus_B_level", "alpha_minus_B_duration")
        )
        assert p.protocol.breaks() == (2.0, 2.0 + duration)
        assert p.at(2.0).alpha_minus_B == pytest.approx(level)
        assert p.at(2.0 + duration).alpha_minus_B == pytest.approx(1.0)
        assert p.protocol.varies("eps")
        seen.add(spec.run_id)
    assert len(seen) == 4


def test_a_constant_protocol_has_the_plain_parameters_run_id():
    tail = "numerics: {resolution: 32, t_final: 6}\nsweep: {axes: {alpha_minus_B: [0.5]}}\n"
    plain = "name: a\nparameters: {noise_modes: 8, chi: 4.0}\n" + tail
    timed = "name: a\nparameters: {noise_modes: 8}\nprotocol: {chi: [[0, 4.0]]}\n" + tail
    other = "name: a\nparameters: {noise_modes: 8}\nprotocol: {chi: [[0, 4], [3, 2]]}\n" + tail
    ids = [expand(parse_campaign(text)).run(0).run_id for text in (plain, timed, other)]
    assert ids[0] == ids[1] != ids[2]


@pytest.mark.parametrize(
    ("change", "says"),
    [
        ("  kappa: [[0, 1.0]]\n", "unknown key 'kappa'"),
        ("  chi: {wave: [[0, 1.0]]}\n", "exactly one of steps, ramp, pulse, sine"),
        ("  chi: [[0, 1.0], [2, -3.0]]\n", "values with a number >= 0"),
        ("  chi: [[0, 1.0], [0, 2.0]]\n", "a time > 0"),
    ],
)
def test_a_protocol_mistake_is_reported_at_its_line(change, says):
    text = PULSES.replace("protocol:\n", "protocol:\n" + change)
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="pulses.yaml")
    message = str(err.value)
    assert "pulses.yaml:5" in message, message  # the changed line
    assert says in message, message


def test_a_missing_number_is_reported_at_its_function():
    text = PULSES.replace("alpha_minus_B_duration: [1, 2.5]", "alpha_minus_B_start: [1, 2]")
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="pulses.yaml")
    assert "pulses.yaml:5" in str(err.value)
    assert "(missing: duration)" in str(err.value)


def test_a_swept_number_out_of_bounds_is_reported_at_its_axis():
    text = PULSES.replace("alpha_minus_B_duration: [1, 2.5]", "eps_amplitude: [0.01, 0.7]")
    text = text.replace("start: 2}", "start: 2, duration: 1}")
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="pulses.yaml")
    message = str(err.value)
    assert "sweep.axes.eps_amplitude" in message, message
    assert "pulses.yaml:10" in message, message
    assert "-0.5 < eps < 0.5" in message


@pytest.mark.parametrize(
    ("text", "says"),
    [
        (PULSES.replace("alpha_minus_B_level", "eps"), "sweep the numbers of its function"),
        (PULSES.replace("alpha_minus_B_level", "alpha_minus_B"), "is a function of time"),
        (PULSES.replace("alpha_minus_B_level", "chi_level"), "unknown key 'chi_level'"),
        (
            PULSES.replace(
                "parameters: {noise_modes: 8}", "parameters: {noise_modes: 8, alpha: 2}"
            ),
            "set in both 'parameters:' (alpha) and 'protocol:'",
        ),
    ],
)
def test_protocols_clash_with_constants_and_axes_of_the_same_parameter(text, says):
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="pulses.yaml")
    assert says in str(err.value)


def test_a_protocol_campaign_runs_each_point_by_its_protocol(tmp_path):
    path = tmp_path / "pulses.yaml"
    path.write_text(PULSES)
    result = CliRunner().invoke(app, ["run", str(path), "--results", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    phase = xr.open_dataset(tmp_path / "results" / "pulses" / "phase.nc")
    assert phase.sizes == {"alpha_minus_B_level": 2, "alpha_minus_B_duration": 2, "seed": 1}
    assert phase["alpha_minus_B_level"].attrs["units"] == "1"
    assert json.loads(phase.attrs["param_protocol"])["alpha_minus_B"]["pulse"]["start"] == 2
    page = (tmp_path / "results" / "pulses" / "report.html").read_text()
    assert "<th>time protocol</th><td>{&#34;alpha_minus_B&#34;: {&#34;pulse&#34;" in page
    assert "param_alpha_minus_B" not in phase.attrs
    assert "param_eps" not in phase.attrs
    # each run is the model's run with that point's protocol
    spec = expand(parse_campaign(PULSES)).run(3)
    ref = simulate(spec.point.parameters, spec.point.numerics, spec.seed)
    got = phase.sigma2_S.sel(
        alpha_minus_B_level=spec.coords["alpha_minus_B_level"],
        alpha_minus_B_duration=spec.coords["alpha_minus_B_duration"],
    ).values
    assert np.allclose(got, ref.sigma2_S.values[-1], rtol=1e-12)
    run_file = next((tmp_path / "results" / "pulses" / "runs").rglob(f"*{spec.run_id}*.nc"))
    with xr.open_dataset(run_file) as ds:
        written = json.loads(ds.attrs["param_protocol"])
    assert Parameters.from_dict({"protocol": written}).protocol == spec.point.parameters.protocol


def test_grid_points_that_are_one_run_are_refused():
    text = PULSES.replace("alpha_minus_B_level: [0.05, 0.5]", "alpha_minus_B_level: [0.05, 1.0]")
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="pulses.yaml")
    message = str(err.value)
    assert "pulses.yaml:8: sweep: the grid points (alpha_minus_B_level=1.0" in message, message
    assert "are the same run" in message
