"""Adaptive campaigns (sweep/refine): the refine: section's checks, the pure plan (bisection
of boundary cells, sequential seeds, order independence, the run bound), run identity of
refined points, and real campaigns at 32^2 (the Fig. A1 setting): refinement converges to the
linear-stability boundary of nematic_solids.model.stability, phase.nc holds the refined points,
status and validate show the rounds, a killed driver resumes to the same plan."""

from __future__ import annotations

import json
import math
import random
import shutil
import signal
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from sweep_helpers import group_alive, kill_group, start_driver, wait_for
from typer.testing import CliRunner

from nematic_solids.model.parameters import Parameters
from nematic_solids.model.stability import critical_eps_closed_form
from nematic_solids.sweep.analysis.stability import stability
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.refine.plan import first_round, next_round, points_of, run_bound, wilson
from nematic_solids.sweep.refine.rounds import read_plan, replay
from nematic_solids.sweep.spec import Overrides, load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore

ROOT = Path(__file__).resolve().parents[2]
FIGA1_ADAPTIVE = ROOT / "campaigns" / "figA1_adaptive.yaml"
FIG2_ADAPTIVE = ROOT / "campaigns" / "fig2_adaptive.yaml"

#: The Fig. A1 setting (campaigns/figA1.yaml: 32^2, linear incompressible, t = 100) on a
#: few activities, eps refined from a coarse grid.
A1 = """\
name: {name}
parameters: {{S0: 0.0, A0: 1.0, gamma: 1.0, tau: 1.0, alpha_minus_B: 1.0, B: 0.5, K: 1.0e-4,
              B_prime: 0.0, C: 3.0, zeta: 1.0, s: 10.0, noise_amplitude: 1.0e-3,
              noise_modes: 8}}
numerics: {{mechanics: linear, incompressible: true, resolution: 32, t_final: 100.0,
            save_every: 2.0, tolerance: 1.0e-4, error_norm: rms}}
sweep:
  axes:
    chi: {chi}
    eps: [0.0, 0.2, 0.4]
seeds: {seeds}
store: {{snapshot_times: [50.0], snapshot_fields: [q1], snapshot_dtype: float32}}
figures: []
refine:
  axis: eps
  observable: growth
  patterned_above: 0.0
  rounds: 4
  min_spacing: 0.025
  seeds: {{initial: {initial}, add: 1}}
execution: {{workers: 2}}
"""


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def a1(folder: Path, name: str, chi: str, seeds: int, initial: int = 2) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    path.write_text(A1.format(name=name, chi=chi, seeds=seeds, initial=initial))
    return path


# --------------------------------------------------------------------------- the section
BASE = """\
name: r
numerics: {resolution: 128}
sweep:
  axes:
    eps: [0.0, 0.2, 0.4]
    chi: [5.0, 10.0]
    K: [1.0e-4, 1.0e-3]
    t_final: [2.0, 3.0]
  zip: [[K, t_final]]
seeds: 4
"""


def problems(text: str) -> list[str]:
    with pytest.raises(CampaignError) as e:
        parse_campaign(text, "c.yaml")
    return [str(p) for p in e.value.problems]


def test_refine_section_parses():
    c = parse_campaign(
        BASE
        + textwrap.dedent("""\
        refine:
          axis: eps
          observable: sigma2_S
          patterned_above: 1.0e-6
          min_spacing: 0.05
          seeds: {initial: 2}
        """),
        "c.yaml",
    )
    assert c.refine is not None
    assert (c.refine.axis, c.refine.source, c.refine.criterion) == (
        "eps",
        "sigma2_S_final",
        "fraction",
    )
    assert (c.refine.initial, c.refine.add, c.refine.rounds) == (2, 2, 4)
    assert parse_campaign(BASE, "c.yaml").refine is None


