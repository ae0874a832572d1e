"""Adaptive campaigns over several axes (sweep/refine with `axes:`), with the class from several
observables (`classes:`) and with seeds by precision (`precision:` together with `refine:`):
the section's checks; the pure plan on synthetic outcomes (boundaries found along each axis
in 2-D and 3-D, geometric midpoints on a log axis, the smallest spacing per axis, classes
from two observables, order independence, the run bound; a one-axis `axes:` plans exactly
as `axis:`); seeds by precision at grid and refined points; the rounds replayed from made-up
run files (a resumed campaign makes the same decisions, recorded in phase.nc); and a real
campaign at 32^2 (the Fig. A1 setting) refined over two axes with seeds by precision."""

from __future__ import annotations

import json
import math
import random
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.files import file_stamp
from nematic_solids.sweep.refine.plan import (
    first_round,
    next_round,
    points_of,
    run_bound,
    values_at,
)
from nematic_solids.sweep.refine.report import validation_lines
from nematic_solids.sweep.refine.rounds import read_plan, replay
from nematic_solids.sweep.refine.seeds import decision
from nematic_solids.sweep.spec import parse_campaign
from nematic_solids.sweep.store import CampaignStore

ROOT = Path(__file__).resolve().parents[2]


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def problems(text: str) -> list[str]:
    with pytest.raises(CampaignError) as e:
        parse_campaign(text, "c.yaml")
    return [str(p) for p in e.value.problems]


def simulate(campaign, outcome) -> tuple[list, dict]:
    """The rounds of ``campaign`` with ``outcome(line, x, seed)`` in place of runs (as the
    replay plans them: refinement rounds, then rounds that only add seeds), and the outcomes
    by point and seed."""
    rounds = [first_round(campaign)]
    values: dict = {}
    while True:
        for r in rounds[-1].runs:
            values.setdefault(r.point, {})[r.seed] = outcome(r.line, r.x, r.seed)
        refining = rounds[-1].number < campaign.refine.rounds
        if not refining and campaign.precision is None:
            return rounds, values
        nxt = next_round(campaign, rounds[-1].number + 1, values, split=refining)
        if not nxt.runs:
            return rounds, values
        rounds.append(nxt)


def n_runs(rounds) -> int:
    return sum(len(r.runs) for r in rounds)


# --------------------------------------------------------------------------- the section
BASE = """\
name: r
parameters: {noise_modes: 16}
numerics: {resolution: 64}
sweep:
  axes:
    eps: [0.0, 0.2, 0.4]
    chi: [2.0, 6.0, 10.0]
    K: {logspace: [-6, -2, 3]}
    kappa: [10.0, 20.0]
    t_final: [2.0, 3.0]
  zip: [[kappa, t_final]]
seeds: 4
"""


def test_several_axes_parse_in_the_order_of_the_dims():
    c = parse_campaign(
        BASE
        + textwrap.dedent("""\
        refine:
          axes: [K, eps, chi]
          log: [K]
          classes: {sigma2_S: 1.0e-6, cos2theta: 0.5}
          min_spacing: {eps: 0.05, chi: 1.0, K: 0.5}
          seeds: {initial: 2}
        """),
        "c.yaml",
    )
    spec = c.refine
    assert spec is not None
    assert [(a.name, a.min_spacing, a.log) for a in spec.axes] == [
        ("eps", 0.05, False),
        ("chi", 1.0, False),
        ("K", 0.5, True),
    ]
    assert [(t.observable, t.source, t.above) for t in spec.thresholds] == [
        ("sigma2_S", "sigma2_S_final", 1e-6),
        ("cos2theta", "cos2theta_final", 0.5),
    ]
    with pytest.raises(ValueError, match="not one axis"):
        _ = spec.axis
    # the bound: the other dim's 2 values x (3 + 2 x 3) eps x (3 + 2 x 3) chi x (3 + 2 x 3) K
    assert run_bound(c) == 2 * 9 * 9 * 9 * 4


