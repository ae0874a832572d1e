"""Seeds by precision (sweep/precision): the precision: section's checks, the pure decision of
a point from synthetic seed values (unanimous seeds stop at M, noisy ones run to the cap, a
precise mean stops early, relative and absolute widths, NaN is not precise), and a real
campaign at 32^2 (t_final 2) run with `nematic run`: every decision taken, recorded per point
in phase.nc and precision.json, the fits' seeds are the ones run, and a resumed campaign (its
last round's runs lost) makes the same decisions."""

from __future__ import annotations

import json
import math
import statistics
import textwrap

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.sweep.campaign import PrecisionSpec, Threshold
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.precision.decide import decide, interval_width, rounds_bound, t_quantile
from nematic_solids.sweep.precision.forecast import expected_seeds
from nematic_solids.sweep.precision.rounds import read_plan, replay
from nematic_solids.sweep.spec import load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore

BASE = """\
name: p
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2.0, save_every: 0.5}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2]
seeds: 8
"""


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def problems(text: str) -> list[str]:
    with pytest.raises(CampaignError) as e:
        parse_campaign(text, "c.yaml")
    return [str(p) for p in e.value.problems]


SIGMA2 = ("sigma2_S", "sigma2_S_final")


def spec(**kw) -> PrecisionSpec:
    kw.setdefault("observable", "lambda_peak")
    kw.setdefault("source", "lambda_peak")
    kw.setdefault("patterned", SIGMA2)
    return PrecisionSpec(**kw)


# --------------------------------------------------------------------------- the section
def test_the_precision_section_parses():
    c = parse_campaign(
        BASE
        + textwrap.dedent("""\
        precision: {observable: lambda_peak, width: 0.1, unanimous: 4,
                    patterned_above: 1.0e-6, initial: 2, add: 3}
        """),
        "c.yaml",
    )
    assert c.precision == PrecisionSpec(
        observable="lambda_peak",
        source="lambda_peak",
        width=0.1,
        relative=True,
        confidence=0.95,
        unanimous=4,
        patterned_above=1e-6,
        initial=2,
        add=3,
        patterned=SIGMA2,  # the nematic model's classifying observable
    )
    assert parse_campaign(BASE, "c.yaml").precision is None


@pytest.mark.parametrize(
    ("section", "words"),
    [
        (
            "{observable: lamda, width: 0.1}",
            ["c.yaml:8: precision.observable", "'lamda'", "did you mean 'lambda'"],
        ),
        ("{observable: sigma2_S, width: -1}", ["precision.width", "-1", "a number > 0"]),
        (
            "{observable: sigma2_S, width: 0.1, relative: yes please}",
            ["precision.relative", "true", "false"],
        ),
        ("{observable: sigma2_S, width: 0.1, confidence: 1.5}", ["precision.confidence", "(0, 1)"]),
        (
            "{observable: sigma2_S, unanimous: 9, patterned_above: 0}",
            ["precision.unanimous", "from 2 to 8"],
        ),
        (
            "{observable: sigma2_S, unanimous: 3}",
            ["precision.patterned_above", "missing", "needed by unanimous"],
        ),
        ("{observable: sigma2_S}", ["precision:", "no stopping rule", "width", "unanimous"]),
        ("{observable: sigma2_S, width: 0.1, initial: 20}", ["precision.initial", "from 1 to 8"]),
        ("{observable: sigma2_S, width: 0.1, add: 0}", ["precision.add", ">= 1"]),
        (
            "{observable: sigma2_S, width: 0.1, widht: 2}",
            ["precision.widht", "did you mean 'width'"],
        ),
        ("[width]", ["precision", "a mapping"]),
    ],
)
def test_precision_mistakes_are_reported_with_file_line_and_key_path(section, words):
    found = problems(BASE + f"precision: {section}\n")
    assert len(found) == 1, found
    for w in words:
        assert w in found[0], (w, found[0])


def test_precision_combines_with_refine_whose_seeds_it_decides():
    text = BASE + textwrap.dedent("""\
        refine: {axis: alpha_minus_B, patterned_above: 0.0, min_spacing: 0.01}
        precision: {observable: sigma2_S, width: 0.1, initial: 3, add: 2}
        """)
    c = parse_campaign(text, "c.yaml")
    assert c.refine is not None
    assert c.precision is not None
    assert (c.refine.initial, c.refine.add) == (3, 2)
    found = problems(text.replace("min_spacing: 0.01}", "min_spacing: 0.01, seeds: {add: 1}}"))
    assert len(found) == 1, found
    assert "refine.seeds" in found[0]
    assert "not with a precision: section" in found[0]