@pytest.mark.parametrize(
    ("section", "words"),
    [
        (
            "refine: {axis: epz, patterned_above: 0, min_spacing: 0.1}",
            ["refine.axis", "'epz'", "did you mean 'eps'"],
        ),
        (
            "refine: {axis: K, patterned_above: 0, min_spacing: 1.0e-4}",
            ["refine.axis", "zip group"],
        ),
        (
            "refine: {axis: eps, min_spacing: 0.1}",
            ["refine.patterned_above", "missing", "criterion 'fraction'"],
        ),
        ("refine: {axis: eps, patterned_above: 0}", ["refine.min_spacing", "missing"]),
        (
            "refine: {axis: eps, patterned_above: 0, min_spacing: 0.5}",
            ["refine.min_spacing", "below the axis's span (0.4)"],
        ),
        (
            "refine: {axis: eps, patterned_above: 0, min_spacing: 0.1, seeds: {initial: 5}}",
            ["refine.seeds.initial", "from 1 to 4"],
        ),
        (
            "refine: {axis: eps, patterned_above: 0, min_spacing: 0.1, roundz: 3}",
            ["refine.roundz", "did you mean 'rounds'"],
        ),
        (
            "refine: {axis: eps, criterion: jump, jump: 0.5, min_spacing: 0.1}",
            ["refine.jump", "factor > 1"],
        ),
        (
            "refine: {axis: eps, observable: sigma2, patterned_above: 0, min_spacing: 0.1}",
            ["refine.observable", "sigma2"],
        ),
        (
            "refine: {axis: eps, fraction: [0.9, 0.1], patterned_above: 0, min_spacing: 0.1}",
            ["refine.fraction", "0 <= low < high <= 1"],
        ),
    ],
)
def test_refine_mistakes_are_reported_with_file_line_and_what_is_allowed(section, words):
    found = problems(BASE + section + "\n")
    assert len(found) == 1, found
    assert found[0].startswith("c.yaml:11: ")
    for w in words:
        assert w in found[0], found[0]


def test_refine_mistakes_are_collected_with_the_rest_of_the_file():
    text = (
        BASE.replace("seeds: 4", "seeds: 4\nexecution: {workerz: 2}")
        + "refine: {axis: chi, patterned_above: 0, min_spacing: 0.1, rounds: -1}\n"
    )
    found = problems(text)
    assert any("execution.workerz" in p for p in found), found
    assert any("refine.rounds" in p and "from 0 to 50" in p for p in found), found
    # an integer axis cannot take midpoints
    found = problems(
        BASE.replace("seeds: 4", "seeds: 4\nparameters: {}").replace(
            "    chi: [5.0, 10.0]", "    noise_modes: [8, 16]"
        )
        + "refine: {axis: noise_modes, patterned_above: 0, min_spacing: 1}\n"
    )
    assert any("a real-valued axis" in p and "int" in p for p in found), found


# --------------------------------------------------------------------------- the pure plan
LINE_CAMPAIGN = """\
name: p
parameters: {noise_modes: 16}
numerics: {resolution: 64, t_final: 2}
sweep:
  axes:
    chi: [5.0, 10.0]
    eps: {linspace: [0.0, 0.4, 5]}
seeds: 4
refine:
  axis: eps
  patterned_above: 0.0
  observable: growth
  rounds: 10
  min_spacing: 0.0125
  seeds: {initial: 2, add: 2}
"""


def test_a_refinement_that_may_exceed_max_runs_is_refused():
    text = LINE_CAMPAIGN.replace("seeds: 4", "seeds: 4\nlimits: {max_runs: 200}")
    found = problems(text)
    assert len(found) == 1, found
    assert "refine.min_spacing" in found[0]
    assert "may reach 264 runs; allowed: at most 200 (limits.max_runs)" in found[0]


def simulate(campaign, outcome) -> list:
    """Rounds of ``campaign`` with ``outcome(line, x, seed)`` in place of runs."""
    rounds = [first_round(campaign)]
    values: dict = {}
    while True:
        for r in rounds[-1].runs:
            values.setdefault(r.point, {})[r.seed] = outcome(r.line, r.x, r.seed)
        if rounds[-1].number >= campaign.refine.rounds:
            return rounds
        nxt = next_round(campaign, rounds[-1].number + 1, values)
        if not nxt.runs:
            return rounds
        rounds.append(nxt)