@pytest.mark.parametrize(
    ("section", "words"),
    [
        (
            "{axis: eps, axes: [chi], patterned_above: 0, min_spacing: 0.1}",
            ["refine.axes", "give axis", "not both"],
        ),
        (
            "{axes: [eps, chi, eps], patterned_above: 0, min_spacing: {eps: 0.1, chi: 1}}",
            ["refine.axes[2]", "each axis once"],
        ),
        (
            "{axes: [eps, kappa], patterned_above: 0, min_spacing: {eps: 0.1, kappa: 1}}",
            ["refine.axes[1]", "zip group"],
        ),
        (
            "{axes: [eps, chi], patterned_above: 0, min_spacing: 0.1}",
            ["refine.min_spacing", "a mapping axis -> smallest spacing for each of eps, chi"],
        ),
        (
            "{axes: [eps, chi], patterned_above: 0, min_spacing: {eps: 0.1}}",
            ["refine.min_spacing.chi", "missing"],
        ),
        (
            "{axes: [eps, chi], patterned_above: 0, min_spacing: {eps: 0.1, chi: 1, K: 1}}",
            ["refine.min_spacing.K", "not a refined axis"],
        ),
        (
            "{axes: [eps, K], log: [K], patterned_above: 0, min_spacing: {eps: 0.1, K: 4}}",
            ["refine.min_spacing.K", "below the axis's span (4 decades)"],
        ),
        (
            "{axes: [eps, K], log: [eps], patterned_above: 0, min_spacing: {eps: 0.1, K: 1e-4}}",
            ["refine.log[0]", "values are all > 0", "eps has 0.0"],
        ),
        (
            "{axes: [eps, K], log: [chi], patterned_above: 0, min_spacing: {eps: 0.1, K: 1e-4}}",
            ["refine.log[0]", "a refined axis (eps, K)"],
        ),
        (
            "{axis: eps, criterion: jump, classes: {sigma2_S: 0}, min_spacing: 0.1}",
            ["refine.classes", "criterion 'fraction' only"],
        ),
        (
            "{axis: eps, patterned_above: 0, classes: {sigma2_S: 0}, min_spacing: 0.1}",
            ["refine.patterned_above", "not with classes"],
        ),
        (
            "{axis: eps, classes: {sigma2_S: 0, sigma2_S_final: 1}, min_spacing: 0.1}",
            ["refine.classes", "each observable once"],
        ),
        (
            "{axis: eps, classes: {cos2thta: 0.5}, min_spacing: 0.1}",
            ["refine.classes.cos2thta", "did you mean 'cos2theta'"],
        ),
    ],
)
def test_mistakes_in_several_axes_and_classes_are_reported(section, words):
    found = problems(BASE + f"refine: {section}\n")
    assert len(found) == 1, found
    assert found[0].startswith("c.yaml:13: "), found[0]
    for w in words:
        assert w in found[0], (w, found[0])


# --------------------------------------------------------------------------- the pure plan
PLANE = """\
name: plane
parameters: {noise_modes: 16}
numerics: {resolution: 64, t_final: 2}
sweep:
  axes:
    chi: [2.0, 6.0, 10.0]
    eps: [0.0, 0.2, 0.4]
seeds: 4
refine:
  axes: [chi, eps]
  observable: growth
  patterned_above: 0.0
  rounds: 6
  min_spacing: {chi: 0.5, eps: 0.025}
  seeds: {initial: 2, add: 2}
"""


def edge(chi: float) -> float:
    """A stability boundary in the (chi, eps) plane: unstable above it."""
    return 0.03 * chi + 0.01


def bracket(points, fixed: dict[int, float], axis: int, crossed) -> tuple[float, float]:
    """The cell of ``axis`` that holds the change of ``crossed`` on the line of ``fixed``."""
    xs = sorted({v[axis] for v in points if all(v[k] == x for k, x in fixed.items())})
    below = max(x for x in xs if not crossed(x))
    above = min(x for x in xs if crossed(x))
    return below, above


