"""Early stop (numerics steady_tol > 0, off by default): a run ends at the first save where
sigma2_S and mean_S are steady, records it (stopped_early, t_stopped, the fields at that
time) and is the same run as without early stop up to then; off, nothing changes (run ids
included)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import STEADY, run
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.identity import run_id_for
from nematic_solids.sweep.spec import parse_campaign
from nematic_solids.sweep.store import record_from_dataset

PARAMS = Parameters.from_dict({"alpha_minus_B": 1.0, "noise_modes": 8})
BASE: dict[str, Any] = {
    "resolution": 32,
    "t_final": 100.0,
    "save_every": 1.0,
    "mechanics": "linear",
}


@pytest.fixture(scope="module")
def pair():
    """The same patterned run (32^2, linear, alpha - B = 1) to t = 100 and with early stop
    (2 % over 10 tau)."""
    full = run(PARAMS, Numerics.from_dict(BASE), 0)
    early = run(PARAMS, Numerics.from_dict({**BASE, "steady_tol": 0.02, "steady_window": 10.0}), 0)
    return full, early


def test_early_stop_is_off_by_default_and_keeps_the_run_ids():
    n = Numerics()
    assert n.steady_tol == 0.0
    assert run_id_for(PARAMS, n, 0) == run_id_for(PARAMS, Numerics(steady_window=7.0), 0)
    assert run_id_for(PARAMS, n, 0) != run_id_for(PARAMS, Numerics(steady_tol=0.01), 0)
    # the golden ids of tests/sweep/test_identity.py are those of runs made before early stop
    # existed; this one is the default parameters and numerics, seed 0
    from nematic_solids.sweep.identity import canonical_json

    assert "steady" not in canonical_json(PARAMS.to_dict(), n.to_dict(), 0)


def test_a_steady_run_stops_early_and_says_so(pair):
    full, early = pair
    assert full.attrs["status"] == early.attrs["status"] == "ok"
    assert float(full.stopped_early) == 0.0
    assert math.isnan(float(full.t_stopped))
    t_stop = float(early.t_stopped)
    assert float(early.stopped_early) == 1.0
    assert 10.0 <= t_stop < 100.0
    assert float(early.t[-1]) == t_stop
    # the same run up to then (the same steps and saves)
    head = full.sel(t=slice(None, t_stop))
    np.testing.assert_array_equal(early.sigma2_S.values, head.sigma2_S.values)
    # the final values and the stored fields are those at t_stop
    assert float(early.sigma2_S_final) == float(early.sigma2_S[-1])
    assert early.snapshot_time.values.tolist() == [t_stop]
    np.testing.assert_array_equal(early.q1.sel(snapshot_time=t_stop).values.shape, (32, 32))

    # the stated criterion holds at t_stop and at no save before it
    def steady_at(t: float) -> bool:
        now = full.sel(t=t)
        then = full.sel(t=t - 10.0)
        return all(
            abs(float(now[k]) - float(then[k]))
            <= 0.02 * max(abs(float(now[k])), abs(float(then[k])))
            for k in STEADY
        )

    assert steady_at(t_stop)
    assert not any(steady_at(float(t)) for t in full.t.values if 10.0 <= t < t_stop)


def test_the_record_and_so_phase_nc_carry_the_early_stop(pair):
    _, early = pair
    rec = record_from_dataset(early, "x", 0)
    assert rec["scalars"]["stopped_early"] == 1.0
    assert rec["scalars"]["t_stopped"] == float(early.t_stopped)


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"steady_tol": -0.1}, "a number >= 0"),
        ({"steady_tol": 0.01, "steady_window": 0.5}, "at least save_every (1.0)"),
        ({"steady_tol": 0.01, "steady_window": 100.0}, "below t_final (100.0)"),
        ({"steady_window": 0.0}, "a number > 0"),
    ],
)
def test_bad_early_stop_settings_are_refused(changes, words):
    with pytest.raises(ParameterError, match=words.replace("(", r"\(").replace(")", r"\)")):
        Numerics.from_dict({**BASE, **changes})


def test_early_stop_in_a_campaign_is_checked_like_any_numerics():
    text = (
        "name: c\nnumerics: {resolution: 128, t_final: 10, save_every: 1, "
        "steady_tol: 0.01, steady_window: 20}\nsweep: {axes: {alpha_minus_B: [0.5, 1.0]}}\n"
    )
    with pytest.raises(CampaignError, match="numerics.steady_window"):
        parse_campaign(text, "c.yaml")
    ok = parse_campaign(text.replace("steady_window: 20", "steady_window: 5"), "c.yaml")
    assert ok.numerics["steady_tol"] == 0.01