def test_bisection_converges_to_a_step_within_the_smallest_spacing():
    c = parse_campaign(LINE_CAMPAIGN, "p.yaml")
    edges = {(0,): 0.2904, (1,): 0.1071}  # theory eps_c at chi = 5, 10 (docs/results.md)

    def outcome(line, x, seed):
        return 1.0 if x > edges[line] else -1.0

    rounds = simulate(c, outcome)
    points = points_of(rounds)
    for line, edge in edges.items():
        xs = sorted(x for (ln, x) in points if ln == line)
        below = max(x for x in xs if x <= edge)
        above = min(x for x in xs if x > edge)
        assert above - below <= 0.0125 + 1e-12
        # only the bracketing cells were refined: coarse points + one per halving
        assert len(xs) == 5 + 3
    # all seeds agree everywhere: no point got more than the initial 2 seeds
    assert all(len(s) == 2 for s in points.values())
    assert sum(len(r.runs) for r in rounds) == 2 * (5 + 3) * 2


def test_the_plan_does_not_depend_on_the_order_of_the_outcomes():
    c = parse_campaign(LINE_CAMPAIGN, "p.yaml")
    rng = random.Random(1)
    outcomes = {}
    for (line, x), seeds in points_of([first_round(c)]).items():
        outcomes[(line, x)] = {s: rng.choice([-1.0, 1.0, math.nan]) for s in seeds}
    reference = next_round(c, 1, outcomes)
    assert reference.runs
    for k in range(10):
        keys = list(outcomes)
        random.Random(k).shuffle(keys)
        shuffled = {key: dict(reversed(list(outcomes[key].items()))) for key in keys}
        assert next_round(c, 1, shuffled) == reference


def test_sequential_seeds_are_added_only_where_the_seeds_disagree():
    c = parse_campaign(LINE_CAMPAIGN, "p.yaml")

    def outcome(line, x, seed):  # at eps = 0.2 of chi = 10 the seeds disagree
        if line == (1,) and x == 0.2:
            return 1.0 if seed % 2 else -1.0
        return 1.0 if x > 0.25 else -1.0

    nxt = next_round(
        c,
        1,
        {(r.line, r.x): {s: outcome(r.line, r.x, s) for s in (0, 1)} for r in first_round(c).runs},
    )
    added = [r for r in nxt.runs if r.why.startswith("uncertain")]
    assert {(r.line, r.x, r.seed) for r in added} == {((1,), 0.2, 2), ((1,), 0.2, 3)}
    assert "1/2 patterned" in added[0].why
    # two agreeing seeds are certain, two disagreeing ones are not (Wilson 90 %, width 0.6)
    lo, hi = wilson(0, 2, 0.9)
    assert hi - lo < 0.6
    lo, hi = wilson(1, 2, 0.9)
    assert hi - lo > 0.6


def test_failed_runs_are_run_but_not_classified():
    c = parse_campaign(LINE_CAMPAIGN, "p.yaml")
    nan = math.nan
    # chi = 10: eps = 0.2 failed for both seeds; its neighbours 0.1 (stable) and 0.3
    # (unstable) make the boundary cell; nothing is split around the failed point itself
    outcomes: dict = {
        ((1,), x): {0: v, 1: v}
        for x, v in ((0.0, -1.0), (0.1, -1.0), (0.2, nan), (0.3, 1.0), (0.4, 1.0))
    }
    nxt = next_round(c, 1, outcomes)
    # the cell 0.1-0.3 has its midpoint 0.2 already: no new point, and a failed point gets
    # no seeds (it is not uncertain: nothing was classified)
    assert nxt.runs == ()
    outcomes[((1,), 0.2)] = {0: nan, 1: 1.0}  # one seed failed, one unstable: 1/1
    nxt = next_round(c, 1, outcomes)
    assert {(r.x, r.seed) for r in nxt.runs} == {(0.15, 0), (0.15, 1), (0.2, 2), (0.2, 3)}
    assert next(r.why for r in nxt.runs if r.x == 0.2) == (
        "uncertain: 1/1 patterned, interval 0.73 wider than 0.6"
    )


def test_the_jump_criterion_splits_where_the_geometric_mean_jumps():
    text = LINE_CAMPAIGN.replace(
        "patterned_above: 0.0\n  observable: growth",
        "criterion: jump\n  jump: 10\n  observable: sigma2_S",
    )
    c = parse_campaign(text, "p.yaml")
    assert c.refine is not None
    assert c.refine.criterion == "jump"
    sig = {0.0: 1e-12, 0.1: 2e-12, 0.2: 1e-3, 0.3: 2e-3, 0.4: 3e-3}
    outcomes: dict = {((0,), x): {0: v, 1: v * 1.1} for x, v in sig.items()}
    nxt = next_round(c, 1, outcomes)
    assert {(r.x, r.seed) for r in nxt.runs} == {(0.15, 0), (0.15, 1)}
    assert "log10 mean" in nxt.runs[0].why
    # seeds a decade and more apart at a point: uncertain (max_width 0.6 decades)
    outcomes[((0,), 0.4)] = {0: 1e-3, 1: 1e-1}
    nxt = next_round(c, 1, outcomes)
    assert {(r.x, r.seed) for r in nxt.runs if r.why.startswith("uncertain")} == {
        (0.4, 2),
        (0.4, 3),
    }


