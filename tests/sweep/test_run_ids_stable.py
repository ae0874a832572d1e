"""Run identity holds for every shipped result: expanding each campaign stored in
``docs/results/*/phase.nc`` today gives exactly the run ids that phase.nc holds, position by
position (a refined or precision campaign: on the grid of the points and seeds it ran, stored as
phase.nc's coordinates). The default model (``model:`` absent) adds nothing to a run's id; any
other model's name is part of it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from test_float32 import overrides

from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.sweep import identity
from nematic_solids.sweep.campaign import DEFAULT_MODEL, Axis, Campaign, Dim
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.identity import PointHasher, hash_canonical, run_id_for, trajectory_id
from nematic_solids.sweep.models import nematic_identity
from nematic_solids.sweep.models.interface import DEFAULT_MODEL as INTERFACE_DEFAULT
from nematic_solids.sweep.models.registry import get_model
from nematic_solids.sweep.spec import load_campaign

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "docs" / "results"
SHIPPED = sorted(p.parent.name for p in RESULTS.glob("*/phase.nc"))
#: results whose runs of a sine were made before the protocol's step bound entered the run
#: identity (sweep/identity.py, protocol_step_rule): their stored ids are today's ids with the
#: bound left out, and they are rerun under their new ids
BEFORE_STEP_BOUND = {"rheology", "rheology_loop_down", "rheology_loop_up"}
#: results whose finite-strain chain successors were made from the end snapshot's displacement
#: before the exact end state's first guess entered the run identity (sweep/identity.py,
#: start_guess): their stored ids are today's with that guess left out (the first runs of
#: their branches keep theirs), and the successors are rerun under their new ids
BEFORE_START_GUESS = {"fig2_loop"}


@pytest.fixture(scope="module")
def campaigns_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every stored campaign text as ``<tmp>/campaigns/<name>.yaml``, beside a link to the
    repository's docs/: what a stored campaign names (``prior: ../docs/results/...``,
    ``initial.from: {campaign: fig2_loop.yaml}``) is found as it was."""
    root = tmp_path_factory.mktemp("shipped")
    (root / "docs").symlink_to(REPO / "docs")
    folder = root / "campaigns"
    folder.mkdir()
    for name in SHIPPED:
        with xr.open_dataset(RESULTS / name / "phase.nc") as phase:
            (folder / f"{name}.yaml").write_text(phase.attrs["campaign_yaml"])
    return folder


def grid_of(campaign: Campaign, phase: xr.Dataset) -> Campaign:
    """``campaign`` on the points and seeds phase.nc holds (a refined campaign's union grid,
    the seeds a precision campaign ran): its dimensions' values read from the coordinates."""
    dims = tuple(
        Dim(d.name, tuple(Axis(a.name, tuple(phase[a.name].values.tolist())) for a in d.axes))
        for d in campaign.dims
    )
    seeds = tuple(int(s) for s in phase["seed"].values)
    return dataclasses.replace(campaign, dims=dims, seeds=seeds)


def check(name: str, folder: Path) -> None:
    with xr.open_dataset(RESULTS / name / "phase.nc") as phase:
        stored = [str(r) for r in np.asarray(phase["run_id"].values).ravel()]
        campaign = load_campaign(
            folder / f"{name}.yaml", overrides(phase.attrs.get("campaign_overrides", ""))
        )
        assert campaign.model == phase.attrs.get("model", DEFAULT_MODEL)
        ids = expand(grid_of(campaign, phase)).run_ids
    assert len(ids) == len(stored)
    wrong = [(i, s, r) for i, (s, r) in enumerate(zip(stored, ids, strict=True)) if s and s != r]
    assert not wrong, f"{len(wrong)} of {len(stored)} stored run ids differ, e.g. {wrong[:3]}"
    assert sum(1 for s in stored if s) > 0


@pytest.mark.parametrize("name", SHIPPED)
def test_expanding_a_shipped_campaign_gives_the_run_ids_of_its_phase_nc(name, campaigns_dir):
    if name in BEFORE_STEP_BOUND | BEFORE_START_GUESS:
        with pytest.raises(AssertionError, match="stored run ids differ"):
            check(name, campaigns_dir)
        return
    check(name, campaigns_dir)