def test_the_class_from_several_observables():
    c = parse_campaign(
        BASE
        + textwrap.dedent("""\
        precision: {observable: sigma2_S, unanimous: 4,
                    classes: {sigma2_S: 1.0e-6, cos2theta: 0.5}}
        """),
        "c.yaml",
    )
    assert c.precision is not None
    assert [(t.observable, t.source, t.above) for t in c.precision.thresholds] == [
        ("sigma2_S", "sigma2_S_final", 1e-6),
        ("cos2theta", "cos2theta_final", 0.5),
    ]
    s = c.precision
    aligned = [(1e-3, 0.9)] * 4
    assert decide(s, [1.0, 2.0, 3.0, 9.0], aligned, 8).state == "unanimous"
    assert "cos2theta > 0.5" in decide(s, [1.0] * 4, aligned, 8).why
    # the same pattern class, but one seed not aligned: not unanimous
    assert decide(s, [1.0, 2.0, 3.0, 9.0], [*aligned[:3], (1e-3, 0.1)], 8).state == "pending"
    assert decide(s, [1.0] * 4, [*aligned[:3], (1e-3, math.nan)], 8).state == "pending"
    for section, words in [
        (
            "{observable: sigma2_S, unanimous: 4, classes: {cos2thta: 0.5}}",
            ["precision.classes.cos2thta", "did you mean 'cos2theta'"],
        ),
        (
            "{observable: sigma2_S, unanimous: 4, classes: {cos2theta: high}}",
            ["precision.classes.cos2theta", "a finite number"],
        ),
        (
            "{observable: sigma2_S, unanimous: 4, patterned_above: 0, classes: {mean_S: 0}}",
            ["precision.patterned_above", "not with classes"],
        ),
        ("{observable: sigma2_S, unanimous: 4, classes: []}", ["precision.classes", "a mapping"]),
    ]:
        found = problems(BASE + f"precision: {section}\n")
        assert len(found) == 1, found
        for w in words:
            assert w in found[0], (w, found[0])


# --------------------------------------------------------------------------- the decision
def sequence(s: PrecisionSpec, values, classes, cap: int) -> tuple[str, int]:
    """Seeds in rounds (initial, then add) until decided: (decision, seeds run)."""
    n = min(s.initial, cap)
    while True:
        d = decide(s, values[:n], classes[:n], cap)
        if d.state != "pending":
            return d.state, d.n
        n = min(n + s.add, cap)


def test_unanimous_seeds_stop_at_m():
    rng = np.random.default_rng(1)
    noisy = list(rng.lognormal(0, 2, 50))  # never precise
    relaxed = [1e-12] * 50
    s = spec(width=0.1, unanimous=6, patterned_above=1e-6, initial=2, add=2)
    assert sequence(s, noisy, relaxed, 50) == ("unanimous", 6)
    s = spec(width=0.1, unanimous=4, patterned_above=1e-6, initial=4, add=4)
    assert sequence(s, noisy, relaxed, 50) == ("unanimous", 4)
    # one seed of the other class among the first M: no unanimity, on to the cap
    mixed = [1e-12] * 3 + [1e-3] + [1e-12] * 46
    assert sequence(s, noisy, mixed, 50) == ("cap", 50)
    # a run without sigma2_S (failed) breaks the unanimity
    assert sequence(s, noisy, [math.nan] + relaxed[1:], 50) == ("cap", 50)


def test_noisy_seeds_run_to_the_cap():
    rng = np.random.default_rng(2)
    noisy = list(rng.lognormal(0, 2, 50))
    s = spec(width=0.1, initial=4, add=4)
    assert sequence(s, noisy, [math.nan] * 50, 50) == ("cap", 50)
    assert sequence(s, noisy[:10], [math.nan] * 10, 10) == ("cap", 10)


def test_a_precise_mean_stops_early():
    rng = np.random.default_rng(3)
    tight = list(0.2 + 0.002 * rng.standard_normal(50))
    s = spec(width=0.1, initial=4, add=4)
    assert sequence(s, tight, [math.nan] * 50, 50) == ("precise", 4)
    # the width shrinks like t / sqrt(n): a looser spread needs more seeds, in steps of add
    loose = list(0.2 + 0.03 * rng.standard_normal(50))
    state, n = sequence(s, loose, [math.nan] * 50, 50)
    assert state == "precise"
    assert 4 < n < 50
    assert (n - 4) % 4 == 0
    mean, width = interval_width(loose[:n], 0.95)
    assert width < 0.1 * abs(mean) <= interval_width(loose[: n - 4], 0.95)[1]


