"""run_id: pinned golden hashes, and invariance under key order, float spelling, int/float
and alpha vs alpha_minus_B (signac ``calc_id`` style)."""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.identity import (
    SCHEMA_VERSION,
    PointHasher,
    PointIdentity,
    canonical_json,
    hash_canonical,
    run_id_for,
)
from nematic_solids.sweep.spec import parse_campaign

# Complete, explicit dicts: the golden hashes must not move when the model's defaults do.
P = {
    "S0": 0.1,
    "A0": 0.1,
    "B": 0.5,
    "B_prime": 0.0,
    "C": 1.0,
    "K": 5e-05,
    "kappa": 10.0,
    "alpha": 0.9,
    "chi": 10.0,
    "zeta": 1.0,
    "s": 1.0,
    "gamma": 1.0,
    "tau": 1.0,
    "eps": 0.0,
    "noise_modes": 16,
}
N = {
    "resolution": 128,
    "t_final": 300.0,
    "dt": 0.05,
    "adaptive": True,
    "tolerance": 0.001,
    "dt_max": 1.0,
    "save_every": 5.0,
    "snapshot_times": [100.0, 300.0],
    "mechanics": "finite",
    "incompressible": False,
    "newton_tol": 1e-08,
    "max_newton": 30,
    "spin_tol": 1e-08,
}

GOLDEN = {0: "c483160a9a6aa705", 1: "10f815a531a5b374", 49: "f090e8046b4a6e3b"}


def test_schema_version_is_pinned():
    # Changing the canonical form changes every run_id: bump SCHEMA_VERSION and the goldens.
    assert SCHEMA_VERSION == 1


def test_canonical_text_is_pinned():
    assert canonical_json(P, N, 0) == (
        '{"numerics":{"adaptive":true,"dt":"0.05","dt_max":"1","incompressible":false,'
        '"max_newton":"30","mechanics":"finite","newton_tol":"1e-08","resolution":"128",'
        '"save_every":"5","snapshot_times":["100","300"],"spin_tol":"1e-08","t_final":"300",'
        '"tolerance":"0.001"},"parameters":{"A0":"0.1","B":"0.5","B_prime":"0","C":"1",'
        '"K":"5e-05","S0":"0.1","alpha":"0.9","chi":"10","eps":"0","gamma":"1","kappa":"10",'
        '"noise_modes":"16","s":"1","tau":"1","zeta":"1"},"schema":1,"seed":"0"}'
    )


@pytest.mark.parametrize(("seed", "expected"), sorted(GOLDEN.items()))
def test_golden_hashes(seed, expected):
    assert hash_canonical(P, N, seed) == expected


def test_other_golden():
    assert (
        hash_canonical(dict(P, alpha=1.5, K=1e-4), dict(N, resolution=64), 7) == "8b92d798b0613bce"
    )


def test_key_order_does_not_matter():
    rng = random.Random(1)
    for _ in range(20):
        p_items, n_items = list(P.items()), list(N.items())
        rng.shuffle(p_items)
        rng.shuffle(n_items)
        assert hash_canonical(dict(p_items), dict(n_items), 0) == GOLDEN[0]


def test_float_spelling_does_not_matter():
    spelled = dict(P, alpha=0.6 + 0.3, K=0.00005, S0=0.1 * 3 / 3, C=1, kappa=10)
    assert spelled["alpha"] != 0.9  # 0.8999999999999999
    assert hash_canonical(spelled, dict(N, t_final=300, dt=0.05000000000000001), 0) == GOLDEN[0]
    assert hash_canonical(dict(P, eps=-0.0), N, 0) == GOLDEN[0]
    assert hash_canonical(P, dict(N, snapshot_times=(100, 300.0)), 0) == GOLDEN[0]


def test_real_changes_change_the_id():
    ids = {
        hash_canonical(P, N, 0),
        hash_canonical(P, N, 1),
        hash_canonical(dict(P, alpha=0.91), N, 0),
        hash_canonical(dict(P, K=5.0001e-05), N, 0),
        hash_canonical(P, dict(N, resolution=64), 0),
        hash_canonical(P, dict(N, mechanics="linear"), 0),
        hash_canonical(P, dict(N, adaptive=False), 0),
        hash_canonical(P, dict(N, snapshot_times=[100.0]), 0),
    }
    assert len(ids) == 8


def test_alpha_minus_b_is_alpha():
    n = Numerics(resolution=128)
    a = run_id_for({"alpha_minus_B": 0.4}, n, 3)
    b = run_id_for({"alpha": 0.9}, n, 3)
    c = run_id_for({"B": 0.5, "alpha_minus_B": 0.4000000000000001}, n, 3)
    assert a == b == c
    assert run_id_for(Parameters.from_dict({"alpha": 0.9}), n, 3) == a


def test_defaults_written_or_not_are_one_run():
    assert run_id_for({}, {}, 0) == run_id_for(Parameters().to_dict(), Numerics().to_dict(), 0)