def test_a_boundary_in_the_plane_is_found_along_both_axes():
    c = parse_campaign(PLANE, "p.yaml")

    def outcome(line, x, seed):
        chi, eps = values_at(x)
        return 1.0 if eps > edge(chi) else -1.0

    rounds, _ = simulate(c, outcome)
    points = [values_at(x) for (_, x) in points_of(rounds)]
    # along eps on each of the grid's activities, to the smallest eps spacing
    for chi in (2.0, 6.0, 10.0):
        lo, hi = bracket(points, {0: chi}, 1, lambda e, chi=chi: e > edge(chi))
        assert lo <= edge(chi) < hi
        assert hi - lo <= 0.025 + 1e-12
    # along chi at eps = 0.2 (unstable below chi = 6.33), to the smallest chi spacing
    lo, hi = bracket(points, {1: 0.2}, 0, lambda chi: edge(chi) >= 0.2)
    assert lo < 19 / 3 <= hi
    assert hi - lo <= 0.5 + 1e-12
    # nothing changes along chi at eps = 0 and 0.4: no point off the grid's activities there
    assert {v[0] for v in points if v[1] in (0.0, 0.4)} == {2.0, 6.0, 10.0}
    whys = {r.why.split(" ")[1] for rnd in rounds for r in rnd.runs if r.why.startswith("bound")}
    assert whys == {"chi", "eps"}
    assert all(len(s) == 2 for s in points_of(rounds).values())  # the seeds agree everywhere


def test_a_one_axis_axes_list_plans_exactly_as_axis():
    one = PLANE.replace("axes: [chi, eps]", "axis: eps").replace("{chi: 0.5, eps: 0.025}", "0.025")
    listed = PLANE.replace("axes: [chi, eps]", "axes: [eps]").replace(
        "{chi: 0.5, eps: 0.025}", "{eps: 0.025}"
    )

    def outcome(line, x, seed):
        return 1.0 if x > edge([2.0, 6.0, 10.0][line[0]]) + 0.01 * (seed == 1) else -1.0

    a, _ = simulate(parse_campaign(one, "p.yaml"), outcome)
    b, _ = simulate(parse_campaign(listed, "p.yaml"), outcome)
    assert a == b
    assert all(isinstance(r.x, float) for rnd in a for r in rnd.runs)
    assert any(r.why.startswith("uncertain") for rnd in a for r in rnd.runs)


SPACE = """\
name: space
parameters: {noise_modes: 16}
numerics: {resolution: 64, t_final: 2}
sweep:
  axes:
    chi: [0.0, 5.0, 10.0]
    K: {logspace: [-6, -2, 3]}
    eps: [0.0, 0.05, 0.1]
seeds: 4
refine:
  axes: [chi, K, eps]
  log: [K]
  classes: {sigma2_S: 1.0e-6, cos2theta: 0.5}
  rounds: 4
  min_spacing: {chi: 1.25, K: 0.5, eps: 0.0125}
  seeds: {initial: 2, add: 2}
"""


def patterned(chi: float, k: float, eps: float) -> bool:
    """Patterned where the activity beats the Frank constant, unless the strain is large."""
    return chi > 2 + 2 * (math.log10(k) + 6) and eps < 0.07


def fig4_like(line, x, seed) -> dict[str, float]:
    chi, k, eps = values_at(x)
    return {
        "sigma2_S_final": 1e-2 if patterned(chi, k, eps) else 1e-14,
        "cos2theta_final": 0.99 if eps > 0.004 else 0.05,
    }