def test_relative_and_absolute_widths():
    values = [10.0, 10.2, 9.8, 10.1]
    mean, width = interval_width(values, 0.95)
    assert 0.2 < width < 0.6  # t(0.975, 3) = 3.18; s = 0.17
    assert decide(spec(width=0.1), values, [], 50).state == "precise"  # 0.1 x 10 = 1
    assert decide(spec(width=0.1, relative=False), values, [], 50).state == "pending"
    assert decide(spec(width=1.0, relative=False), values, [], 50).state == "precise"
    # around zero nothing is relatively precise
    assert decide(spec(width=0.1), [-0.1, 0.1, -0.1, 0.1], [], 50).state == "pending"


def test_nan_values_are_not_precise_and_one_seed_is_not_an_interval():
    s = spec(width=10.0, initial=1, add=1)
    assert decide(s, [0.2, 0.2, math.nan, 0.2], [], 50).state == "pending"
    assert decide(s, [0.2, 0.2, math.nan, 0.2], [], 4).state == "cap"
    assert decide(s, [0.2], [], 50).state == "pending"
    assert decide(s, [0.2, 0.2001], [], 50).state == "precise"


def test_the_forecast_projects_the_interval_to_the_seeds_it_needs():
    """A seed spread that stays what it is: the forecast is the first round count whose
    interval, t(n - 1) s / sqrt(n), is narrower than the limit, the count the rounds reach
    when the later seeds have that spread."""
    s = spec(width=0.1, initial=4, add=4)
    first = [0.17, 0.23, 0.2, 0.2]  # mean 0.2, sd 0.0245: the 4-seed interval is 0.078 wide
    sd = statistics.stdev(first)
    expected = expected_seeds(s, first, [math.nan] * 4, 50, 4)
    assert expected > 4
    assert (expected - 4) % 4 == 0

    def width(n: int) -> float:
        return 2 * t_quantile(0.95, n - 1) * sd / math.sqrt(n)

    assert width(expected) < 0.1 * 0.2 <= width(expected - 4)
    # seeds drawn with that spread are decided at about that count
    rng = np.random.default_rng(4)
    values = first + list(0.2 + sd * rng.standard_normal(46))
    state, n = sequence(s, values, [math.nan] * 50, 50)
    assert state == "precise"
    assert abs(n - expected) <= 8
    # a decided point needs what it has; planned seeds count even when not finished
    assert expected_seeds(s, [0.2, 0.2001, 0.2, 0.2], [math.nan] * 4, 50, 4) == 4
    assert expected_seeds(s, [0.2, 0.2001], [math.nan] * 2, 50, 8) == 8
    # nothing known, a seed without a value, or too wide for the cap: the cap
    assert expected_seeds(s, [], [], 50, 4) == 50
    assert expected_seeds(s, [0.2, math.nan, 0.2, 0.2], [math.nan] * 4, 50, 4) == 50
    assert expected_seeds(s, [0.01, 1.0, 0.02, 2.0], [math.nan] * 4, 50, 4) == 50


def test_the_forecast_of_the_unanimity_rule():
    s = spec(unanimous=12, patterned_above=1e-6, initial=4, add=4)
    relaxed = [1e-12] * 4
    assert expected_seeds(s, [1.0] * 4, relaxed, 50, 4) == 12
    assert expected_seeds(s, [1.0] * 4, [1e-12, 1e-3, 1e-12, 1e-12], 50, 4) == 50
    # with a width rule too, the earlier of the two
    both = spec(width=0.1, unanimous=12, patterned_above=1e-6, initial=4, add=4)
    assert expected_seeds(both, [0.01, 1.0, 0.02, 2.0], relaxed, 50, 4) == 12
    assert expected_seeds(both, [0.17, 0.23, 0.2, 0.2], relaxed, 50, 4) <= 12
    # a class from two observables (classes:): a tuple per seed, unanimous when every seed
    # is above (or below) the same thresholds
    two = spec(
        unanimous=8,
        classes=(
            Threshold("sigma2_S", "sigma2_S_final", 1e-6),
            Threshold("cos2theta", "cos2theta_final", 0.5),
        ),
        initial=4,
        add=4,
    )
    aligned = [(1e-3, 0.9)] * 4
    assert expected_seeds(two, [1.0] * 4, aligned, 50, 4) == 8
    assert expected_seeds(two, [1.0] * 4, [*aligned[:3], (1e-3, 0.1)], 50, 4) == 50
    assert expected_seeds(two, [1.0] * 4, [*aligned[:3], ()], 50, 4) == 50


def test_the_rounds_bound():
    assert rounds_bound(spec(width=0.1, initial=4, add=4), 50) == 13
    assert rounds_bound(spec(width=0.1, initial=2, add=2), 6) == 3
    assert rounds_bound(spec(width=0.1, initial=8, add=2), 8) == 1