def test_backend_is_not_part_of_the_identity():
    """compiled and numpy runs agree to rounding: one run, and the goldens stay."""
    assert hash_canonical(P, dict(N, backend="numpy"), 0) == GOLDEN[0]
    assert PointHasher(P, dict(N, backend="compiled"))(49) == GOLDEN[49]
    assert run_id_for({}, {"backend": "numpy"}, 3) == run_id_for({}, {}, 3)


def test_point_hasher_equals_hash_canonical():
    h = PointHasher(P, N)
    for seed in (0, 1, 49, 12345678901):
        assert h(seed) == hash_canonical(P, N, seed)


PULSE = {"start": 5.0, "duration": 2.0}


def test_point_identity_is_equal_exactly_where_the_run_ids_are():
    """The validation's key of a grid point (no hash, numerics canonicalised once) and the run
    id agree: points that differ below the 12 significant digits, a constant pulse and the
    plain parameter, a protocol whose step bound binds or not."""
    points: list[tuple[dict[str, Any], dict[str, Any]]] = [
        ({"B": 1.0e6, "alpha_minus_B": 1.0e-7}, {}),
        ({"B": 1.0e6, "alpha_minus_B": 2.0e-7}, {}),  # alpha equal to 12 digits: one run
        ({"alpha_minus_B": 1.0}, {}),
        ({"protocol": {"alpha_minus_B": {"pulse": {**PULSE, "base": 1.0, "level": 1.0}}}}, {}),
        ({"protocol": {"eps": {"sine": {"amplitude": 0.01, "period": 40}}}}, {}),
        ({"protocol": {"eps": {"sine": {"amplitude": 0.01, "period": 4}}}}, {}),
        ({"protocol": {"eps": {"sine": {"amplitude": 0.01, "period": 4}}}}, {"dt_max": 0.1}),
        ({}, {"steady_window": 20.0}),  # early stop off: the window changes nothing
        ({}, {"backend": "numpy"}),
        ({}, {"t_final": 100.0}),
        ({"K": 1e-4}, {"t_final": 100.0}),
    ]
    key = PointIdentity()
    built = [(Parameters.from_dict(p), Numerics.from_dict(n)) for p, n in points]
    keys = [key(p, n) for p, n in built]
    ids = [hash_canonical(p.to_dict(), n.to_dict(), 0) for p, n in built]
    for i in range(len(built)):
        for j in range(len(built)):
            assert (keys[i] == keys[j]) == (ids[i] == ids[j]), (points[i], points[j])
    # the cases above are there: alpha to 12 digits; 1.0 = the constant pulse = the defaults
    assert keys[0] == keys[1]
    assert keys[2] == keys[3] == keys[7] == keys[8]
    assert len(set(ids)) == len(ids) - 4


def test_expansion_ids_match_single_run_ids():
    c = parse_campaign(
        "name: x\nsweep: {axes: {alpha_minus_B: [0.1, 0.4], K: [1.0e-4, "
        "1.0e-3]}}\nseeds: 3\nnumerics: {resolution: 128}"
    )
    e = expand(c)
    assert len(set(e.run_ids)) == 12
    for run in e:
        assert run.run_id == run_id_for(run.point.parameters, run.point.numerics, run.seed)
    # the same grid written with alpha instead of alpha_minus_B is the same set of runs
    c2 = parse_campaign(
        "name: y\nparameters: {B: 0.5}\nsweep: {axes: {alpha: [0.6, 0.9], "
        "K: [0.0001, 0.001]}}\nseeds: [0, 1, 2]\nnumerics: {resolution: 128}"
    )
    assert expand(c2).run_ids == e.run_ids


def test_the_runs_by_point_are_the_runs_grouped_by_their_point():
    from nematic_solids.sweep.refine.runs import RunList

    c = parse_campaign(
        "name: x\nsweep: {axes: {alpha_minus_B: [0.1, 0.4], K: [1.0e-4, "
        "1.0e-3]}}\nseeds: [3, 1, 2]\nnumerics: {resolution: 128}"
    )
    e = expand(c)

    def grouped(runs: Any) -> list[tuple[Any, list[str], list[int]]]:
        out: dict[int, tuple[Any, list[str], list[int]]] = {}
        for r in runs:
            out.setdefault(id(r.point), (r.point, [], []))[1].append(r.run_id)
            out[id(r.point)][2].append(r.seed)
        return list(out.values())

    assert list(e.by_point()) == grouped(e)
    assert len(list(e.by_point())) == 4
    # a list of runs in another order (the planned runs of a round): grouped the same way
    some = [e.run(i) for i in (7, 0, 8, 3, 4)]
    assert list(RunList(c, some).by_point()) == grouped(some)


