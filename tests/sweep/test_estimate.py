"""Cost before launch (sweep/cost/estimate.py, sweep/cost/model.py): `nematic run --dry-run` and
`nematic validate --estimate` from a campaign's finished runs (records made up with known run
times: exact CPU and wall times), from the cost model without runs, scaled by resolution; an
adaptive campaign's round and bound; nothing written; the command-line text and errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.model.parameters import Numerics
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.cost import estimate as estimate_module
from nematic_solids.sweep.cost import model as cost_model
from nematic_solids.sweep.cost.estimate import driver_overhead, estimate, makespan
from nematic_solids.sweep.cost.model import MODEL_SPREAD, curve_steps, model_seconds, model_steps
from nematic_solids.sweep.cost.result import lines
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.files import file_stamp
from nematic_solids.sweep.refine.plan import first_round, run_bound
from nematic_solids.sweep.refine.rounds import replay
from nematic_solids.sweep.spec import Overrides, load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore

ROOT = Path(__file__).resolve().parents[2]
#: a machine with nothing else to do: 2 cores, load average 0
QUIET = (0.0, 2)

GRID = """\
name: {name}
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: 10}}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2, 0.3]
seeds: {seeds}
execution: {{workers: 2}}
"""

REFINED = """\
name: r
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 10}
sweep:
  axes:
    alpha_minus_B: [0.0, 0.4, 0.8]
seeds: 4
execution: {workers: 2}
refine:
  axis: alpha_minus_B
  observable: sigma2_S_final
  patterned_above: 1.0e-6
  rounds: 3
  min_spacing: 0.1
  seeds: {initial: 2, add: 2}
"""


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def write(folder: Path, text: str, name: str = "c") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    path.write_text(text)
    return path


def fake_run(
    store: CampaignStore,
    run_id: str,
    seconds: float,
    *,
    status: str = "ok",
    scalars: dict | None = None,
) -> None:
    """A finished run as the worker leaves it: a run file and a record naming its stamp."""
    path = store.nc_path(run_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(run_id.encode())
    store.write_record(
        {
            "run_id": run_id,
            "status": status,
            "reason": "" if status == "ok" else "nan",
            "wall_time": seconds,
            "scalars": scalars or {},
            "seed": 0,
            **file_stamp(path),
        }
    )


def tree(folder: Path) -> dict[str, tuple[int, int]]:
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in folder.rglob("*")
    }


# --------------------------------------------------------------------------- the cost model
def test_cost_model_constants_are_the_benchmarks_fit():
    """The constants in sweep/cost/model.py are benchmarks/cost_model.json's fit (3 digits)."""
    fit = json.loads((ROOT / "benchmarks" / "cost_model.json").read_text())["fit"]
    for mech, const in cost_model.COSTS.items():
        for name in ("step", "save", "setup"):
            assert const.__dict__[name] == pytest.approx(fit[mech][name], rel=5e-3, abs=1e-9)
        assert [list(p) for p in const.steps_curve] == fit[mech]["steps_curve"]
    assert pytest.approx(fit["spread"], abs=5e-3) == MODEL_SPREAD
    factors = {
        ("linear", "scheme", "etdrk2"): fit["linear"]["variants"]["scheme=etdrk2"],
        ("finite", "scheme", "etdrk2"): fit["finite"]["variants"]["scheme=etdrk2"],
        ("linear", "error_norm", "rms"): fit["linear"]["variants"]["error_norm=rms"],
        ("linear", "incompressible", True): fit["linear"]["variants"]["incompressible"],
        ("finite", "displacement", "equilibrium"): fit["finite"]["variants"][
            "displacement=equilibrium"
        ],
    }
    for key, value in factors.items():
        assert cost_model.VARIANT_FACTORS[key] == pytest.approx(value["time"], abs=5e-3)


