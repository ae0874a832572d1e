"""A chain whose up branch starts each run from a fresh texture (``chain: {up: fresh}``): the
up branch's runs are the plain runs of its points, the down branch's ids are the quasi-static
chain's (and those ids did not move: pinned), the top run shared by both branches runs once,
and the ``transition`` fit gives the loop width with its interval from this one campaign."""

from __future__ import annotations

import hashlib

import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.spec import parse_campaign

LOOP = """\
name: loop
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: {t_final}, save_every: 1}}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.8, 0.4]
chain: {{axis: alpha_minus_B{extra}}}
seeds: 2
execution: {{workers: 2}}
"""


def loop(extra: str = "", t_final: float = 6) -> str:
    return LOOP.format(extra=extra, t_final=t_final)


def test_the_quasi_static_chain_keeps_its_ids():
    """The run ids of a chain without ``up:`` (tests/sweep/test_chains.py's campaign), pinned:
    the option leaves them as they were. (Pinned again when the exact first guess of a
    finite-strain successor's displacement entered the successors' ids: "93f5b18a155138bf"
    before, tests/sweep/test_identity_coverage.py.)"""
    ids = expand(parse_campaign(loop())).run_ids
    assert hashlib.sha256(" ".join(ids).encode()).hexdigest()[:16] == "c496806990148dcd"
    assert expand(parse_campaign(loop(", up: predecessor"))).run_ids == ids


def test_the_fresh_up_branch_is_the_plain_runs_and_the_down_branch_is_unchanged():
    chained = expand(parse_campaign(loop()))
    fresh = expand(parse_campaign(loop(", up: fresh")))
    plain = expand(parse_campaign(loop().replace("chain: {axis: alpha_minus_B}\n", "")))
    by_branch = {
        b: [(r.run_id, r.start) for r in fresh if r.coords["branch"] == b] for b in ("up", "down")
    }
    assert all(start is None for _, start in by_branch["up"])
    assert {rid for rid, _ in by_branch["up"]} == set(plain.run_ids)
    assert [r.run_id for r in chained if r.coords["branch"] == "down"] == [
        rid for rid, _ in by_branch["down"]
    ]
    # the down branch's first run (alpha - B = 0.8) is the up branch's top run: one run id,
    # and the down branch's second run starts from the up branch's position of it
    top = {r.seed: r.run_id for r in fresh if r.coords == {"branch": "up", "alpha_minus_B": 0.8}}
    first_down = {
        r.seed: r.run_id for r in fresh if r.coords == {"branch": "down", "alpha_minus_B": 0.8}
    }
    assert top == first_down
    for i, r in enumerate(fresh):
        if r.coords == {"branch": "down", "alpha_minus_B": 0.4}:
            p = fresh.chain_parents[i]
            assert p is not None
            assert fresh.run(p).coords == {"branch": "up", "alpha_minus_B": 0.8}
            assert r.start is not None
            assert r.start["run"] == top[r.seed]
    assert len(set(fresh.run_ids)) == len(fresh) - 2  # two seeds


def test_a_wrong_start_is_reported_at_its_line():
    with pytest.raises(CampaignError) as err:
        parse_campaign(loop(", up: sideways"), source="loop.yaml")
    assert "loop.yaml:7: chain.up" in str(err.value)
    assert "predecessor or fresh" in str(err.value)


def test_one_campaign_gives_the_loop_width(tmp_path):
    """Run for real (32^2, t/tau = 20): 12 grid positions, 10 runs (the shared top run once),
    every position filled; the up branch's files begin from the texture; the loop width is
    the up branch's jump minus the down branch's, with the interval of the two."""
    path = tmp_path / "loop.yaml"
    path.write_text(
        loop(", up: fresh", t_final=20)
        + "fits: [{transition: {axis: alpha_minus_B, min_jump: 0.5}}]\n"
    )
    results = tmp_path / "results"
    r = CliRunner().invoke(app, ["run", str(path), "--results", str(results)])
    assert r.exit_code == 0, r.output
    root = results / "loop"
    assert len(list((root / "runs").glob("*.nc"))) == 10
    phase = xr.open_dataset(root / "phase.nc")
    assert phase.attrs["chain_up"] == "fresh"
    assert (phase.status.values == 1).all()
    for rid in phase.run_id.sel(branch="up").values.ravel():
        with xr.open_dataset(root / "runs" / f"{rid}.nc") as run:
            assert run.attrs["initial_from"] == ""
    top = phase.sel(alpha_minus_B=0.8)
    assert (top.run_id.sel(branch="up") == top.run_id.sel(branch="down")).all()
    fits = xr.open_dataset(root / "fits.nc")
    up, down = (fits.sel(branch=b) for b in ("up", "down"))
    width = float(fits.transition_loop_width)
    assert width == pytest.approx(float(up.transition_location - down.transition_location))
    lo, hi = float(fits.transition_loop_width_lower), float(fits.transition_loop_width_upper)
    assert lo == pytest.approx(float(up.transition_lower - down.transition_upper))
    assert hi == pytest.approx(float(up.transition_upper - down.transition_lower))
    assert lo <= width <= hi