def test_a_boundary_in_three_dimensions_with_geometric_midpoints_and_spacings_per_axis():
    c = parse_campaign(SPACE, "s.yaml")
    rounds, _ = simulate(c, fig4_like)
    points = [values_at(x) for (_, x) in points_of(rounds)]
    chis, ks, epss = ({v[i] for v in points} for i in range(3))
    # every value is a grid value or a midpoint down to the axis's smallest spacing
    assert chis <= {1.25 * i for i in range(9)}
    assert epss <= {float(f"{0.0125 * i:.12g}") for i in range(9)}
    assert ks <= {float(f"{10 ** (-6 + 0.5 * i):.12g}") for i in range(9)}
    # the geometric midpoints of 1e-6 | 1e-4 are 1e-5 (the grid value of campaigns/fig4.yaml),
    # then 10^-5.5, normalised to 12 digits
    assert {1e-5, 3.16227766017e-05} <= ks
    # along K at chi = 5, eps = 0 (patterned below K = 10^-4.5): the cell is half a decade
    lo, hi = bracket(points, {0: 5.0, 2: 0.0}, 1, lambda k: not patterned(5.0, k, 0.0))
    assert (lo, hi) == (1e-5, 3.16227766017e-05)
    # along eps at chi = 10, K = 1e-6: the alignment boundary (above eps = 0) and the
    # pattern's (eps = 0.07), each to the eps spacing
    lo, hi = bracket(points, {0: 10.0, 1: 1e-6}, 2, lambda e: e > 0.004)
    assert (lo, hi) == (0.0, 0.0125)
    lo, hi = bracket(points, {0: 10.0, 1: 1e-6}, 2, lambda e: e >= 0.07)
    assert (lo, hi) == (0.0625, 0.075)
    # along chi at K = 1e-4, eps = 0 (patterned above chi = 6): to the chi spacing
    lo, hi = bracket(points, {1: 1e-4, 2: 0.0}, 0, lambda chi: patterned(chi, 1e-4, 0.0))
    assert lo < 6.0 < hi
    assert hi - lo == 1.25
    assert n_runs(rounds) <= run_bound(c)
    assert (
        "boundary: K 1e-06 (2/2 sigma2_S > 1e-06, 0/2 cos2theta > 0.5) | 0.0001 (0/2 "
        "sigma2_S > 1e-06, 0/2 cos2theta > 0.5)" in {r.why for r in rounds[1].runs}
    )


LINE = """\
name: line
parameters: {noise_modes: 16}
numerics: {resolution: 64, t_final: 2}
sweep:
  axes:
    eps: [0.0, 0.1, 0.2, 0.3]
seeds: 4
refine:
  axis: eps
  classes: {sigma2_S: 1.0e-6, cos2theta: 0.5}
  rounds: 1
  min_spacing: 0.025
  seeds: {initial: 2, add: 2}
"""


def test_the_class_from_two_observables():
    c = parse_campaign(LINE, "l.yaml")

    def row(s2: float, cos: float) -> dict[str, float]:
        return {"sigma2_S_final": s2, "cos2theta_final": cos}

    # every run patterned; 0 not aligned, 0.1 aligned: the class changes by cos2theta alone.
    # At 0.3 the seeds disagree on the alignment only: a mixed point.
    outcomes: dict = {
        ((), 0.0): {0: row(1e-2, 0.1), 1: row(1e-2, 0.2)},
        ((), 0.1): {0: row(1e-2, 0.9), 1: row(1e-2, 0.95)},
        ((), 0.2): {0: row(1e-2, 0.9), 1: row(1e-2, 0.95)},
        ((), 0.3): {0: row(1e-2, 0.9), 1: row(1e-2, 0.1)},
    }
    nxt = next_round(c, 1, outcomes)
    by_x: dict = {}
    for r in nxt.runs:
        by_x.setdefault(r.x, (r.why, []))[1].append(r.seed)
    assert set(by_x) == {0.05, 0.25, 0.3}
    assert by_x[0.05] == (
        "boundary: eps 0 (2/2 sigma2_S > 1e-06, 0/2 cos2theta > 0.5) | "
        "0.1 (2/2 sigma2_S > 1e-06, 2/2 cos2theta > 0.5)",
        [0, 1],
    )
    assert by_x[0.3] == (
        "uncertain: 2/2 sigma2_S > 1e-06, 1/2 cos2theta > 0.5, interval 0.76 wider than 0.6",
        [2, 3],
    )
    assert by_x[0.25][0].startswith("boundary: eps 0.2 (")
    # one observable in classes: is observable + patterned_above
    one = parse_campaign(
        LINE.replace("{sigma2_S: 1.0e-6, cos2theta: 0.5}", "{cos2theta: 0.5}"), "l.yaml"
    )
    assert "refine eps: patterned when cos2theta > 0.5; a point is mixed" in flat(
        "\n".join(validation_lines(one))
    )
    assert next_round(one, 1, outcomes) == next_round(
        parse_campaign(
            LINE.replace(
                "classes: {sigma2_S: 1.0e-6, cos2theta: 0.5}",
                "observable: cos2theta\n  patterned_above: 0.5",
            ),
            "l.yaml",
        ),
        1,
        outcomes,
    )
    # a run without one of the two values is not classified
    outcomes[((), 0.1)] = {0: row(1e-2, math.nan), 1: row(math.nan, 0.9)}
    assert {r.x for r in next_round(c, 1, outcomes).runs if r.why.startswith("bound")} == {0.25}


