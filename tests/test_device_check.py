"""The device check (benchmarks/device_check.sh and .py): its verdict fails the exit status when
the agreement fails, its rows come in order of importance, and (slow) the ``--tiny`` CPU run that
CI makes passes with both mechanics and both precisions in its JSON."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "device_check.py"


def load():
    spec = importlib.util.spec_from_file_location("device_check", SCRIPT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_differences_are_relative_or_absolute_and_nan_is_never_agreement():
    dc = load()
    a, b = np.array([1.0, 2.0, np.nan]), np.array([1.001, 2.0, 5.0])
    assert dc.worst(a, b, absolute=False) == pytest.approx(1e-3)
    assert dc.worst(np.array([0.0]), np.array([1e-4]), absolute=True) == pytest.approx(1e-4)
    assert dc.worst(np.array([np.nan]), np.array([np.nan]), absolute=False) == float("inf")
    # a value near zero (sigma2_S of a uniform S: round-off) is compared by its absolute change
    assert dc.worst(np.array([1e-33]), np.array([1e-18]), absolute=False) == pytest.approx(1e-9)


def test_the_rows_run_batch_8_at_every_size_first():
    rows = load().timing_rows([128, 256, 512], [1, 8, 50])
    assert len(rows) == 36
    assert {(n, b) for _, n, b, _ in rows[:12]} == {(128, 8), (256, 8), (512, 8)}
    assert {b for _, _, b, _ in rows[12:24]} == {50}


@pytest.mark.parametrize("ok", [True, False])
def test_a_failed_agreement_is_a_failed_exit_status(ok, tmp_path, monkeypatch):
    pytest.importorskip("jax", reason="the accelerated backend needs JAX")
    dc = load()
    row = {"mechanics": "linear", "resolution": 32, "ok": ok, "checks": {}}
    monkeypatch.setattr(dc, "agreement", lambda *args: [row])
    monkeypatch.setattr(dc, "timing", lambda *args: [])
    out = tmp_path / "check.json"
    assert dc.main(["--tiny", "--out", str(out)]) == (0 if ok else 1)
    assert json.loads(out.read_text())["passed"] is ok


@pytest.mark.slow  # (minutes: both mechanics compile in both precisions, and the reference runs)
def test_the_tiny_device_check_passes_on_the_cpu(tmp_path):
    pytest.importorskip("jax", reason="the accelerated backend needs JAX")
    out = tmp_path / "check.json"
    env = {**os.environ, "PYTHON": sys.executable}
    proc = subprocess.run(
        ["bash", str(ROOT / "benchmarks" / "device_check.sh"), "--tiny", "--out", str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    record = json.loads(out.read_text())
    assert record["passed"] is True
    assert {a["mechanics"] for a in record["agreement"]} == {"linear", "finite"}
    done = [r for r in record["timing"] if "wall_s" in r]
    assert {(r["mechanics"], r["precision"]) for r in done} == {
        (m, p) for m in ("linear", "finite") for p in ("float64", "float32")
    }
    assert "PASSED: agreement check" in proc.stdout
