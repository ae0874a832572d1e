"""The nematic model as a plugin of the model interface (sweep/models): its settings read
from the model's dataclasses, its observables declared once with their aggregation rules, its
run equal to the model's own, its classes; and a campaign's ``model:`` key."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from nematic_solids.model.parameters import CHOICES, MECHANICS, Numerics, Parameters
from nematic_solids.model.protocol import PROTOCOL_PARAMETERS
from nematic_solids.model.resolution import read_rule
from nematic_solids.model.simulate import run as simulate
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.models.interface import (
    DEFAULT_MODEL,
    Model,
    Observable,
    RunOutcome,
    RunRequest,
    defaults,
    observable,
    setting,
    setting_names,
)
from nematic_solids.sweep.models.nematic import MODEL, PATTERNED_ABOVE
from nematic_solids.sweep.models.registry import get_model, list_models
from nematic_solids.sweep.spec import load_campaign

TINY_P = {"noise_modes": 4, "alpha_minus_B": 0.8, "K": 1e-3}
TINY_N = {"resolution": 16, "t_final": 2.0, "save_every": 1.0, "mechanics": "linear"}


def test_the_default_model_is_the_nematic_plugin_found_by_name():
    assert DEFAULT_MODEL == "nematic"
    assert "nematic" in list_models()
    assert get_model() is MODEL
    assert get_model("nematic") is MODEL
    assert isinstance(MODEL, Model)


def test_every_field_of_the_models_dataclasses_is_a_setting_with_its_default():
    params = {f.name: f for f in dataclasses.fields(Parameters) if f.name != "protocol"}
    numerics = {f.name: f for f in dataclasses.fields(Numerics)}
    assert setting_names(MODEL, "parameter") == [*params, "alpha_minus_B"]
    assert setting_names(MODEL, "numerics") == list(numerics)
    p_defaults = defaults(MODEL, "parameter")
    assert p_defaults.pop("alpha_minus_B") == Parameters().alpha - Parameters().B
    # the defaults build the model's own default objects
    assert Parameters.from_dict(p_defaults) == Parameters()
    assert Numerics.from_dict(defaults(MODEL, "numerics")) == Numerics()
    for s in MODEL.settings:
        assert s.long_name, s
        assert s.long_name != s.name, s
        assert s.accepts(s.default), s


def test_word_settings_have_the_models_choices_and_protocols_its_protocol_parameters():
    assert setting(MODEL, "mechanics").choices == MECHANICS
    for name, choices in CHOICES.items():
        assert setting(MODEL, name).choices == choices
    assert setting(MODEL, "mechanics").accepts("finite")
    assert not setting(MODEL, "mechanics").accepts("plastic")
    assert {s.name for s in MODEL.settings if s.protocol} == set(PROTOCOL_PARAMETERS)
    assert not setting(MODEL, "snapshot_times").sweepable
    assert setting(MODEL, "alpha_minus_B").symbol == r"$\alpha - B$"
    with pytest.raises(KeyError, match="no setting 'alpha_min_B'"):
        setting(MODEL, "alpha_min_B")


def test_sigma2_s_is_the_one_classifying_observable_and_its_seed_mean_is_geometric():
    sig = observable(MODEL, "sigma2_S")
    assert [o.name for o in MODEL.observables if o.classifies] == ["sigma2_S"]
    assert sig.scalar == "sigma2_S_final"
    assert sig.seed_mean == "geometric"
    assert sig.pattern
    # one relaxed seed at the solver's floor and one patterned seed: the geometric mean
    assert sig.mean([1e-12, 1e-2, math.nan]) == pytest.approx(1e-7, rel=1e-12)
    assert observable(MODEL, "mean_S").mean([0.1, 0.3]) == pytest.approx(0.2)
    assert math.isnan(sig.mean([0.0, -1.0, math.nan]))
    names = [o.name for o in MODEL.observables]
    assert len(names) == len(set(names))


def test_an_observables_change_is_relative_or_absolute_by_its_rule():
    cos = observable(MODEL, "cos2theta")
    assert cos.change == "absolute"
    assert cos.difference(0.01, -0.02) == pytest.approx(-0.03)
    lam = observable(MODEL, "lambda")
    assert lam.difference(0.2, 0.25) == pytest.approx(0.25)
    assert lam.difference(0.0, 0.0) == 0.0
    assert lam.difference(0.0, 1.0) == math.inf
    assert math.isnan(lam.difference(math.nan, 1.0))
    with pytest.raises(ValueError, match="seed_mean"):
        Observable("x", "x", "x", seed_mean="harmonic")  # type: ignore[arg-type]


def test_classify_by_the_seed_mean_of_sigma2_s():
    assert MODEL.classify({"sigma2_S": 10 * PATTERNED_ABOVE}) == "patterned"
    assert MODEL.classify({"sigma2_S": PATTERNED_ABOVE / 10}) == "relaxed"
    assert MODEL.classify({"sigma2_S": math.nan}) == "unknown"
    assert MODEL.classify({}) == "unknown"


def test_capabilities_and_the_methods_they_promise():
    caps = MODEL.capabilities
    assert caps.exact_continuation
    assert caps.protocols
    assert caps.start_from_state
    assert caps.batched
    assert caps.cost_model
    assert caps.resolution_rule
    assert caps.memory_per_run
    assert caps.precisions == ("float64", "float32")
    fine = MODEL.resolution("auto", {"K": 1e-5})  # the rule of docs/model/resolution.md
    assert fine == read_rule("auto").grid(1e-5, Parameters().A0)
    assert fine > MODEL.resolution("auto", {"K": 1e-3})
    assert MODEL.resolution(64, {"K": 1e-5}) == 64
    small = MODEL.memory_bytes({"resolution": 64})
    assert MODEL.memory_bytes({"resolution": 128}) - small == 220 * 8 * (128**2 - 64**2)
    short = MODEL.cost_seconds({}, {"resolution": 64, "t_final": 10})
    assert 0 < short < MODEL.cost_seconds({}, {"resolution": 64, "t_final": 100})


def test_a_run_through_the_interface_is_the_models_run_bit_for_bit():
    out = MODEL.run(RunRequest(TINY_P, TINY_N, seed=3))
    assert isinstance(out, RunOutcome)
    assert out.end_state is not None
    ds, end = simulate(Parameters.from_dict(TINY_P), Numerics.from_dict(TINY_N), 3, keep_state=True)
    assert end is not None
    assert end.t == out.end_state.t
    np.testing.assert_array_equal(out.end_state.fields, end.fields)
    for name in ("sigma2_S", "mean_S"):
        np.testing.assert_array_equal(out.dataset[name].values, ds[name].values)
    # every declared observable is read from a scalar the run file holds
    for o in MODEL.observables:
        assert out.dataset[o.scalar].ndim == 0, o


def test_a_longer_run_continues_the_end_state_exactly_and_checkpoints_are_handed_out():
    states: list[Any] = []
    first = MODEL.run(
        RunRequest(TINY_P, {**TINY_N, "t_final": 1.0}, seed=1, checkpoint=states.append)
    )
    longer = MODEL.run(RunRequest(TINY_P, TINY_N, seed=1, start=first.end_state))
    straight = MODEL.run(
        RunRequest(TINY_P, TINY_N, seed=1, checkpoint=states.append, checkpoint_every=1.0)
    )
    assert longer.end_state is not None
    assert straight.end_state is not None
    np.testing.assert_array_equal(longer.end_state.fields, straight.end_state.fields)
    assert [s.t for s in states] == [1.0]


def test_an_unknown_model_is_refused_at_its_line_naming_the_registered_ones(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("name: c\nmodel: nematc\nseeds: 1\n")
    with pytest.raises(CampaignError) as e:
        load_campaign(path)
    text = str(e.value)
    assert f"{path}:2" in text
    assert "nematic" in text
    assert "did you mean 'nematic'" in text
    path.write_text("name: c\nmodel: [nematic]\nseeds: 1\n")
    with pytest.raises(CampaignError, match="a registered model"):
        load_campaign(path)


def test_the_command_line_refuses_an_unknown_model_with_exit_2_and_no_traceback(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("name: c\nmodel: nobody\nseeds: 1\n")
    done = subprocess.run(
        [sys.executable, "-m", "nematic_solids.sweep", "validate", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 2, done
    assert "Traceback" not in done.stderr + done.stdout
    assert f"{path}:2" in done.stderr + done.stdout
    assert "nematic" in done.stderr + done.stdout
