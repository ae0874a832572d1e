"""The recovery fit and the switch figure (nematic_solids.sweep.analysis.recovery,
nematic_solids.sweep.figures.switch): the memory is the Pearson correlation of two fields; each
run's values are read from its series and snapshots at the pulse's switch and restore times; a lower
level of activity lowers the pattern more; the figure is drawn."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from nematic_solids.sweep.analysis.recovery import memory
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.spec import parse_campaign

PULSES = """\
name: pulses
parameters: {noise_modes: 8}
protocol:
  alpha_minus_B: {pulse: {base: 1.0, start: 4}}
numerics: {resolution: 32, t_final: 14, save_every: 1}
sweep:
  axes:
    alpha_minus_B_level: [-0.3, 0.6]
    alpha_minus_B_duration: [2, 6]
seeds: 2
store: {snapshot_times: [4, 6, 10]}
execution: {workers: 2}
"""


def test_memory_is_the_correlation_of_two_fields(rng):
    a = rng.standard_normal((16, 16))
    assert memory(a, a) == pytest.approx(1.0)
    assert memory(a, -2 * a + 3) == pytest.approx(-1.0)
    assert abs(memory(a, rng.standard_normal((16, 16)))) < 0.25
    assert np.isnan(memory(a, np.ones((16, 16))))


def test_the_recovery_of_a_switched_pattern(tmp_path):
    path = tmp_path / "pulses.yaml"
    path.write_text(PULSES)
    result = CliRunner().invoke(app, ["run", str(path), "--results", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    root = tmp_path / "results" / "pulses"
    assert (root / "figures" / "switch.png").stat().st_size > 10_000
    fits = xr.open_dataset(root / "fits.nc")
    # one run by hand: its series and snapshots at the switch (4) and restore (4 + D) times
    spec = next(
        r for r in expand(parse_campaign(PULSES)) if r.coords["alpha_minus_B_duration"] == 6
    )
    with xr.open_dataset(root / "runs" / f"{spec.run_id}.nc") as run:
        s2 = run.sigma2_S
        S = np.hypot(run.q1, run.q2)
        want = {
            "sigma2_before": float(s2.sel(t=4.0)),
            "sigma2_restore": float(s2.sel(t=10.0)),
            "sigma2_end": float(s2.isel(t=-1)),
            "memory_restore": memory(
                S.sel(snapshot_time=4.0).values, S.sel(snapshot_time=10.0).values
            ),
            "memory_end": memory(S.sel(snapshot_time=4.0).values, S.isel(snapshot_time=-1).values),
        }
    got = fits.sel(
        alpha_minus_B_level=spec.coords["alpha_minus_B_level"],
        alpha_minus_B_duration=6.0,
        seed=spec.seed,
    )
    for name, value in want.items():
        assert float(got[f"recovery_{name}"]) == pytest.approx(value, rel=1e-6), name
    # activity held lower for longer lowers the pattern more (the run's physics)
    restore = fits.recovery_sigma2_restore.sel(alpha_minus_B_duration=6.0)
    before = fits.recovery_sigma2_before.sel(alpha_minus_B_duration=6.0)
    ratio = (restore / before).mean("seed")
    assert float(ratio.sel(alpha_minus_B_level=-0.3)) < float(ratio.sel(alpha_minus_B_level=0.6))