@pytest.mark.parametrize("name", sorted(BEFORE_STEP_BOUND | BEFORE_START_GUESS))
def test_runs_made_before_have_todays_ids_without_the_newer_rules(name, campaigns_dir, monkeypatch):
    """Today's ids with the step bound and the first guess left out are the stored ones (a
    loop of rheology begins from its other branch's end states: both rules apply there)."""
    monkeypatch.setattr(nematic_identity, "protocol_step_rule", lambda parameters, numerics: None)
    monkeypatch.setattr(nematic_identity, "start_guess", lambda numerics, start: None)
    check(name, campaigns_dir)


def test_every_shipped_result_is_checked():
    assert len(SHIPPED) >= 20
    assert set(SHIPPED) >= {"fig2", "fig2_adaptive", "fig2_precision", "rheology_loop_up"}


def test_the_default_model_adds_nothing_and_another_models_name_is_in_the_id():
    assert DEFAULT_MODEL == INTERFACE_DEFAULT
    p, n = Parameters().to_dict(), Numerics().to_dict()
    plain = hash_canonical(p, n, 3)
    assert hash_canonical(p, n, 3, model=DEFAULT_MODEL) == plain
    other = hash_canonical(p, n, 3, model="swift-hohenberg")
    assert other != plain
    assert '"model":"swift-hohenberg"' in identity.canonical_json(p, n, 3, model="swift-hohenberg")
    assert "model" not in identity.canonical_json(p, n, 3)
    assert PointHasher(p, n, "swift-hohenberg")(3) == other
    assert PointHasher(p, n)(3) == plain
    assert trajectory_id(p, n, 3, model="swift-hohenberg") != trajectory_id(p, n, 3)


def test_a_campaign_that_names_the_default_model_keeps_its_run_ids(tmp_path):
    text = (
        "name: m\nparameters: {noise_modes: 4}\nnumerics: {resolution: 16, t_final: 1}\nseeds: 2\n"
    )
    (tmp_path / "a.yaml").write_text(text)
    (tmp_path / "b.yaml").write_text(text + "model: nematic\n")
    a = expand(load_campaign(tmp_path / "a.yaml"))
    b = expand(load_campaign(tmp_path / "b.yaml"))
    assert a.run_ids == b.run_ids


def test_another_models_ids_hold_every_setting_but_the_execution_only_ones():
    """A model without identity rules of its own: each setting that can change a number
    enters the id; the py-pde backend (numpy or numba, equal to rounding) does not."""
    model = get_model("swift-hohenberg")
    p, n = model.point({"eps": 0.1, "g": 0.5}, {"t_final": 10.0, "dt": 0.01})
    base = run_id_for(p, n, 0, model="swift-hohenberg")
    assert run_id_for(p, n, 0, model="swift-hohenberg") == base  # deterministic
    text = identity.canonical_json(p.to_dict(), n.to_dict(), 0, model="swift-hohenberg")
    assert "backend" not in text
    assert '"kick"' in text
    assert '"model":"swift-hohenberg"' in text
    numba = model.point({"eps": 0.1, "g": 0.5}, {"t_final": 10.0, "dt": 0.01, "backend": "numba"})
    assert run_id_for(*numba, 0, model="swift-hohenberg") == base
    for key, value in (("g", 0.25), ("eps", 0.05)):
        other = model.point({"eps": 0.1, "g": 0.5, key: value}, {"t_final": 10.0, "dt": 0.01})
        assert run_id_for(*other, 0, model="swift-hohenberg") != base
    for key, value in (("dt", 0.005), ("points", 6), ("kick", 1e-3), ("t_final", 20.0)):
        other = model.point({"eps": 0.1, "g": 0.5}, {"t_final": 10.0, "dt": 0.01, key: value})
        assert run_id_for(*other, 0, model="swift-hohenberg") != base, key
