"""`nematic simulate` through typer's CliRunner: output files, summary, exit codes."""

from __future__ import annotations

import xarray as xr
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app

runner = CliRunner()
FAST = [
    "--set",
    "resolution=32",
    "--set",
    "noise_modes=6",
    "--set",
    "t_final=4",
    "--set",
    "mechanics=linear",
    "--quiet",
]


def test_simulate_writes_netcdf_and_png(tmp_path):
    out, png = tmp_path / "run.nc", tmp_path / "run.png"
    res = runner.invoke(
        app, ["simulate", *FAST, "--seed", "3", "--out", str(out), "--png", str(png)]
    )
    assert res.exit_code == 0, res.output
    for word in ("sigma2_S", "cos2theta", "lambda", "wall time"):
        assert word in res.output
    ds = xr.open_dataset(out)
    assert ds.attrs["status"] == "ok"
    assert ds.attrs["seed"] == 3
    assert ds.attrs["param_K"] == 5e-5
    assert ds.attrs["num_resolution"] == 32
    assert ds["q1"].shape == (1, 32, 32)
    assert float(ds["t"][-1]) == 4.0
    ds.close()
    assert png.stat().st_size > 10_000
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_simulate_bad_input_exits_2_naming_the_parameter():
    for bad, name in [
        ("K=-1", "K"),
        ("resolution=33", "resolution"),
        ("resolutoin=64", "resolutoin"),
        ("t_final=0", "t_final"),
        ("mechanics=soft", "mechanics"),
    ]:
        res = runner.invoke(app, ["simulate", "--set", bad, "--quiet"])
        assert res.exit_code == 2, (bad, res.output)
        assert name in res.output
    res = runner.invoke(app, ["simulate", "--set", "resolutoin=64"])
    assert "did you mean 'resolution'" in res.output


def test_simulate_failed_run_exits_1_with_reason_and_time():
    """alpha - B = 3 with a weak quartic term drives (alpha - B) S past the well-posedness
    limit 1: the well-posedness monitor stops the run with its reason (no hang, no garbage)."""
    res = runner.invoke(
        app,
        [
            "simulate",
            *FAST,
            "--set",
            "alpha_minus_B=3",
            "--set",
            "C=0.5",
            "--set",
            "s=1",
            "--set",
            "t_final=50",
        ],
    )
    assert res.exit_code == 1, res.output
    assert "run failed at t =" in res.output
    assert "rate_problem_ill_posed" in res.output  # the reason that holds, checked every step
    assert "(alpha - B) S = 1." in res.output