def test_model_scales_with_resolution_length_and_mechanics():
    def secs(**kw) -> float:
        return model_seconds(Numerics.from_dict({"t_final": 300.0, **kw}))

    # a step is N^2 log2 N work plus a small overhead: 256^2 costs ~4.6x 128^2
    ratio = secs(resolution=256) / secs(resolution=128)
    assert 3.5 < ratio < 4.6 * 1.05
    assert secs(resolution=64) < secs(resolution=128) < ratio * secs(resolution=128)
    assert secs(t_final=100.0) < secs(t_final=300.0) < secs(t_final=600.0)
    assert secs(mechanics="linear") < secs(mechanics="finite")
    # steps: the curve, scaled by the tolerance (etdrk4: 1/4 power), floored by dt_max
    n = Numerics(t_final=300.0)
    assert model_steps(n) == pytest.approx(
        curve_steps(cost_model.COSTS["finite"].steps_curve, 300.0)
    )
    tighter = Numerics(t_final=300.0, tolerance=1e-4)
    assert model_steps(tighter) == pytest.approx(model_steps(n) * 10**0.25)
    assert model_steps(Numerics(t_final=300.0, dt_max=0.01)) == pytest.approx(30000.0)
    assert model_steps(Numerics(t_final=300.0, adaptive=False, dt=0.5)) == 600.0
    # beyond the curve's last time: its last slope
    curve = ((0.0, 0.0), (100.0, 50.0), (200.0, 150.0))
    assert curve_steps(curve, 300.0) == 250.0
    assert curve_steps(curve, 50.0) == 25.0


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_the_model_prices_the_steps_a_protocol_forces(tmp_path):
    """10,000 switches force 10,001 steps (one per piece); a sine 16 per period; the estimate
    of a campaign with them is priced accordingly (not at the activity curve's 448 steps)."""
    from nematic_solids.model.protocol import protocol_from

    n = Numerics(t_final=300.0)
    switches = [[0, 1.0]] + [[0.03 * (i + 1), 0.9 if i % 2 else 1.0] for i in range(9_999)]
    protocol, _ = protocol_from({"alpha_minus_B": switches})
    assert protocol.forced_steps(300.0) == 10_000
    assert model_steps(n, protocol=protocol) == 10_000
    sine, _ = protocol_from({"eps": {"sine": {"amplitude": 0.01, "period": 0.5}}})
    assert model_steps(n, protocol=sine) == pytest.approx(300.0 / 0.5 * 16)
    assert model_seconds(n, protocol=protocol) > 15 * model_seconds(n)
    slow = Numerics(t_final=300.0, adaptive=False, dt=0.5)
    assert model_steps(slow, protocol=protocol) == 10_000
    # the campaign's estimate carries it
    few = [[0, 1.0]] + [[0.1 * (i + 1), 0.9 if i % 2 else 1.0] for i in range(2_999)]
    points = ", ".join(f"[{t:g}, {v:g}]" for t, v in few)
    plain = "name: e\nparameters: {noise_modes: 8}\nnumerics: {resolution: 32, t_final: 300}\n"
    (tmp_path / "a.yaml").write_text(plain)
    (tmp_path / "b.yaml").write_text(plain + f"protocol: {{alpha_minus_B: [{points}]}}\n")
    runs = {
        f: estimate(
            load_campaign(tmp_path / f), CampaignStore(tmp_path / "r", f), load_cores=(0.0, 2)
        ).cpu[0]
        for f in ("a.yaml", "b.yaml")
    }
    assert runs["b.yaml"] > 5 * runs["a.yaml"]  # 3,000 steps against the curve's 448


def test_makespan_deals_runs_to_the_first_free_worker():
    assert makespan([10.0, 20.0, 30.0], 2) == 40.0  # 10 | 20, then 30 after the 10
    assert makespan([5.0] * 8, 2) == 20.0
    assert makespan([5.0] * 3, 8) == 5.0
    assert makespan([], 4) == 0.0


# --------------------------------------------------------------------------- estimates
def test_estimate_from_finished_runs_is_exact(tmp_path):
    """Seed 0 of each point ran (10, 20, 30 s): seed 1 at each point costs the same."""
    path = write(tmp_path, GRID.format(name="c", seeds=2))
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "c")
    exp = expand(campaign)
    for i, seconds in ((0, 10.0), (2, 20.0), (4, 30.0)):  # seed 0 of each point
        fake_run(store, exp.run_ids[i], seconds)
    e = estimate(campaign, store, load_cores=QUIET)
    assert (e.total, e.done, e.failed, e.to_do, e.measured) == (6, 3, 0, 3, 3)
    assert e.cpu[0] == pytest.approx(60.0)
    assert e.wall[0] == pytest.approx(40.0)  # 10 | 20, then 30
    assert e.workers == 2
    assert e.overhead == driver_overhead(1.0)
    assert [c.seconds for c in e.points] == [10.0, 20.0, 30.0]
    assert all(c.basis == "its 1 finished run" for c in e.points)
    assert e.basis.startswith("from 3 finished runs of this campaign")
    # one measurement per point: the spread is that of the ratios measured / model
    assert e.cpu[1] < 60.0 < e.cpu[2]