# --------------------------------------------------------------------------- a real campaign
#: 0.1 and 0.2 pattern weakly by t = 2 (sigma2_S ~ 2e-4, 3e-4; seeds agree to a few %);
#: alpha - B = 20 fails at once (tests/sweep_helpers.py), so it has no value and no class.
REAL = """\
name: prec
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2.0, save_every: 0.5}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2, 20.0]
seeds: 6
precision:
  observable: sigma2_S
  width: 0.6
  unanimous: 2
  patterned_above: 1.0e-6
  initial: 2
  add: 2
figures: []
execution: {workers: 2}
"""


def decisions(ds: xr.Dataset) -> list[str]:
    names = ds["seed_decision"].attrs["flag_meanings"].split()
    return [names[int(v)] for v in ds["seed_decision"].values]


def test_a_real_campaign_decides_every_point_and_resumes_to_the_same_decisions(tmp_path):
    from test_cf_files import _checker_messages

    path = tmp_path / "prec.yaml"
    path.write_text(REAL)
    results = tmp_path / "results"
    out = invoke("validate", path)
    assert out.exit_code == 0, out.output
    assert "round 0: 3 points x 2 seed(s) = 6 runs" in out.output
    assert "at most 18 (every point to the cap), in at most 3 round(s)" in out.output

    first = invoke("run", path, "--results", results, "--no-dashboard")
    assert "round 1: 2 runs: 1 undecided point(s)" in first.output, first.output
    # before each later round the cost is estimated again from the runs so far: the round's
    # runs, and while rounds may follow, the bound and the forecast from the finished seeds
    re1 = first.output.split("cost re-estimated for round 1 and later from the runs so far:")[1]
    re1 = re1.split("cost re-estimated for round 2 and later from the runs so far:")[0]
    assert "2 failed (not redone), 2 to do; seeds by precision: round 1" in re1, re1
    assert "basis: from 4 finished runs of this campaign" in re1, re1
    assert "later rounds: at most 10 more runs in at most 1 more round(s) (the bound" in re1, re1
    assert "expected: about 2 more runs" in re1, re1
    assert "(forecast from the finished seeds of 3 point(s))" in re1, re1
    assert "cost re-estimated for round 2 and later" in first.output, first.output
    assert "seeds by precision finished after round 2" in first.output, first.output
    ds = xr.open_dataset(results / "prec" / "phase.nc")
    # 0.1: two seeds, not precise (their interval is wider than 0.6 x the mean) but both
    # patterned; 0.2: precise after two seeds; 20: failed runs run to the cap
    assert decisions(ds) == ["unanimous", "precise", "cap"]
    assert ds["seed_count"].values.tolist() == [2, 2, 6]
    assert ds.attrs["precision_finished"] == 1
    assert ds.attrs["precision_runs_planned"] == 10
    # the seeds not run are NaN, so seed statistics and the fits' bootstrap use those run
    finite = np.isfinite(ds["sigma2_S"].values)
    assert finite.sum(axis=1).tolist() == [2, 2, 0]
    assert not finite[:, 2:].any()
    plan = read_plan(CampaignStore(results, "prec"))
    assert plan is not None
    assert plan["finished"]
    assert [p["decision"] for p in plan["points"]] == ["unanimous", "precise", "cap"]
    assert [r["n_runs"] for r in plan["rounds"]] == [6, 2, 2]
    assert _checker_messages(results / "prec" / "phase.nc", tmp_path) == []
    status = invoke("status", path, "--results", results)
    assert "decisions: 1 precise, 1 unanimous, 1 cap, 0 pending; finished" in status.output
    js = json.loads(invoke("status", path, "--results", results, "--json").output)
    assert js["precision"]["decisions"] == {"unanimous": 1, "precise": 1, "cap": 1}

    # a killed driver: the last round's runs are lost, the plan and phase.nc too
    store = CampaignStore(results, "prec")
    c = load_campaign(path)
    before = replay(c, store)
    lost = [before.grid.run_ids[2 * 6 + j] for j in (4, 5)]
    for rid in lost:
        for p in store.runs_dir.glob(f"{rid}*"):
            p.unlink()
    (store.root / "phase.nc").unlink()
    (store.root / "precision.json").unlink()
    store.scan()
    mid = replay(c, store)
    assert not mid.finished
    assert mid.current.number == 2
    assert len(mid.pending) == 2
    assert [d.state for d in mid.decisions] == ["unanimous", "precise", "pending"]
    again = invoke("run", path, "--results", results, "--no-dashboard")
    assert "seeds by precision finished after round 2" in again.output, again.output
    after = replay(c, store)
    assert after.to_dict()["points"] == before.to_dict()["points"]
    assert after.indices() == before.indices()
    ds2 = xr.open_dataset(results / "prec" / "phase.nc")
    assert decisions(ds2) == ["unanimous", "precise", "cap"]
