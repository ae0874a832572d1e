"""A campaign of another model than the paper's (``model: swift-hohenberg``, a py-pde model)
through the whole machinery: validation by the model's settings and its own checks, run ids
that hold the model and its settings, chains that begin from the predecessor's end state,
continuation to a longer t_final bitwise equal to a straight run, corrupt states refused, and
phase.nc, products and report for the model's own observables."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.figures.swift_hohenberg import _edge, branch_boundaries, classes
from nematic_solids.sweep.provenance import git_commit
from nematic_solids.sweep.run.continuation import STATE_GROUP, ParentUnusable, starting_state
from nematic_solids.sweep.run.task import RunTask
from nematic_solids.sweep.spec import load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore

MODEL = "swift-hohenberg"

#: a 16 x 18 grid, RK4 at dt = 0.0125 (its limit on this grid is 0.019 at eps = 0.1)
TINY = """
name: {name}
model: swift-hohenberg
numerics: {{periods: 2, points: 8, dt: 0.0125, save_every: 2.5, t_final: {t_final}, kick: 0.001}}
parameters: {{g: 1.0}}
sweep:
  axes:
    eps: [-0.02, 0.1]
{chain}
seeds: 1
execution: {{workers: 1}}
"""
CHAIN = "chain: {axis: eps, branches: [up, down]}"


def write(folder: Path, name: str, t_final: float = 5.0, chain: str = CHAIN) -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(TINY.format(name=name, t_final=t_final, chain=chain))
    return path


def run(path: Path, results: Path, *args: str) -> str:
    out = CliRunner().invoke(app, ["run", str(path), "--results", str(results), *args])
    assert out.exit_code == 0, out.output
    return out.output


def records(results: Path, name: str) -> dict[str, dict]:
    runs = results / name / "runs"
    return {p.stem: json.loads(p.read_text()) for p in runs.glob("*.json")}


def test_the_model_settings_and_checks_validate_the_file(tmp_path):
    bad = TINY.format(name="bad", t_final=5.0, chain="").replace("dt: 0.0125", "dt: 0.05")
    with pytest.raises(CampaignError) as e:
        parse_campaign(bad + "\n", "bad.yaml")
    text = str(e.value)
    assert "bad.yaml:4: numerics.dt: got 0.05; allowed: below the stability limit" in text
    unknown = TINY.format(name="u", t_final=5.0, chain="").replace("g: 1.0", "K: 1.0")
    with pytest.raises(CampaignError, match=r"parameters.K: unknown key 'K'; allowed keys: eps, g"):
        parse_campaign(unknown, "u.yaml")
    nematic_fit = TINY.format(name="f", t_final=5.0, chain="") + "fits: [transition]\n"
    with pytest.raises(CampaignError, match="reads the observables of the model nematic"):
        parse_campaign(nematic_fit, "f.yaml")


def test_a_chain_of_the_model_runs_from_its_predecessors_end_states(tmp_path):
    path = write(tmp_path, "chain")
    output = run(path, tmp_path / "results")
    assert "run(s) failed" not in output
    expansion = expand(load_campaign(path))
    recs = records(tmp_path / "results", "chain")
    assert set(recs) == set(expansion.run_ids)
    assert all(r["status"] == "ok" for r in recs.values())
    assert all(r["git_commit"] == git_commit() for r in recs.values())  # provenance, as nematic
    successors = [r for r in recs.values() if r["initial_from"]]
    assert len(successors) == 2  # the second point of each branch
    for r in successors:
        parent = r["initial_from"].split("/")[1].split("@")[0]
        assert parent in recs
        assert recs[parent]["coords"]["branch"] == r["coords"]["branch"]
    phase = xr.open_dataset(tmp_path / "results" / "chain" / "phase.nc")
    assert phase.attrs["model"] == "swift-hohenberg"
    assert {"amplitude_mean", "hexagonality_mean", "mean_mean"} <= set(phase.data_vars)
    assert "sigma2_S_mean" not in phase.data_vars
    assert phase["eps"].attrs["long_name"].startswith("distance from onset")
    report = (tmp_path / "results" / "chain" / "report.html").read_text()
    assert "amplitude(t) of the clicked point" in report  # the model's classifying observable
    assert "sigma2_S" not in report
    assert not (tmp_path / "results" / "chain" / "failed_products.json").exists()


def test_a_longer_run_continues_the_shorter_ones_end_state_bitwise(tmp_path):
    short = write(tmp_path, "grow", t_final=5.0, chain="")
    run(short, tmp_path / "results")
    longer = write(tmp_path, "grow", t_final=10.0, chain="")
    run(longer, tmp_path / "results")
    straight = write(tmp_path, "straight", t_final=10.0, chain="")
    run(straight, tmp_path / "results")
    grown = records(tmp_path / "results", "grow")
    continued = [r for r in grown.values() if r["continued_from"]]
    assert len(continued) == 2  # both points continued their t_final = 5 runs
    for r in continued:
        other = xr.open_dataset(tmp_path / "results" / "straight" / "runs" / f"{r['run_id']}.nc")
        mine = xr.open_dataset(tmp_path / "results" / "grow" / "runs" / f"{r['run_id']}.nc")
        assert r["started_at"] == pytest.approx(5.0, rel=1e-12)
        np.testing.assert_array_equal(mine["u_final"].values, other["u_final"].values)
        np.testing.assert_array_equal(mine["amplitude"].values, other["amplitude"].values)


def test_a_continuation_that_is_not_exact_says_so_in_its_record(tmp_path):
    """With adaptive steps the step size at the stop is not kept: the continued run is close
    to a straight run, not equal, and its record says so."""
    for t_final in (5.0, 10.0):
        path = write(tmp_path, "adaptive", t_final=t_final, chain="")
        path.write_text(path.read_text().replace("kick: 0.001", "kick: 0.001, adaptive: true"))
        run(path, tmp_path / "results")
    recs = [r for r in records(tmp_path / "results", "adaptive").values() if r["continued_from"]]
    assert len(recs) == 2
    assert all("not equal to, a run that never stopped" in r["start_warning"] for r in recs)


def test_a_corrupt_state_is_never_used(tmp_path):
    """A successor whose predecessor's end state fails its checksum fails (``parent_state``)
    rather than begin from anything else; a run's own checkpoint that fails it is ignored
    with the reason, and the run starts at t = 0."""
    path = write(tmp_path, "corrupt")
    run(path, tmp_path / "results")
    expansion = expand(load_campaign(path))
    store = CampaignStore(tmp_path / "results", "corrupt")
    recs = records(tmp_path / "results", "corrupt")
    successor = next(r for r in recs.values() if r["initial_from"])
    parent = successor["initial_from"].split("/")[1].split("@")[0]
    spec = next(r for r in expansion if r.run_id == successor["run_id"])
    task = RunTask.from_spec(spec, store, "corrupt", expansion.campaign.store, model=MODEL)
    file = store.nc_path(parent)
    state = xr.load_dataset(file, group=STATE_GROUP)
    main = xr.load_dataset(file)
    state["data"].values[0, 0] += 1e-3  # altered: no longer its checksum
    main.to_netcdf(file)
    state.to_netcdf(file, mode="a", group=STATE_GROUP)
    with pytest.raises(ParentUnusable, match="checksum"):
        starting_state(task, store)
    first = next(r for r in expansion if r.run_id == parent)
    own = RunTask.from_spec(first, store, "corrupt", expansion.campaign.store, model=MODEL)
    store.checkpoint_path(parent).parent.mkdir(parents=True, exist_ok=True)
    state.to_netcdf(store.checkpoint_path(parent))  # its own checkpoint, altered
    start = starting_state(own, store)
    assert start.state is None
    assert "checkpoint ignored" in start.warning
    assert "checksum" in start.warning


def test_refinement_and_verification_run_on_the_models_observables(tmp_path):
    """``refine:`` splits the cells where the model's own observable crosses its threshold,
    and ``verify:`` reruns a sample at half the step and compares the model's observables by
    their declared rules."""
    path = tmp_path / "adaptive.yaml"
    path.write_text(
        TINY.format(name="adaptive", t_final=10.0, chain="").replace(
            "eps: [-0.02, 0.1]", "eps: [-0.1, 0.1, 0.3]"
        )
        + "refine: {axis: eps, observable: amplitude, patterned_above: 0.02, min_spacing: 0.05,"
        " rounds: 2}\n"
        "verify: {variants: [{dt: /2}], seeds: 1, observables: [amplitude, hexagonality],"
        " patterned_above: 0.02}\n"
    )
    output = run(path, tmp_path / "results")
    assert "refinement finished" in output
    phase = xr.open_dataset(tmp_path / "results" / "adaptive" / "phase.nc")
    assert phase.sizes["eps"] > 3  # points added between the grid's
    verify = xr.open_dataset(tmp_path / "results" / "adaptive" / "verify.nc")
    assert verify.sizes["point"] >= 2
    assert bool(verify["converged"].all())


def test_the_models_own_figure_is_drawn_for_its_chain(tmp_path):
    """A chain over eps and g draws the model's figure (``sh_phase``, registered for the
    model swift-hohenberg), none of the paper's; its boundaries read the classes."""
    path = tmp_path / "plane.yaml"
    path.write_text(
        TINY.format(name="plane", t_final=5.0, chain=CHAIN)
        .replace("    eps: [-0.02, 0.1]", "    eps: [-0.02, 0.1]\n    g: [0.5, 1.0]")
        .replace("parameters: {g: 1.0}\n", "")
    )
    run(path, tmp_path / "results")
    figures = tmp_path / "results" / "plane" / "figures"
    assert sorted(p.name for p in figures.iterdir()) == ["sh_phase.pdf", "sh_phase.png"]
    phase = xr.open_dataset(tmp_path / "results" / "plane" / "phase.nc")
    rows = branch_boundaries(phase)
    assert [r["g"] for r in rows] == [0.5, 1.0]
    assert rows[1]["eps_H_leading"] == pytest.approx(-1 / 15)
    cls = classes(phase)
    assert set(cls.values.ravel()) <= {"uniform", "stripes", "hexagons"}