def test_points_with_several_runs_give_the_seed_spread(tmp_path):
    path = write(tmp_path, GRID.format(name="c", seeds=4))
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "c")
    exp = expand(campaign)
    for point, times in enumerate(((8.0, 12.0), (18.0, 22.0), (27.0, 33.0))):
        for seed, seconds in enumerate(times):
            fake_run(store, exp.run_ids[4 * point + seed], seconds)
    e = estimate(campaign, store, load_cores=QUIET)
    assert e.to_do == 6
    assert e.cpu[0] == pytest.approx(2 * (10.0 + 20.0 + 30.0))
    # within-point ratios 0.8, 1.2, 0.9, 1.1, 0.9, 1.1: 10 % and 90 % quantiles 0.85, 1.15
    assert e.cpu[1] == pytest.approx(120.0 * 0.85)
    assert e.cpu[2] == pytest.approx(120.0 * 1.15)


def test_unmeasured_points_are_scaled_by_the_cost_model(tmp_path):
    """Runs at 32^2 measured; the 64^2 runs cost that ratio times the model's 64^2 cost."""
    text = (
        GRID.format(name="c", seeds=1)
        .replace("resolution: 32, ", "")
        .replace("[0.1, 0.2, 0.3]", "[0.1, 0.2, 0.3]\n    resolution: [32, 64]")
    )
    path = write(tmp_path, text)
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "c")
    exp = expand(campaign)
    at32 = [i for i in range(len(exp)) if exp.run(i).point.numerics.resolution == 32]
    ratios = []
    for k, i in enumerate(at32):
        seconds = 2.0 * (k + 1)
        fake_run(store, exp.run_ids[i], seconds)
        ratios.append(seconds / model_seconds(exp.run(i).point.numerics))
    e = estimate(campaign, store, load_cores=QUIET)
    assert e.to_do == 3
    model64 = model_seconds(Numerics.from_dict({"resolution": 64, "t_final": 10}))
    assert sorted(ratios)[1] * model64 * 3 == pytest.approx(e.cpu[0])
    assert {c.basis for c in e.points} == {"scaled"}
    assert model64 > model_seconds(Numerics.from_dict({"resolution": 32, "t_final": 10}))


def test_a_busy_machine_stretches_the_cost_model_and_the_driver(tmp_path):
    """Load average 6 on 2 cores: each of 2 workers gets 2 / (6 + 2) of a core."""
    path = write(tmp_path, GRID.format(name="c", seeds=2))
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "c")
    one = model_seconds(expand(campaign).points[0].numerics)
    e = estimate(campaign, store, load_cores=(6.0, 2))
    assert e.stretch == 4.0
    assert e.cpu[0] == pytest.approx(6 * one)  # CPU time: a free core per run
    assert e.wall[0] == pytest.approx(3 * one * 4.0)
    assert e.overhead == pytest.approx(driver_overhead(4.0))
    assert "each worker gets about 25 % of a core" in flat("\n".join(lines(e)))
    # measured run times are taken as they are; the driver is still stretched
    exp = expand(campaign)
    for i, seconds in ((0, 10.0), (2, 20.0), (4, 30.0)):
        fake_run(store, exp.run_ids[i], seconds)
    e = estimate(campaign, store, load_cores=(6.0, 2))
    assert e.wall[0] == pytest.approx(40.0)
    assert e.overhead == pytest.approx(driver_overhead(4.0))
    # more workers than cores stretch too
    assert estimate_module.slowdown(8, 0.0, 2) == 4.0
    assert estimate_module.slowdown(2, 0.0, 2) == 1.0


def test_a_running_driver_does_not_count_its_start_or_its_workers_again(tmp_path):
    """Re-estimated mid-campaign (``started``: the seconds the driver took to start): the
    driver's own time left is its overhead less those seconds (never below zero), and the
    load average's share of the campaign's own 2 workers is not other load."""
    path = write(tmp_path, GRID.format(name="c", seeds=2))
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "c")
    before = estimate(campaign, store, load_cores=QUIET)
    again = estimate(campaign, store, load_cores=QUIET, started=5.0)
    assert again.overhead == pytest.approx(before.overhead - 5.0)
    assert estimate(campaign, store, load_cores=QUIET, started=1e3).overhead == 0.0
    busy = estimate(campaign, store, load_cores=(2.0, 2))  # 2 others: each worker half a core
    assert busy.stretch == 2.0
    mine = estimate(campaign, store, load_cores=(2.0, 2), started=0.0)  # the 2 are ours
    assert mine.stretch == 1.0
    assert mine.overhead == pytest.approx(driver_overhead(1.0))