def test_the_plan_over_several_axes_does_not_depend_on_the_order_of_the_outcomes():
    c = parse_campaign(SPACE, "s.yaml")
    rng = random.Random(3)
    outcomes = {}
    for point, seeds in points_of([first_round(c)]).items():
        outcomes[point] = {
            s: {
                "sigma2_S_final": rng.choice([1e-14, 1e-2, math.nan]),
                "cos2theta_final": rng.choice([0.0, 1.0]),
            }
            for s in seeds
        }
    reference = next_round(c, 1, outcomes)
    assert reference.runs
    for k in range(6):
        keys = list(outcomes)
        random.Random(k).shuffle(keys)
        shuffled = {key: dict(reversed(list(outcomes[key].items()))) for key in keys}
        assert next_round(c, 1, shuffled) == reference


def test_the_run_bound_holds_over_several_axes():
    c = parse_campaign(PLANE, "p.yaml")
    bound = run_bound(c)
    assert bound == 17 * 17 * 4  # chi: 2 cells of 4 halved 3 times; eps: 2 of 0.2, too
    for k in range(4):
        rng = random.Random(k)
        rounds, _ = simulate(c, lambda line, x, seed, rng=rng: rng.choice([-1.0, 1.0]))
        assert n_runs(rounds) <= bound


# --------------------------------------------------------------------------- with precision
PRECISE = """\
name: precise
parameters: {noise_modes: 16}
numerics: {resolution: 64, t_final: 2}
sweep:
  axes:
    chi: [5.0, 6.0]           # the same outcomes; too close to be split
    eps: [0.0, 0.2, 0.4]
seeds: 8
refine:
  axes: [chi, eps]
  patterned_above: 1.0e-6
  rounds: 2
  min_spacing: {chi: 0.75, eps: 0.05}
precision:
  observable: sigma2_S
  width: 0.2
  unanimous: 4
  patterned_above: 1.0e-6
  initial: 4
  add: 2
"""


def mixed_line(line, x, seed) -> dict[str, float]:
    """Patterned above eps = 0.25 (seeds agree within 1 %); between 0.15 and 0.25 every other
    seed patterns; relaxed below (sigma2_S spread over decades: never precise)."""
    _, eps = values_at(x)
    rng = random.Random(f"{eps}-{seed}")
    on = eps > 0.25 or (eps > 0.15 and seed % 2 == 1)
    s2 = 1e-2 * (1 + 0.01 * rng.random()) if on else 10 ** (-14 + 2 * rng.random())
    return {"sigma2_S_final": s2}


def by_eps(points: dict) -> dict[float, Any]:
    """``points`` keyed by eps, checking that both activities have the same."""
    out: dict[float, Any] = {}
    for (_, x), value in points.items():
        eps = values_at(x)[1]
        assert out.setdefault(eps, value) == value, (x, value, out[eps])
    return out