def test_the_run_bound_holds_for_any_outcomes():
    c = parse_campaign(LINE_CAMPAIGN, "p.yaml")
    bound = run_bound(c)
    assert bound == 2 * (5 + 4 * 7) * 4  # 4 cells of 0.1 halved 3 times, all seeds
    for k in range(5):
        rng = random.Random(k)
        rounds = simulate(c, lambda line, x, seed, rng=rng: rng.choice([-1.0, 1.0]))
        assert sum(len(r.runs) for r in rounds) <= bound


def test_refined_points_keep_the_grid_run_identity():
    """eps = 0.025 and 0.05 reached by halving 0.1 twice are values of the full Fig. A1 grid
    (linspace, step 0.025): the refined runs are the full grid's runs (the same files)."""
    adaptive = load_campaign(FIGA1_ADAPTIVE)
    full = expand(load_campaign(ROOT / "campaigns" / "figA1.yaml"))
    namer_ref = replay(adaptive, CampaignStore(Path("/nonexistent"), "x")).namer
    assert namer_ref is not None
    chi = adaptive.dims[0].axes[0].values
    line = (chi.index(10.0),)
    for eps in (0.025, 0.05, 0.3):
        for seed in (0, 3):
            rid = namer_ref.run_id(line, eps, seed)
            i = full.position[rid]
            assert full.run(i).coords == {"chi": 10.0, "eps": eps, "seed": seed}
    # midpoints are normalised like grid values (0.1 + 0.2 is 0.30000000000000004)
    c = parse_campaign(LINE_CAMPAIGN, "p.yaml")
    nxt = next_round(
        c,
        1,
        {
            (r.line, r.x): {0: (1.0 if r.x > 0.2 else -1.0), 1: (1.0 if r.x > 0.2 else -1.0)}
            for r in first_round(c).runs
        },
    )
    assert {r.x for r in nxt.runs} == {0.25}
    assert (0.2 + 0.3) / 2 == 0.25
    assert (0.1 + 0.2) != 0.3


def test_validate_prints_the_first_round_and_a_bound():
    result = invoke("validate", FIGA1_ADAPTIVE)
    assert result.exit_code == 0, result.output
    text = flat(result.output)
    assert "round 0 (the grid): 50 points x 2 seed(s) = 100 runs" in text
    assert "runs: at most 680" in text  # the full grid's 17 x 10 x 4
    assert "refine eps: patterned when growth > 0" in text


def test_the_fig2_refine_variant_validates_at_full_and_reduced_size():
    for extra in ([], SMALL_FIG2):
        result = invoke("validate", FIG2_ADAPTIVE, *extra)
        assert result.exit_code == 0, result.output
        assert "round 0 (the grid): 5 points x 2 seed(s) = 10 runs" in flat(result.output)
    c = load_campaign(FIG2_ADAPTIVE, Overrides(settings={"mechanics": "linear"}))
    assert c.refine is not None
    assert c.refine.criterion == "jump"
    # its refined values 0.4, 0.45 (halving 0.3-0.5) are the full Fig. 2 grid's runs
    full = expand(load_campaign(ROOT / "campaigns" / "fig2.yaml"))
    namer = replay(load_campaign(FIG2_ADAPTIVE), CampaignStore(Path("/nonexistent"), "x")).namer
    assert namer is not None
    for amb in (0.4, 0.45, 0.35):
        assert namer.run_id((), amb, 7) in full.position


# --------------------------------------------------------------------------- real campaigns
#: campaigns/fig2_adaptive.yaml at small size
SMALL_FIG2 = [
    "--set",
    "resolution=32",
    "--set",
    "noise_modes=8",
    "--set",
    "mechanics=linear",
    "--seeds",
    "6",
    "--name",
    "fig2_small",
]