def test_cost_model_without_runs_and_without_a_folder(tmp_path):
    path = write(tmp_path, GRID.format(name="c", seeds=2))
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "c")
    e = estimate(campaign, store, load_cores=QUIET)
    one = model_seconds(expand(campaign).points[0].numerics)
    assert (e.to_do, e.measured) == (6, 0)
    assert e.cpu == pytest.approx((6 * one, 6 * one * MODEL_SPREAD[0], 6 * one * MODEL_SPREAD[1]))
    assert e.wall[0] == pytest.approx(3 * one)
    assert e.basis.startswith("cost model, no finished runs")
    assert not (tmp_path / "results").exists()


def test_failed_runs_are_to_do_only_with_retry_failed(tmp_path):
    path = write(tmp_path, GRID.format(name="c", seeds=1))
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "c")
    exp = expand(campaign)
    fake_run(store, exp.run_ids[0], 5.0)
    fake_run(store, exp.run_ids[1], 1.0, status="failed")
    e = estimate(campaign, store, load_cores=QUIET)
    assert (e.done, e.failed, e.to_do, e.measured) == (1, 1, 1, 1)
    assert estimate(campaign, store, retry_failed=True, load_cores=QUIET).to_do == 2
    # a run whose file was damaged is redone
    store.nc_path(exp.run_ids[0]).write_bytes(b"truncated")
    assert estimate(campaign, store, load_cores=QUIET).to_do == 2
    # everything done: nothing to do, and no wall time
    for i in range(3):
        fake_run(store, exp.run_ids[i], 5.0)
    e = estimate(campaign, store, load_cores=QUIET)
    assert e.to_do == 0
    assert e.cpu[0] == 0.0
    assert e.overhead == 0.0
    assert "nothing to do" in lines(e)


def test_adaptive_campaign_round_and_bound(tmp_path):
    campaign = parse_campaign(REFINED)
    store = CampaignStore(tmp_path / "results", "r")
    e = estimate(campaign, store, load_cores=QUIET)  # no results: round 0
    assert not (tmp_path / "results").exists()
    n0 = len(first_round(campaign).runs)
    assert (e.total, e.to_do) == (n0, n0)
    assert e.later is not None
    assert e.later.runs == run_bound(campaign) - n0
    assert e.later.rounds == 3
    one = model_seconds(Numerics.from_dict({"resolution": 32, "t_final": 10}))
    assert e.later.cpu == pytest.approx(e.later.runs * one)
    assert e.later.expected is None  # a refinement is not forecast without a prior
    assert "no expected value: a refinement's rounds are not forecast" in flat(" ".join(lines(e)))
    assert "adaptive: round 0 (the grid)" in lines(e)[0]
    # round 0 done (patterned above 0.4): round 1 splits the cell 0.4-0.8 at 0.6
    ref = replay(campaign, store)
    for (_, x, _), rid in ref.run_ids.items():
        fake_run(store, rid, 4.0, scalars={"sigma2_S_final": 1.0 if x > 0.5 else 0.0})
    e = estimate(campaign, store, load_cores=QUIET)
    ref = replay(campaign, store)
    assert ref.current.number == 1
    assert e.to_do == len(ref.current.runs)
    assert e.measured == n0
    assert e.cpu[0] == pytest.approx(4.0 * e.to_do)  # scaled: every run measured 4 s
    assert e.later is not None
    assert e.later.runs == run_bound(campaign) - ref.n_runs
    assert e.later.cpu == pytest.approx(4.0 * e.later.runs)


def test_a_finished_refinement_with_seeds_by_precision_has_nothing_to_do(tmp_path):
    """A campaign with refine: and precision: (as fig4_adaptive.yaml) run to its end: the estimate
    says nothing to do (it used to stop on the seeds of a precision-only campaign)."""
    text = REFINED.replace("  seeds: {initial: 2, add: 2}\n", "") + (
        "precision: {observable: sigma2_S, width: 0.1, unanimous: 2, patterned_above: 1.0e-6,\n"
        "            initial: 2, add: 2}\n"
    )
    campaign = parse_campaign(text)
    store = CampaignStore(tmp_path / "results", "r")
    for _ in range(20):
        ref = replay(campaign, store)
        if ref.finished:
            break
        for (_, _x, _), rid in ref.run_ids.items():
            if not store.nc_path(rid).exists():
                fake_run(store, rid, 3.0, scalars={"sigma2_S_final": 0.0})
    assert replay(campaign, store).finished
    e = estimate(campaign, store, load_cores=QUIET)
    assert e.to_do == 0
    assert e.later is None
    assert "refinement finished" in lines(e)[0]
    assert "nothing to do" in lines(e)