def test_seeds_by_precision_at_grid_and_refined_points():
    c = parse_campaign(PRECISE, "p.yaml")
    assert c.refine is not None
    assert (c.refine.initial, c.refine.add) == (4, 2)
    rounds, values = simulate(c, mixed_line)
    seeds = by_eps(points_of(rounds))
    states = by_eps(
        {
            point: decision(c, [values[point][k] for k in s]).state
            for point, s in points_of(rounds).items()
        }
    )
    # relaxed points stop at 4 unanimous seeds, patterned ones at a precise mean; where the
    # seeds disagree (0.2 on the grid, 0.25 refined in round 2) they run to the cap, always
    # the campaign's seeds in order
    assert states == {
        0.0: "unanimous",
        0.1: "unanimous",
        0.15: "unanimous",
        0.2: "cap",
        0.25: "cap",
        0.3: "precise",
        0.4: "precise",
    }
    assert {x: len(s) for x, s in seeds.items()} == {
        0.0: 4,
        0.1: 4,
        0.15: 4,
        0.2: 8,
        0.25: 8,
        0.3: 4,
        0.4: 4,
    }
    assert seeds[0.25] == list(range(8))
    # two refinement rounds, then rounds that only add seeds (0.25's) until it is decided
    assert len(rounds) == 5
    assert all(not r.why.startswith("boundary") for rnd in rounds[3:] for r in rnd.runs)
    assert {r.x for rnd in rounds[3:] for r in rnd.runs} == {(5.0, 0.25), (6.0, 0.25)}
    assert rounds[1].runs[0].why.startswith("undecided after 4 seeds: ")
    assert n_runs(rounds) == 2 * (5 * 4 + 2 * 8)


