"""What the campaign page draws beyond the seed means: each point's round (a plan of rounds,
``refine.json``) and its verification verdict (the shipped ``docs/results/fig2/verify.nc``),
in the API and, in headless Chromium against a real ``nematic serve``, on the phase diagram
(round labels, verdict glyphs); and a campaign of three swept axes, whose third axis is chosen
by a selector (the diagram shows that slice)."""

from __future__ import annotations

import json
import os
import shutil
import signal
from pathlib import Path

import pytest

pytest.importorskip("fastapi")
from test_service_deltas import AUTH, client_for

from nematic_solids.sweep.campaign_copy import save_campaign_copy
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.store import CampaignStore

ROOT = Path(__file__).resolve().parents[2]
FIG2_VERIFY = ROOT / "docs" / "results" / "fig2" / "verify.nc"
#: fig2's verify.nc: per sampled point (alpha_minus_B), its variants' verdicts
VERDICTS = {0.1: "converged", 0.4: "CHANGED", 0.45: "CHANGED", 1.0: "CHANGED"}
LINE = """\
name: line
parameters: {noise_modes: 4}
numerics: {resolution: 16, t_final: 0.5, mechanics: linear}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2, 0.4, 0.45, 1.0]
seeds: 1
"""
CUBE = """\
name: cube
parameters: {noise_modes: 4}
numerics: {resolution: 16, t_final: 0.5, mechanics: linear}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2]
    K: [1.0e-5, 1.0e-4]
    chi: [5.0, 10.0]
seeds: 1
"""


def make(root: Path, text: str, tmp: Path) -> tuple[CampaignStore, list]:
    path = tmp / "c.yaml"
    path.write_text(text)
    campaign = load_campaign(path)
    store = CampaignStore(root, campaign.name)
    store.ensure()
    save_campaign_copy(store, campaign)
    runs = list(expand(campaign))
    for run in runs:  # every run done, its value that of chi (or alpha - B)
        value = float(run.coords.get("chi", run.coords["alpha_minus_B"]))
        store.write_record(
            {
                "run_id": run.run_id,
                "status": "ok",
                "seed": run.seed,
                "wall_time": 1.0,
                "scalars": {"sigma2_S_final": value},
            },
            sync_dir=False,
        )
    return store, runs


def folders(tmp: Path) -> Path:
    root = tmp / "results"
    line, _ = make(root, LINE, tmp)
    shutil.copy(FIG2_VERIFY, line.root / "verify.nc")
    cube, runs = make(root, CUBE, tmp)
    # a plan of rounds as the refinement writes it: round 1 ran two more points
    later = [r for r in runs if r.coords["alpha_minus_B"] == 0.2 and r.coords["chi"] == 10.0]
    plan = {
        "finished": False,
        "rounds": [
            {
                "round": 0,
                "n_runs": len(runs) - 2,
                "runs": [
                    {"coords": r.point.coords, "seed": r.seed} for r in runs if r not in later
                ],
            },
            {
                "round": 1,
                "n_runs": 2,
                "runs": [{"coords": r.point.coords, "seed": r.seed} for r in later],
            },
        ],
    }
    (cube.root / "refine.json").write_text(json.dumps(plan))
    return root


def test_the_page_marks_rounds_and_verdicts(tmp_path):
    root = folders(tmp_path)
    client, ctx = client_for(root)
    line = client.get("/api/campaigns/line", headers=AUTH).json()
    marks = {p["coords"]["alpha_minus_B"]: p.get("verdict") for p in line["points"]}
    assert marks == {**VERDICTS, 0.2: None}
    first = next(p for p in line["points"] if p["coords"]["alpha_minus_B"] == 0.4)
    assert first["verdicts"] == ["resolution x2: converged", "tolerance /10: converged",
                                 "noise_modes=24: CHANGED"]  # fmt: skip
    cube = client.get("/api/campaigns/cube", headers=AUTH).json()
    assert cube["dims"] == ["alpha_minus_B", "K", "chi"]
    rounds = {
        (p["coords"]["alpha_minus_B"], p["coords"]["chi"]): p["round"] for p in cube["points"]
    }
    assert rounds == {(a, c): int(a == 0.2 and c == 10.0) for a in (0.1, 0.2) for c in (5.0, 10.0)}
    assert [r["round"] for r in cube["rounds"]["rounds"]] == [0, 1]
    ctx.catalogue.close()


@pytest.mark.browser
def test_the_diagram_draws_rounds_verdicts_and_a_selector_of_the_third_axis(tmp_path):
    from sweep_helpers import kill_group, wait_group_gone
    from test_report_browser import headless_chromium
    from test_service_browser import wait_js
    from test_service_process import start_service

    from nematic_solids.sweep.service.paths import ServicePaths

    root = folders(tmp_path)
    proc = start_service(root, tmp_path / "serve.log")
    driver_gen = headless_chromium("1300,1000", "127.0.0.1")
    chromium = next(driver_gen)
    try:
        paths = ServicePaths(root)
        info = paths.running()
        assert info is not None
        chromium.get(f"{info['url']}?token={paths.read_token()}")
        chromium.get(f"{info['url']}campaigns/line")
        glyphs = wait_js(
            chromium,
            "return [...document.querySelectorAll('#phase text.verdict')]"
            ".map(t => [t.dataset.verdict, t.firstChild.nodeValue])",
            lambda v: len(v) == 4,
            30,
            "four verdict glyphs",
        )
        assert sorted(v for v, _ in glyphs) == sorted(VERDICTS.values())
        assert {g for _, g in glyphs} == {"\u2713", "\u2717"}
        chromium.get(f"{info['url']}campaigns/cube")
        keys = (
            "return [...document.querySelectorAll('#phase circle.point')].map(c => c.dataset.key)"
        )
        shown = wait_js(chromium, keys, lambda v: len(v) == 4, 30, "one slice of the cube")
        assert all(k.endswith("chi=5") for k in shown)
        labels = chromium.execute_script(
            "return [...document.querySelectorAll('#phase text.round')].map(t => t.textContent)"
        )
        assert labels == []  # round 1's points are at chi = 10
        # chosen in one script: a redraw (an event) cannot come between finding and choosing
        chromium.execute_script(
            "const s = document.querySelector('#slice select[data-dim=chi]');"
            "s.value = '1'; s.dispatchEvent(new Event('change'));"
        )
        shown = wait_js(
            chromium,
            keys,
            lambda v: len(v) == 4 and all(k.endswith("chi=10") for k in v),
            30,
            "the other slice",
        )
        assert len(shown) == 4
        labels = chromium.execute_script(
            "return [...document.querySelectorAll('#phase text.round')].map(t => t.textContent)"
        )
        assert labels == ["r1", "r1"]
        severe = [e for e in chromium.get_log("browser") if e["level"] == "SEVERE"]
        assert not severe, severe
    finally:
        driver_gen.close()
        os.kill(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=120)
        finally:
            kill_group(proc)
    wait_group_gone(proc.pid)