PRECISE = """\
name: p
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 10}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2, 0.3]
seeds: 20
execution: {workers: 2}
precision: {observable: sigma2_S, width: 0.1, unanimous: 8, patterned_above: 1.0e-6,
            initial: 4, add: 4}
"""


def test_seeds_by_precision_current_round_and_forecast(tmp_path):
    """The current round is costed; the later rounds are the seeds each point is forecast
    to need (sweep/precision/forecast.py) at the point's measured cost, with the bound."""
    campaign = parse_campaign(PRECISE)
    store = CampaignStore(tmp_path / "results", "p")
    e = estimate(campaign, store, load_cores=QUIET)  # nothing run: round 0, the rest unknown
    assert (e.total, e.to_do) == (12, 12)
    assert "seeds by precision: round 0" in lines(e)[0]
    assert e.later is not None
    assert e.later.runs == 60 - 12  # the bound: every point to the cap
    assert e.later.expected is None  # no data: no expected value, and the text says so
    text = flat(" ".join(lines(e)))
    assert "expected: about" not in text
    assert "at most 48 more runs" in text
    assert "no expected value: no point has finished seeds yet" in text
    # round 0 done: 0.1 relaxed (unanimous at 8), 0.2 precise already, 0.3 mixed (the cap)
    values = {
        0.1: [1e-12, 3e-12, 2e-13, 5e-12],
        0.2: [1.0, 1.01, 0.99, 1.0],
        0.3: [1e-12, 1.0, 0.02, 2.0],
    }
    grid = expand(campaign)
    for i, rid in enumerate(grid.run_ids):
        run = grid.run(i)
        x, j = run.point.coords["alpha_minus_B"], grid.seeds.index(run.seed)
        if j < 4:
            fake_run(
                store,
                rid,
                2.0 if x < 0.3 else 5.0,
                scalars={"sigma2_S_final": values[round(x, 1)][j]},
            )
    e = estimate(campaign, store, load_cores=QUIET)
    assert "seeds by precision: round 1" in lines(e)[0]
    assert e.to_do == 8  # 0.1 and 0.3 get seeds 4-7
    assert e.cpu[0] == pytest.approx(4 * 2.0 + 4 * 5.0)
    assert e.later is not None
    assert e.later.expected is not None
    assert e.later.expected.runs == 12  # 0.3 on to 20 seeds; 0.1 stops at 8
    assert e.later.expected.cpu == pytest.approx(12 * 5.0)
    assert e.later.runs == 60 - 20
    text = flat(" ".join(lines(e)))
    assert "expected: about 12 more runs" in text
    assert "forecast from the finished seeds of 3 point(s)" in text


def write_prior(path, seeds_run):
    """A phase.nc of campaign PRECISE whose points ran ``seeds_run`` seeds."""
    status = np.zeros((3, 20), dtype=np.int8)
    for k, n in enumerate(seeds_run):
        status[k, :n] = 1
    xr.Dataset(
        {"status": (("alpha_minus_B", "seed"), status)},
        coords={"alpha_minus_B": [0.1, 0.2, 0.3], "seed": np.arange(20)},
        attrs={"campaign": "p", "run_git_commits": "abc1234"},
    ).to_netcdf(path)


def test_a_prior_gives_the_expected_value_before_any_run(tmp_path):
    write_prior(tmp_path / "phase.nc", [8, 4, 20])
    path = tmp_path / "p.yaml"
    path.write_text(PRECISE + "prior: phase.nc\n")
    campaign = load_campaign(path)
    e = estimate(campaign, CampaignStore(tmp_path / "results", "p"), load_cores=QUIET)
    assert e.later is not None
    assert e.later.expected is not None
    assert e.later.expected.runs == 4 + 0 + 16  # the prior's seeds beyond round 0's 4
    assert e.later.runs == 60 - 12
    text = flat(" ".join(lines(e)))
    assert "prior: the 32 runs of campaign p in" in text
    assert "3 point(s) from the prior" in text


