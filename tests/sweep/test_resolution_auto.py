"""``resolution: auto`` in a campaign (nematic_solids.model.resolution): each point's grid from its
K, the run ids of those grids, one phase diagram of runs on several grids with each point's grid in
it, the grids in the dry run and the report, verify's ``resolution: x2`` on top, and the clear
refusals (a bad rule at its line, chains along K, initial.from)."""

from __future__ import annotations

import math

import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.model.resolution import ResolutionRule
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.spec import parse_campaign

#: 1 cell per Frank length from 32^2 to 64^2: K = 1e-4 (l_F = 0.032) on 32^2, K = 5e-5
#: (l_F = 0.022) on 64^2, K = 1e-7 (l_F = 1e-3) held at the cap 64^2.
RULE = "{cells_per_frank: 1.0, floor: 32, cap: 64}"
AUTO = f"""\
name: auto
parameters: {{noise_modes: 8, alpha_minus_B: 1.0}}
numerics: {{resolution: {RULE}, t_final: 1.0, save_every: 0.5}}
sweep:
  axes:
    K: [1.0e-4, 5.0e-5, 1.0e-7]
seeds: 2
execution: {{workers: 2}}
"""


def explicit(n: int, K: float) -> str:
    return (
        AUTO.replace(f"resolution: {RULE}", f"resolution: {n}")
        .replace("[1.0e-4, 5.0e-5, 1.0e-7]", f"[{K!r}]")
        .replace("name: auto", "name: plain")
    )


def test_each_point_gets_the_rules_grid_and_the_run_id_of_that_grid():
    expansion = expand(parse_campaign(AUTO))
    rule = ResolutionRule(cells_per_frank=1.0, floor=32, cap=64)
    grids = [p.numerics.resolution for p in expansion.points]
    assert grids == [rule.grid(K, 0.1) for K in (1e-4, 5e-5, 1e-7)] == [32, 64, 64]
    for i, K in enumerate((1e-4, 5e-5, 1e-7)):
        plain = expand(parse_campaign(explicit(grids[i], K)))
        assert expansion.run_ids[2 * i : 2 * i + 2] == plain.run_ids  # the grid is the identity


def test_a_campaign_on_several_grids_is_one_phase_diagram(tmp_path):
    path = tmp_path / "auto.yaml"
    path.write_text(AUTO)
    results = tmp_path / "results"
    dry = CliRunner().invoke(app, ["run", str(path), "--results", str(results), "--dry-run"])
    assert dry.exit_code == 0, dry.output
    assert "K=0.0001, 32^2: 2 to do" in dry.output
    assert "K=5e-05, 64^2: 2 to do" in dry.output
    assert "K=1e-07, 64^2 (held at the cap): 2 to do" in dry.output
    result = CliRunner().invoke(app, ["run", str(path), "--results", str(results)])
    assert result.exit_code == 0, result.output
    phase = xr.open_dataset(results / "auto" / "phase.nc")
    assert phase.sizes == {"K": 3, "seed": 2}
    assert phase["resolution"].values.tolist() == [32, 64, 64]
    assert phase.attrs["num_resolution"].startswith("auto (1 cells per Frank length, 32 to 64")
    assert int((phase["status"] == 1).sum()) == 6
    # the runs on different grids are the model's runs on their grids: their sigma2_S differ
    # between K values and match a plain campaign at that grid
    plain = tmp_path / "plain.yaml"
    plain.write_text(explicit(64, 5e-5))
    again = CliRunner().invoke(app, ["run", str(plain), "--results", str(results)])
    assert again.exit_code == 0, again.output
    other = xr.open_dataset(results / "plain" / "phase.nc")
    assert float(other.sigma2_S.isel(K=0, seed=1)) == float(phase.sigma2_S.isel(K=1, seed=1))
    page = (results / "auto" / "report.html").read_text()
    assert "failed of 2 seeds on 64^2" in page
    assert "failed of 2 seeds on 32^2" in page


def test_verify_doubles_each_points_own_grid():
    text = AUTO + "verify:\n  variants:\n    - resolution: x2\n"
    campaign = parse_campaign(text)
    from nematic_solids.sweep.spec.verify import resolve

    expansion = expand(campaign)
    assert campaign.verify is not None
    variant = campaign.verify.variants[0]
    doubled = [resolve(variant, p.parameters, p.numerics)[1].resolution for p in expansion.points]
    assert doubled == [64, 128, 128]


@pytest.mark.parametrize(
    ("change", "line", "says"),
    [
        ("resolution: {cells_per_frank: -1}", 3, "allowed: an even integer >= 16, 'auto'"),
        ("resolution: fine", 3, "'auto' (the grid from K"),
    ],
)
def test_a_bad_rule_is_reported_at_its_line(change, line, says):
    text = AUTO.replace(f"resolution: {RULE}", change)
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="auto.yaml")
    message = str(err.value)
    assert f"auto.yaml:{line}" in message, message
    assert says in message, message


def test_a_chain_along_K_with_a_rule_is_refused():
    text = AUTO + "chain: {axis: K, branches: up}\n"
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="auto.yaml")
    assert "would change the grid between a run and the next" in str(err.value)


def test_the_memory_check_uses_the_grids_the_rule_gives():
    # a cap far beyond this machine's memory is fine as long as no point needs it
    text = AUTO.replace(RULE, "{cells_per_frank: 1.0, floor: 32, cap: 65536}").replace(
        "1.0e-7]", "1.0e-5]"
    )
    expansion = expand(parse_campaign(text))
    assert max(p.numerics.resolution for p in expansion.points) < 256
    tiny_k = text.replace("1.0e-5]", "1.0e-13]")  # 1e6 per side wanted: held at the cap
    with pytest.raises(CampaignError) as err:
        parse_campaign(tiny_k, source="auto.yaml")
    assert "got 65536: one run" in str(err.value), str(err.value)
    assert math.isclose(ResolutionRule(1.0, 32, 65536).wanted(1e-13, 0.1), 1e6)