def test_the_branch_edges_follow_each_branch_from_its_start():
    """The down branch's pattern is followed from the top of the axis until it is lost (a
    down branch whose top is uniform has none); the up branch patterns at its first
    patterned point from the bottom."""
    eps = [-0.1, 0.0, 0.1]
    assert math.isnan(_edge(eps, ["uniform", "hexagons", "uniform"], "down")["down_pattern"])
    assert _edge(eps, ["uniform", "hexagons", "hexagons"], "down") == {
        "down_pattern": 0.0,
        "down_uniform": -0.1,
    }
    assert _edge(eps, ["uniform", "stripes", "hexagons"], "up")["up_pattern"] == 0.0
    assert math.isnan(_edge(eps, ["uniform"] * 3, "up")["up_pattern"])


@pytest.mark.slow
def test_the_chain_shows_the_subcritical_hysteresis(tmp_path):
    """At g = 1 and eps = -0.02 the uniform state is linearly stable and hexagons exist (the
    amplitude equations' band is -g^2/15 < eps < 0, docs/model/swift_hohenberg.md): the up
    branch, from noise, stays uniform; the down branch, from eps = 0.1's hexagons, keeps
    them. At eps = 0.1 both branches are hexagons."""
    path = write(tmp_path, "loop", t_final=100.0)
    run(path, tmp_path / "results")
    phase = xr.open_dataset(tmp_path / "results" / "loop" / "phase.nc")
    amp = phase["amplitude_mean"].sel(eps=-0.02)
    hexa = phase["hexagonality_mean"]
    assert float(amp.sel(branch="up")) < 1e-2  # uniform
    assert float(amp.sel(branch="down")) > 0.1
    assert float(hexa.sel(branch="down", eps=-0.02)) > 0.5  # hexagons
    assert float(hexa.sel(branch="up", eps=0.1)) > 0.5
    assert float(hexa.sel(branch="down", eps=0.1)) > 0.5


def test_the_model_campaign_file_shipped_validates():
    campaign = load_campaign(Path(__file__).resolve().parents[2] / "campaigns/swift_hohenberg.yaml")
    assert campaign.model == "swift-hohenberg"
    assert campaign.chain is not None
    assert campaign.n_runs == 170