def test_the_copy_of_a_campaign_with_a_relative_prior_reads_it_from_the_campaign_folder(tmp_path):
    """The results folder's copy of a campaign whose ``prior:`` is relative (the paper's
    campaigns) is read against the campaign file's folder: opened by name, and compared
    with the file when it changes (what changed is listed, not 'not a valid campaign')."""
    from nematic_solids.sweep import open_campaign
    from nematic_solids.sweep.campaign_copy import save_campaign_copy
    from nematic_solids.sweep.outputs.changes import campaign_changes

    (tmp_path / "docs").mkdir()
    write_prior(tmp_path / "docs" / "phase.nc", [8, 4, 20])
    (tmp_path / "campaigns").mkdir()
    path = tmp_path / "campaigns" / "p.yaml"
    path.write_text(PRECISE + "prior: ../docs/phase.nc\n")
    campaign = load_campaign(path)
    store = CampaignStore(tmp_path / "results", "p")
    store.root.mkdir(parents=True)
    save_campaign_copy(store, campaign)  # as `run`
    opened = open_campaign("p", results=tmp_path / "results")
    assert opened.campaign.precision == campaign.precision
    assert campaign_changes(campaign, store) is None  # the same campaign
    path.write_text(PRECISE.replace("seeds: 20", "seeds: 30") + "prior: ../docs/phase.nc\n")
    changed = campaign_changes(load_campaign(path), store)
    assert changed is not None
    assert not any("not a valid campaign" in line for line in changed.lines())


def test_a_missing_or_unreadable_prior_is_said_and_gives_no_expected_value(tmp_path):
    with pytest.raises(CampaignError) as err:
        parse_campaign(PRECISE + "prior: nowhere.nc\n", source=str(tmp_path / "p.yaml"))
    assert "prior: no file" in str(err.value)
    (tmp_path / "bad.nc").write_bytes(b"not netcdf")
    path = tmp_path / "p.yaml"
    path.write_text(PRECISE + "prior: bad.nc\n")
    e = estimate(load_campaign(path), CampaignStore(tmp_path / "r", "p"), load_cores=QUIET)
    assert e.later is not None
    assert e.later.expected is None
    assert "the prior is not used: cannot read" in flat(" ".join(lines(e)))


# --------------------------------------------------------------------------- the commands
@pytest.fixture
def quiet_machine(monkeypatch):
    monkeypatch.setattr(estimate_module, "machine_load", lambda: QUIET)


def test_dry_run_prints_the_estimate_and_writes_nothing(tmp_path, quiet_machine):
    path = write(tmp_path, GRID.format(name="c", seeds=2))
    results = tmp_path / "results"
    r = invoke("run", path, "--results", results, "--dry-run")
    assert r.exit_code == 0, r.output
    assert not results.exists()
    out = flat(r.output)
    assert "dry run of campaign c" in out
    assert "nothing is run or written" in out
    assert "runs: 6 planned, 0 done, 0 failed (not redone), 6 to do" in out
    assert "basis: cost model, no finished runs" in out
    assert "CPU time:" in out
    assert "CPU-h" in out
    assert "wall time:" in out
    assert "on 2 worker(s) (local cluster;" in out
    # with finished runs: their basis; the folder is left as it was (no lock, no manifest)
    store = CampaignStore(results, "c")
    exp = expand(load_campaign(path))
    for i, seconds in ((0, 10.0), (2, 20.0), (4, 30.0)):
        fake_run(store, exp.run_ids[i], seconds)
    before = tree(results)
    r = invoke("run", path, "--results", results, "--dry-run", "--workers", "3")
    assert r.exit_code == 0, r.output
    assert tree(results) == before
    out = flat(r.output)
    assert (
        "basis: from 3 finished runs of this campaign (run times 10 s to 30 s, median 20 s)" in out
    )
    assert "alpha_minus_B=0.1: 1 to do, 10 s each" in out
    assert "CPU time: 1 min 00 s = 0.017 CPU-h" in out
    # 3 workers on 2 cores: each gets 2/3 of a core (the driver is stretched, not the runs)
    assert f"wall time: {30 + driver_overhead(1.5):.0f} s on 3 worker(s)" in out
    assert "each worker gets about 67 % of a core" in out
    assert (
        f"wall time: {40 + driver_overhead(1.0):.0f} s on 2 worker(s) (this machine's "
        "local cluster" in out
    )
    # -q: the totals only
    r = invoke("run", path, "--results", results, "--dry-run", "-q")
    assert "alpha_minus_B=0.1" not in r.output
    assert "CPU time" in r.output


