"""A campaign file that changed since its results were made: `run` and `status` say what
changed and how many runs are new, kept and orphaned; `run --prune` removes the orphaned
ones; an adaptive campaign's refined runs are not orphaned (real runs at 32^2 for the
commands, records made up for the rest)."""

from __future__ import annotations

import json

from sweep_helpers import records
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.outputs.changes import describe_changes, run_counts
from nematic_solids.sweep.refine.rounds import RunNamer, expansion_for
from nematic_solids.sweep.spec import parse_campaign
from nematic_solids.sweep.store import CampaignStore


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


BASE = """\
name: c
parameters: {noise_modes: 8, K: 1.0e-4}
numerics: {resolution: 32, t_final: 2}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2, 0.3]
    chi: [5.0, 10.0]
seeds: 2
"""


def test_every_kind_of_change_is_described():
    old = parse_campaign(BASE)
    new = parse_campaign(
        BASE.replace("[0.1, 0.2, 0.3]", "[0.1, 0.3, 0.4, 0.5]")
        .replace("chi: [5.0, 10.0]", "eps: [0.0, 0.05]")
        .replace("K: 1.0e-4}", "K: 2.0e-4, C: 2.0}")
        .replace("t_final: 2}", "t_final: 3}")
        .replace("seeds: 2", "seeds: [0, 1, 7]\nexecution: {workers: 1}")
    )
    assert describe_changes(old, new) == [
        "axis alpha_minus_B: values added 0.4, 0.5; values removed 0.2",
        "axis eps added: 0, 0.05",
        "axis chi removed (was 5, 10)",
        "parameters: C = 2 added; K 0.0001 -> 0.0002",
        "numerics: t_final 2 -> 3",
        "seeds: 2 -> 3; added 7",
        "also changed (no effect on the run ids): execution",
    ]
    zipped = parse_campaign(
        BASE.replace("chi: [5.0, 10.0]", "chi: [5.0, 10.0, 15.0]\n  zip: [[alpha_minus_B, chi]]")
    )
    assert describe_changes(old, zipped) == [
        "axis chi: values added 15",
        "zip groups: none -> [alpha_minus_B, chi]",
    ]
    assert describe_changes(old, parse_campaign("# a comment\n" + BASE)) == [
        "nothing that changes the runs (comments or layout)"
    ]


def test_status_says_what_changed_and_counts_the_runs(copy_of_small):
    unchanged = invoke("status", copy_of_small.path, "--results", copy_of_small.results)
    assert "differs from the one its results were made with" not in unchanged.output
    assert (
        json.loads(
            invoke(
                "status", copy_of_small.path, "--results", copy_of_small.results, "--json"
            ).output
        )["changes"]
        is None
    )
    text = copy_of_small.path.read_text()
    copy_of_small.path.write_text(text.replace("[0.1, 0.2, 20.0]", "[0.1, 0.15, 20.0]"))
    out = flat(invoke("status", copy_of_small.path, "--results", copy_of_small.results).output)
    copy = copy_of_small.results / "small" / "campaign.yaml"
    assert f"the campaign differs from the one its results were made with ({copy}):" in out
    assert "axis alpha_minus_B: values added 0.15; values removed 0.2" in out
    assert "runs: 2 new, 4 kept, 2 orphaned" in out
    assert "the orphaned runs are kept; 'nematic run --prune' removes them" in out
    report = json.loads(
        invoke("status", copy_of_small.path, "--results", copy_of_small.results, "--json").output
    )
    assert report["changes"] == {
        "copy": str(copy),
        "changes": ["axis alpha_minus_B: values added 0.15; values removed 0.2"],
        "new": 2,
        "kept": 4,
        "orphaned": 2,
        "continuing": 0,  # new runs continuing a finished shorter run (none: same t_final)
    }


def test_run_reports_the_change_first_and_prunes_only_when_asked(copy_of_small):
    old = records(copy_of_small.runs)
    orphans = {rid for rid, rec in old.items() if rec["coords"]["alpha_minus_B"] == 0.2}
    assert len(orphans) == 2
    text = copy_of_small.path.read_text()
    copy_of_small.path.write_text(text.replace("[0.1, 0.2, 20.0]", "[0.1, 0.15, 20.0]"))
    result = invoke(
        "run",
        copy_of_small.path,
        "--results",
        copy_of_small.results,
        "--no-figures",
        "--workers",
        "1",
    )
    assert result.exit_code == 1, result.output  # alpha - B = 20 still fails
    out = flat(result.output)
    assert "axis alpha_minus_B: values added 0.15; values removed 0.2" in out
    assert "runs: 2 new, 4 kept, 2 orphaned" in out
    assert "the orphaned runs are kept; --prune removes them" in out
    assert out.index("2 orphaned") < out.index("workers ready")  # before running anything
    assert all((copy_of_small.runs / f"{rid}.nc").exists() for rid in orphans)
    # the campaign copy is now the new file: nothing changed, the orphans stay until --prune
    again = invoke(
        "run", copy_of_small.path, "--results", copy_of_small.results, "--no-figures", "--prune"
    )
    assert again.exit_code == 1, again.output
    out = flat(again.output)
    assert "differs from the one its results were made with" not in out
    assert (
        f"pruned 2 orphaned run(s) (their records and run files) from {copy_of_small.runs}" in out
    )
    left = records(copy_of_small.runs)
    assert not orphans & set(left)
    assert not any((copy_of_small.runs / f"{rid}.nc").exists() for rid in orphans)
    assert len(left) == 6
    assert {rid for rid in old if rid not in orphans} <= set(left)
    once_more = invoke(
        "run",
        copy_of_small.path,
        "--results",
        copy_of_small.results,
        "--no-figures",
        "--no-aggregate",
        "--prune",
    )
    assert "nothing to prune: every run in the folder is planned by this campaign" in flat(
        once_more.output
    )


REFINED = """\
name: r
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2}
sweep:
  axes:
    chi: [5.0, 10.0]
    eps: {linspace: [0.0, 0.4, 5]}
seeds: 4
refine:
  axis: eps
  observable: sigma2_S
  patterned_above: 1.0e-6
  min_spacing: 0.0125
  seeds: {initial: 2, add: 2}
"""


def test_runs_a_refinement_can_plan_are_not_orphaned(tmp_path):
    campaign = parse_campaign(REFINED)
    store = CampaignStore(tmp_path / "results", "r")
    store.runs_dir.mkdir(parents=True)
    namer = RunNamer(campaign)
    refined = namer.run_id((0,), 0.05, 1)  # a midpoint a later round may plan
    outside = namer.run_id((0,), 0.45, 1)  # beyond the refined axis's grid
    other_seed = namer.run_id((1,), 0.05, 9)  # a seed the campaign does not have
    for rid, chi, eps, seed in (
        (refined, 5.0, 0.05, 1),
        (outside, 5.0, 0.45, 1),
        (other_seed, 10.0, 0.05, 9),
    ):
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
    expansion = expansion_for(campaign, store)
    assert refined not in expansion.position  # not in the rounds replayed so far
    counts = run_counts(campaign, expansion, store, store.scan())
    assert sorted(counts.orphaned) == sorted([outside, other_seed])
    assert counts.kept == 0
    assert counts.new == 20  # round 0: 2 chi x 5 eps x the first 2 seeds