def theory(chi: float) -> float:
    """eps_c of the linear stability analysis (docs/stability.md Eq. S10) at the A1 values."""
    p = Parameters.from_dict(
        {
            "S0": 0.0,
            "A0": 1.0,
            "gamma": 1.0,
            "tau": 1.0,
            "alpha_minus_B": 1.0,
            "B": 0.5,
            "K": 1e-4,
            "B_prime": 0.0,
            "C": 3.0,
            "zeta": 1.0,
            "s": 10.0,
            "chi": chi,
        }
    )
    return float(critical_eps_closed_form(p, incompressible=True))


@pytest.fixture(scope="module")
def refined(tmp_path_factory):
    """A refined Fig. A1 campaign at chi = 10 with one seed, run to its end by `nematic
    run`."""
    folder = tmp_path_factory.mktemp("refine")
    path = a1(folder, "a1", "[10.0]", 1, initial=1)
    results = folder / "results"
    result = invoke("run", path, "--results", results, "--no-dashboard")
    return path, results, result


def test_refinement_converges_to_the_linear_stability_boundary(refined):
    path, results, result = refined
    assert result.exit_code == 0, result.output
    out = flat(result.output)
    assert "round 1: 1 runs: 1 new point(s)" in out
    assert "boundary: eps 0 (0/1 patterned) | 0.2 (1/1 patterned)" in out
    assert "refinement finished after round 3" in out
    eps_c = theory(10.0)
    assert 0.1 < eps_c < 0.125  # 0.1071: the closed form of docs/stability.md
    phase = xr.open_dataset(results / "a1" / "phase.nc")
    fit = stability(phase, {}, results / "a1")
    lo = float(fit.stability_eps_c_sim_lower.values[0])
    hi = float(fit.stability_eps_c_sim_upper.values[0])
    assert lo <= eps_c <= hi
    assert hi - lo <= 0.025 + 1e-12  # the smallest spacing
    assert np.allclose(phase.eps.values, [0.0, 0.1, 0.125, 0.15, 0.2, 0.4])
    assert phase.seed_count.values.tolist() == [[1, 1, 1, 1, 1, 1]]
    assert phase.refine_round.values.tolist() == [[0, 1, 3, 2, 0, 0]]
    assert phase.attrs["refine_finished"] == 1
    assert phase.attrs["n_ok"] == 6
    plan = read_plan(CampaignStore(results, "a1"))
    assert plan is not None
    assert plan["finished"]
    assert plan["n_runs"] == 6
    assert [r["n_runs"] for r in plan["rounds"]] == [3, 1, 1, 1]


def test_status_and_aggregate_of_a_refined_campaign(refined):
    path, results, _ = refined
    result = invoke("status", path, "--results", results)
    assert result.exit_code == 0, result.output
    out = flat(result.output)
    assert "6 done, 0 failed, 0 pending of 6" in out
    assert "round 0: 3 runs (3 new point(s), 0 with more seeds); done" in out
    assert "round 3: 1 runs (1 new point(s), 0 with more seeds); done" in out
    assert "finished: converged" in out
    result = invoke("status", path, "--results", results, "--json")
    data = json.loads(result.output)
    assert data["done"] == 6
    assert [r["pending"] for r in data["refine"]["rounds"]] == [0] * 4
    before = xr.load_dataset(results / "a1" / "phase.nc")
    result = invoke("aggregate", path, "--results", results)
    assert result.exit_code == 0, result.output
    after = xr.load_dataset(results / "a1" / "phase.nc")
    assert after.eps.values.tolist() == before.eps.values.tolist()
    np.testing.assert_array_equal(after.sigma2_S.values, before.sigma2_S.values)
    # a rerun finds the campaign finished and runs nothing
    result = invoke("run", path, "--results", results, "--no-dashboard", "--no-figures")
    assert result.exit_code == 0, result.output
    assert "run(s) in" not in result.output


def test_the_refined_phase_file_passes_the_cf_checker(refined, tmp_path):
    from test_cf_files import _checker_messages

    _, results, _ = refined
    assert _checker_messages(results / "a1" / "phase.nc", tmp_path) == []