def test_dry_run_of_a_real_campaign_folder_writes_nothing(copy_of_small, quiet_machine):
    """The small campaign's real records (run times measured by the workers)."""
    before = tree(copy_of_small.results)
    r = invoke(
        "run",
        copy_of_small.path,
        "--results",
        copy_of_small.results,
        "--dry-run",
        "--seeds",
        "4",
        "--retry-failed",
    )
    assert r.exit_code == 0, r.output
    assert tree(copy_of_small.results) == before
    out = flat(r.output)
    assert "runs: 12 planned, 4 done, 0 failed (not redone), 8 to do" in out
    assert "basis: from 4 finished runs of this campaign" in out


def test_validate_estimate(tmp_path, quiet_machine):
    path = write(tmp_path, GRID.format(name="c", seeds=2))
    r = invoke("validate", path, "--results", tmp_path / "results", "--estimate")
    assert r.exit_code == 0, r.output
    out = flat(r.output)
    assert out.startswith("valid: campaign c")
    assert "basis: cost model, no finished runs" in out
    assert "wall time:" in out
    assert not (tmp_path / "results").exists()
    assert "CPU time" not in invoke("validate", path, "--results", tmp_path / "results").output


def test_bad_input_is_one_line(tmp_path):
    path = write(tmp_path, GRID.format(name="c", seeds=2))
    for extra, says in (
        (["--detach"], "does not take --detach"),
        (["--prune"], "does not take --prune"),
    ):
        r = invoke("run", path, "--results", tmp_path / "results", "--dry-run", *extra)
        assert r.exit_code == 2
        assert says in r.output
        assert "Traceback" not in r.output
        assert len(r.output.strip().splitlines()) == 1
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    r = invoke("run", path, "--results", blocker, "--dry-run")
    assert r.exit_code == 2
    assert r.output.startswith("error: ")
    assert "Traceback" not in r.output
    bad = write(tmp_path, GRID.format(name="c", seeds=2).replace("numerics", "numercs"), "bad")
    r = invoke("run", bad, "--dry-run")
    assert r.exit_code == 2
    assert "error: invalid campaign" in r.output


def test_quickstart_estimate_without_results(tmp_path):
    """The quickstart (8 runs, 128^2, finite, t = 40) from the cost model alone."""
    campaign = load_campaign(
        ROOT / "campaigns" / "quickstart.yaml", Overrides(name="estimate-test")
    )
    e = estimate(campaign, CampaignStore(tmp_path / "results", campaign.name), load_cores=QUIET)
    assert e.to_do == 8
    assert e.workers == 2
    one = model_seconds(Numerics(resolution=128, t_final=40.0, save_every=1.0))
    assert e.cpu[0] == pytest.approx(8 * one)
    assert math.isclose(e.wall[0], 4 * one)


def test_workers_of_a_batch_cluster_and_of_a_scheduler(tmp_path):
    """A dask-jobqueue cluster runs jobs x cores at once (its runs are not stretched by this
    machine's load); an external scheduler's workers are not known: the local count."""
    text = GRID.format(name="c", seeds=2).replace(
        "execution: {workers: 2}",
        "execution: {cluster: {kind: slurm, jobs: 3, cores: 2, processes: 2, memory: 4GB}}",
    )
    campaign = parse_campaign(text)
    e = estimate(campaign, CampaignStore(tmp_path / "results", "c"), load_cores=(6.0, 2))
    one = model_seconds(expand(campaign).points[0].numerics)
    assert e.workers == 6
    assert "slurm cluster: jobs 3 x cores 2" in e.where
    assert e.wall[0] == pytest.approx(one)  # 6 runs on 6 workers, not stretched
    assert e.overhead == pytest.approx(driver_overhead(e.stretch))
    text = GRID.format(name="c", seeds=2).replace(
        "execution: {workers: 2}", "execution: {scheduler: 'tcp://127.0.0.1:8786'}"
    )
    e = estimate(parse_campaign(text), CampaignStore(tmp_path / "results", "c"), load_cores=QUIET)
    assert "its workers are not known here" in e.where


