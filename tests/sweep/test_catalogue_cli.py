"""``nematic catalogue index|runs|campaigns`` on copies of the shipped results folders: the
counts, ranges across campaigns as a table and as CSV, and one-line errors for bad input."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from nematic_solids.sweep.catalogue import location
from nematic_solids.sweep.cli import app

SHIPPED = Path(__file__).resolve().parents[2] / "docs" / "results"


@pytest.fixture(autouse=True)
def no_env(monkeypatch):
    monkeypatch.delenv(location.ENV, raising=False)
    monkeypatch.delenv("NEMATIC_RESULTS", raising=False)


@pytest.fixture
def root(tmp_path):
    out = tmp_path / "results"
    for name in ("fig2", "fig2_precision"):
        shutil.copytree(SHIPPED / name, out / name)
    return out


def invoke(*args: object):
    return CliRunner().invoke(app, ["catalogue", *map(str, args)])


def test_index_then_campaigns_and_runs_across_campaigns(root):
    r = invoke("index", root)
    assert r.exit_code == 0, r.output
    assert "fig2: 110 run(s) from its phase.nc" in r.output
    assert "fig2_precision: 190 run(s) from its phase.nc" in r.output
    assert "indexed 300 run(s) of 2 campaign(s)" in r.output
    r = invoke("campaigns", root, "--format", "csv")
    camps = pd.read_csv(io.StringIO(r.output)).set_index("name")
    assert camps.loc["fig2", "runs"] == 110
    assert camps.loc["fig2_precision", "ok"] == 190
    r = invoke(
        "runs",
        root,
        "--where",
        "K=5e-5",
        "--where",
        "alpha_minus_B=0.35:0.45",
        "--where",
        "seed=0:1",
        "--format",
        "csv",
    )
    assert r.exit_code == 0, r.output
    runs = pd.read_csv(io.StringIO(r.output))
    assert len(runs) == 6
    assert set(runs["campaigns"]) == {"fig2,fig2_precision"}
    assert sorted(set(runs["alpha_minus_B"])) == [0.35, 0.4, 0.45]
    r = invoke(
        "runs",
        root,
        "--campaign",
        "fig2_precision",
        "--where",
        "seed=10:",
        "--columns",
        "run_id,seed,sigma2_S",
    )
    assert r.exit_code == 0, r.output
    assert "run_id" in r.output
    assert "sigma2_S" in r.output
    assert "80 run(s)" in r.output  # the seeds beyond fig2's, fig2_precision's alone


def test_csv_to_a_file(root, tmp_path):
    out = tmp_path / "k.csv"
    r = invoke("runs", root, "--where", "K=5e-5", "--format", "csv", "-o", out)
    assert r.exit_code == 0, r.output
    assert len(pd.read_csv(out)) == 300 - 110  # each shared run once


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("runs", "--where", "K"), "expected KEY=VALUE"),
        (("runs", "--where", "K=2:1"), "low end is above"),
        (("runs", "--format", "xml"), "allowed: table, csv"),
        (("nothing",), "unknown action"),
        (("runs", "--where", "bad.K=1"), "the space is one of"),
    ],
)
def test_bad_input_is_one_line(root, args, message):
    action, *rest = args
    r = invoke(action, root, *rest)
    assert r.exit_code == 2
    assert message in r.output
    assert "Traceback" not in r.output


def test_a_missing_root_and_a_network_filesystem(tmp_path, monkeypatch):
    r = invoke("runs", tmp_path / "none")
    assert r.exit_code == 2
    assert "no results root" in r.output
    monkeypatch.setattr(location, "mount_table", lambda: [("/", "ext4"), (str(tmp_path), "nfs4")])
    r = invoke("campaigns", tmp_path)
    assert r.exit_code == 2
    assert "network filesystem (nfs4)" in r.output