# --------------------------------------------------------------------------- the replay
def write_run(store: CampaignStore, run_id: str, scalars: dict[str, float]) -> None:
    """A finished run as the worker leaves it (a file and a record naming its stamp)."""
    path = store.nc_path(run_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(run_id.encode())
    store.write_record(
        {
            "run_id": run_id,
            "status": "ok",
            "reason": "",
            "wall_time": 1.0,
            "scalars": scalars,
            "seed": 0,
            **file_stamp(path),
        }
    )


def run_to_the_end(campaign, store: CampaignStore):
    """Replay, "run" every pending run with :func:`mixed_line`, until finished."""
    while True:
        ref = replay(campaign, store)
        if ref.finished:
            return ref
        for line, x, seed in ref.pending:
            write_run(store, ref.run_ids[(line, x, seed)], mixed_line(line, x, seed))
        store.scan()


def test_the_replay_from_the_run_files_resumes_to_the_same_decisions(tmp_path):
    c = parse_campaign(PRECISE, "p.yaml")
    store = CampaignStore(tmp_path / "results", "precise")
    ref = run_to_the_end(c, store)
    planned, _ = simulate(c, mixed_line)
    assert ref.rounds == planned
    assert ref.stop == (
        "rounds used (2 after the grid); every point's seeds decided (4 "
        "precise, 6 unanimous, 4 cap, 0 pending)"
    )
    before = ref.to_dict()
    assert {(p["coords"]["eps"], p["seeds_run"], p["decision"]) for p in before["points"]} == {
        (0.0, 4, "unanimous"),
        (0.1, 4, "unanimous"),
        (0.15, 4, "unanimous"),
        (0.2, 8, "cap"),
        (0.25, 8, "cap"),
        (0.3, 4, "precise"),
        (0.4, 4, "precise"),
    }
    assert len(before["points"]) == 14
    assert before["precision"]["unanimous"] == 4

    ds = ref.expansion().build_phase(store.scan(), store)
    names = ds["seed_decision"].attrs["flag_meanings"].split()
    assert names == ["not_run", "pending", "precise", "unanimous", "cap"]
    assert ds["seed_decision"].attrs["flag_values"].tolist() == [-1, 0, 1, 2, 3]
    assert ds.eps.values.tolist() == [0.0, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4]
    assert ds.chi.values.tolist() == [5.0, 6.0]
    for row in range(2):
        decided = [names[int(v) + 1] for v in ds["seed_decision"].values[row]]
        assert decided == [
            "unanimous",
            "unanimous",
            "unanimous",
            "cap",
            "cap",
            "precise",
            "precise",
        ]
        assert ds["seed_count"].values[row].tolist() == [4, 4, 4, 8, 8, 4, 4]
        assert ds["refine_round"].values[row].tolist() == [0, 1, 2, 0, 2, 1, 0]
        assert np.isfinite(ds["sigma2_S"].values[row]).sum(-1).tolist() == [4, 4, 4, 8, 8, 4, 4]

    # the last round's runs lost (a killed driver): the replay stops there, then the same plan
    last = ref.rounds[-1]
    for r in last.runs:
        for p in store.runs_dir.glob(f"{ref.run_ids[(r.line, r.x, r.seed)]}*"):
            p.unlink()
    store.scan()
    mid = replay(c, store)
    assert not mid.finished
    assert mid.current.number == last.number
    assert len(mid.pending) == len(last.runs)
    assert mid.rounds == ref.rounds
    assert {d.state for p, d in mid.decisions.items() if values_at(p[1])[1] == 0.25} == {"pending"}
    again = run_to_the_end(c, store)
    assert again.to_dict() == before


# --------------------------------------------------------------------------- a real campaign
#: The Fig. A1 setting (tests/sweep/test_refine.py) refined over chi and eps, seeds by precision
#: on the growth class: stable / unstable (growth above 0) unanimous over 2 seeds, or all 3.
REAL = """\
name: {name}
parameters: {{S0: 0.0, A0: 1.0, gamma: 1.0, tau: 1.0, alpha_minus_B: 1.0, B: 0.5, K: 1.0e-4,
              B_prime: 0.0, C: 3.0, zeta: 1.0, s: 10.0, noise_amplitude: 1.0e-3,
              noise_modes: 8}}
numerics: {{mechanics: linear, incompressible: true, resolution: 32, t_final: 100.0,
            save_every: 2.0, tolerance: 1.0e-4, error_norm: rms}}
sweep:
  axes:
    chi: [4.0, 12.0]
    eps: [0.0, 0.2]
seeds: 3
store: {{snapshot_times: [50.0], snapshot_fields: [q1], snapshot_dtype: float32}}
figures: []
refine:
  axes: [chi, eps]
  observable: growth
  patterned_above: 0.0
  rounds: 2
  min_spacing: {{chi: 2.0, eps: 0.05}}
precision:
  observable: growth
  unanimous: 2
  classes: {{growth: 0.0}}
  initial: 2
  add: 1
execution: {{workers: 2}}
"""


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_a_real_campaign_refined_over_two_axes_with_seeds_by_precision(tmp_path):
    from test_cf_files import _checker_messages

    path = tmp_path / "two.yaml"
    path.write_text(REAL.format(name="two"))
    results = tmp_path / "results"
    out = invoke("validate", path)
    assert out.exit_code == 0, out.output
    text = flat(out.output)
    assert "refine chi, eps: patterned when growth > 0" in text
    assert "smallest spacing chi 2, eps 0.05; seeds by precision at every point" in text
    assert "round 0 (the grid): 4 points x 2 seed(s) = 8 runs" in text

    result = invoke("run", path, "--results", results, "--no-dashboard")
    assert result.exit_code == 0, result.output
    assert "adaptive, refining chi, eps in rounds, seeds by precision" in flat(result.output)
    assert "refinement finished after round" in result.output
    ds = xr.open_dataset(results / "two" / "phase.nc")
    names = ds["seed_decision"].attrs["flag_meanings"].split()
    flags = ds["seed_decision"].values
    count = ds["seed_count"].values
    ran = count > 0
    # every point run is decided: unanimous at 2 seeds, else all 3 (no width rule)
    assert {names[int(v) + 1] for v in flags[ran]} <= {"unanimous", "cap"}
    assert (flags[~ran] == -1).all()
    for v, n in zip(flags[ran], count[ran], strict=True):
        assert n == (2 if names[int(v) + 1] == "unanimous" else 3)
    # theory: chi = 4 is stable at any strain, chi = 12 unstable above eps = 0.087: chi is
    # refined at eps = 0.2 (8: unstable above 0.14) and eps at chi = 12
    out = flat(result.output)
    assert "chi=8, eps=0.2: seeds 0, 1: boundary: chi 4 (0/2 patterned) | 12 (2/2 patterned)" in out
    assert (
        "chi=12, eps=0.1: seeds 0, 1: boundary: eps 0 (0/2 patterned) | 0.2 (2/2 patterned)" in out
    )
    assert {4.0, 8.0, 12.0} <= set(ds.chi.values.tolist())
    assert {0.0, 0.1, 0.2} <= set(ds.eps.values.tolist())
    assert ds.attrs["refine_axis"] == "chi, eps"
    assert _checker_messages(results / "two" / "phase.nc", tmp_path) == []
    plan = read_plan(CampaignStore(results, "two"))
    assert plan is not None
    assert plan["finished"]
    assert len(plan["points"]) == int(ran.sum())
    status = invoke("status", path, "--results", results)
    assert status.exit_code == 0, status.output
    assert "decisions: 0 precise, " in status.output
    js = json.loads(invoke("status", path, "--results", results, "--json").output)
    assert js["refine"]["finished"]


# --------------------------------------------------------------------------- the campaign file
FIG4_ADAPTIVE = ROOT / "campaigns" / "fig4_adaptive.yaml"


def test_the_fig4_adaptive_campaign_validates_and_shares_fig4s_runs():
    from nematic_solids.sweep.expand import expand
    from nematic_solids.sweep.refine.rounds import RunNamer
    from nematic_solids.sweep.spec import load_campaign

    result = invoke("validate", FIG4_ADAPTIVE)
    assert result.exit_code == 0, result.output
    text = flat(result.output)
    assert (
        "refine chi, K, eps: a run's class is which of sigma2_S > 1e-06, cos2theta > 0.5 "
        "hold" in text
    )
    assert "round 0 (the grid): 27 points x 4 seed(s) = 108 runs" in text
    c = load_campaign(FIG4_ADAPTIVE)
    assert c.refine is not None
    assert c.precision is not None
    assert c.precision.thresholds == c.refine.thresholds  # one class (a YAML alias)
    # the first halving of each axis gives campaigns/fig4.yaml's values: the same runs where
    # the resolution rule keeps fig4.yaml's 128^2 (K >= 3.16e-5), other runs (on 256^2) below
    full = expand(load_campaign(ROOT / "campaigns" / "fig4.yaml"))
    namer = RunNamer(c)
    for chi, k, eps in ((0.0, 1e-3, 0.0), (10.0, 1e-4, 0.025)):
        for seed in (0, 3):
            run = full.run(full.position[namer.run_id((), (chi, k, eps), seed)])
            assert run.coords == {"chi": chi, "K": k, "eps": eps, "seed": seed}
    for chi, k, eps in ((2.5, 1e-5, 0.025), (10.0, 1e-6, 0.1)):
        assert namer.run_id((), (chi, k, eps), 0) not in full.position


def test_runs_a_refinement_over_several_axes_can_plan_are_not_orphaned(tmp_path):
    from nematic_solids.sweep.outputs.changes import run_counts
    from nematic_solids.sweep.refine.rounds import RunNamer, expansion_for

    c = parse_campaign(PRECISE, "p.yaml")
    store = CampaignStore(tmp_path / "results", "precise")
    store.runs_dir.mkdir(parents=True)
    namer = RunNamer(c)
    inside = namer.run_id((), (5.5, 0.35), 7)  # refined along both axes, a later seed
    outside = namer.run_id((), (5.5, 0.45), 1)  # beyond eps's grid
    for rid, chi, eps, seed in ((inside, 5.5, 0.35, 7), (outside, 5.5, 0.45, 1)):
        store.write_record(
            {
                "run_id": rid,
                "status": "failed",
                "reason": "nan",
                "nc_bytes": None,
                "seed": seed,
                "scalars": {},
                "coords": {"chi": chi, "eps": eps},
            }
        )
    expansion = expansion_for(c, store)
    assert inside not in expansion.position
    counts = run_counts(c, expansion, store, store.scan())
    assert counts.orphaned == [outside]
    assert counts.new == 6 * 4  # round 0: 2 chi x 3 eps x the first 4 seeds