def test_the_band_texture_keeps_the_ids_it_had_before_initial_existed():
    # "initial": "band" (the only texture before the field existed) is left out of the
    # canonical text; the golden hashes above are of dicts without it
    assert hash_canonical(dict(P, initial="band"), N, 0) == GOLDEN[0]
    # the constants that were the defaults before `initial` existed (band 16, zeta = 1,
    # kappa = 10): the id this point had then
    old = Parameters.from_dict(
        {"alpha_minus_B": 0.6, "K": 3e-5, "noise_modes": 16, "zeta": 1.0, "kappa": 10.0}
    )
    assert run_id_for(old, Numerics(t_final=150, save_every=1), 7) == "702b95bdf3bae1f3"


def test_runs_of_other_defaults_are_other_runs():
    """The defaults chosen by the joint calibration (band 32, zeta = 0.5, kappa = 20) give the same
    campaign point new run ids, so results made with the earlier defaults never enter a
    phase diagram of the current ones."""
    now = run_id_for(
        Parameters.from_dict({"alpha_minus_B": 0.6, "K": 3e-5}),
        Numerics(t_final=150, save_every=1),
        7,
    )
    assert now != "702b95bdf3bae1f3"
    for name, value in (("noise_modes", 16), ("zeta", 1.0), ("kappa", 10.0)):
        one_old = Parameters.from_dict({"alpha_minus_B": 0.6, "K": 3e-5, name: value})
        assert run_id_for(one_old, Numerics(t_final=150, save_every=1), 7) not in (
            now,
            "702b95bdf3bae1f3",
        )


def test_the_per_node_texture_is_another_run_and_ignores_noise_modes():
    per_node = hash_canonical(dict(P, initial="per_node"), N, 0)
    assert per_node != GOLDEN[0]
    # the band's width does not enter the per-node texture, so it does not split its runs
    assert hash_canonical(dict(P, initial="per_node", noise_modes=48), N, 0) == per_node
    assert run_id_for(Parameters(initial="per_node", noise_modes=8), Numerics(), 0) == run_id_for(
        Parameters(initial="per_node"), Numerics(), 0
    )


def test_a_step_bound_that_can_change_the_steps_enters_the_id():
    """A sine or ramp whose step bound (a fraction of its period or piece) is below dt_max can
    change a run's steps, so its numbers: its id names the bound. A slower sine, and steps or
    pulses (which only land on their switch times), keep the ids they had without it."""
    import json

    from nematic_solids.model.parameters import Numerics, Parameters
    from nematic_solids.sweep.identity import canonical_json

    def text(protocol, **numerics):
        p = Parameters.from_dict({"protocol": protocol})
        return json.loads(canonical_json(p.to_dict(), Numerics(**numerics).to_dict(), 0))

    fast = {"eps": {"sine": {"amplitude": 0.01, "period": 10}}}  # bound 0.625 < dt_max = 1
    slow = {"eps": {"sine": {"amplitude": 0.01, "period": 50}}}  # bound 3.125 > dt_max
    ramp = {"chi": {"ramp": {"from": 10, "to": 0, "start": 1, "duration": 4}}}  # 0.125, 0.5
    pulse = {"chi": {"pulse": {"base": 10, "level": 0, "start": 1, "duration": 0.1}}}
    assert text(fast)["protocol_steps"] == "sine 0.0625, ramp 0.125"
    assert text(ramp)["protocol_steps"] == "sine 0.0625, ramp 0.125"
    assert "protocol_steps" not in text(slow)
    assert "protocol_steps" in text(slow, dt_max=4.0)
    assert "protocol_steps" not in text(fast, dt_max=0.5)
    assert "protocol_steps" in text(fast, adaptive=False, dt=1.0)
    assert "protocol_steps" not in text(pulse)


def test_the_shipped_rheology_runs_keep_their_ids_where_the_step_bound_cannot_bind(tmp_path):
    """docs/results/rheology was run before the protocol step bound: its T = 50 runs (bound
    3.125 above dt_max = 1) keep their ids, its T = 10 runs (bound 0.625) have new ones, so
    their stored numbers are never taken for a run under the bound."""
    import numpy as np
    import xarray as xr

    from nematic_solids.sweep.expand import expand
    from nematic_solids.sweep.spec import load_campaign

    results = Path(__file__).resolve().parents[2] / "docs" / "results" / "rheology"
    with xr.open_dataset(results / "phase.nc") as phase:
        periods = phase["eps_period"].broadcast_like(phase["run_id"]).values.ravel()
        stored = [str(r) for r in np.asarray(phase["run_id"]).ravel()]
        path = tmp_path / "rheology.yaml"
        path.write_text(phase.attrs["campaign_yaml"])
    planned = set(expand(load_campaign(path)).run_ids)
    slow = {r for r, T in zip(stored, periods, strict=True) if r and T == 50}
    fast = {r for r, T in zip(stored, periods, strict=True) if r and T == 10}
    assert slow
    assert fast
    assert slow <= planned
    assert not fast & planned