def test_a_prior_with_run_times_prices_the_planned_and_the_later_runs(tmp_path):
    """A prior whose phase.nc has each run's time: the runs planned now cost the prior's mean
    time at their point (this campaign has measured none), and the later rounds' expected value
    is the prior's runs beyond those planned, at their own times (not a mean of round 0's)."""
    grid = np.linspace(0, 0.8, 9)
    status = np.zeros((9, 4), dtype=np.int8)
    status[:, :2] = 1  # 18 runs in all
    times = np.where(status == 1, 1.0, np.nan)
    times[grid > 0.3, :2] = 50.0  # the refined points near the boundary are the slow ones
    times[np.isclose(grid, 0.4), :2] = [10.0, 30.0]  # a grid point: mean 20 s
    xr.Dataset(
        {
            "status": (("alpha_minus_B", "seed"), status),
            "run_time": (("alpha_minus_B", "seed"), times, {"units": "s"}),
        },
        coords={"alpha_minus_B": grid, "seed": np.arange(4)},
        attrs={"campaign": "r"},
    ).to_netcdf(tmp_path / "phase.nc")
    path = tmp_path / "r.yaml"
    path.write_text(REFINED + "prior: phase.nc\n")
    campaign = load_campaign(path)
    e = estimate(campaign, CampaignStore(tmp_path / "results", "r"), load_cores=QUIET)
    # round 0: 0.0, 0.4, 0.8 with 2 seeds each, at 1 s, 20 s and 50 s
    assert e.to_do == 6
    assert e.cpu[0] == pytest.approx(2 * (1.0 + 20.0 + 50.0))
    assert "3 point(s) at the measured run times of the prior" in flat(" ".join(lines(e)))
    assert "cost model" not in lines(e)[-1]
    planned = {0.0: 1.0 * 2, 0.4: 40.0, 0.8: 100.0}
    total = float(np.nansum(times))
    assert e.later is not None
    assert e.later.expected is not None
    assert e.later.expected.runs == 18 - 6
    assert e.later.expected.cpu == pytest.approx(total - sum(planned.values()))
    assert "12 of them beyond the runs planned so far, at their measured run times" in flat(
        " ".join(lines(e))
    )


def test_a_prior_measured_on_another_grid_is_scaled_by_the_cost_model(tmp_path):
    """The prior ran on 16^2 (its num_resolution), the campaign runs on 32^2: a planned run
    costs the prior's time there times the cost model's ratio of the two grids, and so does
    each of the prior's runs that prices the later rounds."""
    grid = np.linspace(0, 0.8, 9)
    status = np.zeros((9, 4), dtype=np.int8)
    status[:, :2] = 1
    xr.Dataset(
        {
            "status": (("alpha_minus_B", "seed"), status),
            "run_time": (("alpha_minus_B", "seed"), np.where(status == 1, 3.0, np.nan)),
        },
        coords={"alpha_minus_B": grid, "seed": np.arange(4)},
        attrs={"campaign": "r", "num_resolution": 16},
    ).to_netcdf(tmp_path / "phase.nc")
    path = tmp_path / "r.yaml"
    path.write_text(REFINED + "prior: phase.nc\n")
    e = estimate(load_campaign(path), CampaignStore(tmp_path / "results", "r"), load_cores=QUIET)
    ratio = model_seconds(Numerics.from_dict({"resolution": 32, "t_final": 10})) / model_seconds(
        Numerics.from_dict({"resolution": 16, "t_final": 10})
    )
    assert ratio > 1.1  # (small grids: per-step overheads dominate the cost model)
    assert e.cpu[0] == pytest.approx(6 * 3.0 * ratio)
    assert "on 16^2, scaled to 32^2 by the cost model" in flat(" ".join(lines(e)))
    # the later rounds: the prior's 12 runs beyond the planned ones, each scaled alike
    assert e.later is not None
    assert e.later.expected is not None
    assert e.later.expected.runs == 12
    assert e.later.expected.cpu == pytest.approx(12 * 3.0 * ratio)
    assert "at 9 point(s) on another grid than this campaign's there" in flat(" ".join(lines(e)))


def test_a_refinement_expects_the_priors_run_count(tmp_path):
    campaign_text = REFINED
    status = np.zeros((9, 4), dtype=np.int8)
    status[:, :2] = 1  # 18 runs in all
    xr.Dataset(
        {"status": (("alpha_minus_B", "seed"), status)},
        coords={"alpha_minus_B": np.linspace(0, 0.8, 9), "seed": np.arange(4)},
        attrs={"campaign": "r"},
    ).to_netcdf(tmp_path / "phase.nc")
    path = tmp_path / "r.yaml"
    path.write_text(campaign_text + "prior: phase.nc\n")
    campaign = load_campaign(path)
    e = estimate(campaign, CampaignStore(tmp_path / "results", "r"), load_cores=QUIET)
    n0 = len(first_round(campaign).runs)
    assert e.later is not None
    assert e.later.expected is not None
    assert e.later.expected.runs == 18 - n0
    assert e.later.runs == run_bound(campaign) - n0  # the bound is unchanged
    assert f"18 runs in all, {n0} planned so far" in flat(" ".join(lines(e)))