@pytest.mark.slow
def test_a_killed_driver_resumes_to_the_same_plan_and_seeds_stop_where_they_agree(tmp_path):
    """`nematic run` killed (SIGKILL) in round 1, resumed: the plan equals the replay of the
    files in a copy of the folder (another machine), and the rounds recorded before the kill
    are unchanged. Sequential seeds: 2 of 3 seeds where they agree, 3 where they do not.
    Both activities converge onto the linear-stability boundary."""
    path = a1(tmp_path, "killed", "[8.0, 12.5]", 3)
    results = tmp_path / "results"
    store = CampaignStore(results, "killed")
    proc = start_driver(
        ["run", str(path), "--results", str(results), "--no-dashboard"], tmp_path / "log"
    )

    def in_round_1() -> bool:
        plan = read_plan(store)
        if plan is None or len(plan["rounds"]) < 2:
            return proc.poll() is not None
        return (
            any(r["state"] == "done" for r in plan["rounds"][1]["runs"]) or proc.poll() is not None
        )

    try:
        wait_for(in_round_1, 240, "a finished run of round 1")
        assert proc.poll() is None, (tmp_path / "log").read_text()
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        wait_for(lambda: not group_alive(proc.pid), 30, "the local workers to exit")
    finally:
        kill_group(proc)
    at_kill = read_plan(store)
    assert at_kill is not None
    assert not at_kill["finished"]
    status = invoke("status", path, "--results", results)
    assert status.exit_code == 0, status.output
    assert "in progress" in flat(status.output)
    assert "pending" in flat(status.output)

    result = invoke("run", path, "--results", results, "--no-dashboard")
    assert result.exit_code == 0, result.output
    final = read_plan(store)
    assert final is not None
    assert final["finished"]

    def runs(plan):
        return [[(r["run_id"], r["why"]) for r in rnd["runs"]] for rnd in plan["rounds"]]

    recorded = runs(at_kill)
    assert runs(final)[: len(recorded)] == recorded
    copy = tmp_path / "elsewhere"
    shutil.copytree(results, copy)  # other mtimes: the files are checksummed, not re-run
    again = replay(load_campaign(path), CampaignStore(copy, "killed"))
    assert again.finished
    assert runs(again.to_dict()) == runs(final)

    by_point: dict = {}
    for rnd in final["rounds"]:
        for r in rnd["runs"]:
            key = (r["coords"]["chi"], r["coords"]["eps"])
            by_point.setdefault(key, []).append(r["outcome"] > 0)
    for key, unstable in by_point.items():
        agree = len(set(unstable[:2])) == 1
        assert len(unstable) == (2 if agree else 3), (key, unstable)
    for chi in (8.0, 12.5):
        eps_c = theory(chi)
        stable = [e for (c, e), u in by_point.items() if c == chi and sum(u) / len(u) < 0.5]
        unstable = [e for (c, e), u in by_point.items() if c == chi and sum(u) / len(u) >= 0.5]
        assert max(stable) < eps_c < min(unstable)
        assert min(unstable) - max(stable) <= 0.025 + 1e-12


@pytest.mark.slow
def test_the_fig2_refine_variant_runs_at_small_size(tmp_path):
    """campaigns/fig2_adaptive.yaml at 32^2, linear mechanics, 6 seeds: the jump criterion
    refines alpha - B around the sigma2_S jump; the transition fit reads the refined phase.nc
    and places the jump in a cell of the smallest spacing (0.05)."""
    from nematic_solids.sweep.analysis.transition import transition

    results = tmp_path / "results"
    result = invoke(
        "run", FIG2_ADAPTIVE, *SMALL_FIG2, "--results", results, "--no-dashboard", "--no-figures"
    )
    assert result.exit_code == 0, result.output
    assert "refinement finished" in result.output
    phase = xr.open_dataset(results / "fig2_small" / "phase.nc")
    amb = phase.alpha_minus_B.values.tolist()
    assert set(amb) > {0.1, 0.3, 0.5, 0.7, 1.0}  # refined values were added
    fit = transition(phase, {"n_boot": 200})
    lo, hi = float(fit.transition_grid_lower), float(fit.transition_grid_upper)
    assert 0.1 <= lo < hi <= 1.0
    assert hi - lo <= 0.05 + 1e-12
    n = int(phase.attrs["n_ok"]) + int(phase.attrs["n_failed"])
    assert n < 11 * 6  # fewer runs than the full grid with these seeds
