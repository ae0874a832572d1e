"""Campaign YAML: parsing, ranges, zip groups, seeds, overrides, and the bad-input matrix
(every mistake exits 2 through ``nematic validate`` naming the file, key path and value)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.spec import Overrides, load_campaign, parse_campaign
from nematic_solids.sweep.spec.yaml_input import parse_assignments

GOOD = """
name: good
description: a test campaign
parameters: {B: 0.5, chi: 10, noise_modes: 16}
numerics: {resolution: 64, t_final: 4}
sweep:
  axes:
    alpha_minus_B: {linspace: [0.1, 0.7, 7]}
    K: {logspace: [-5, -3, 3]}
    eps: [0.0, 0.1, 0.2]
  zip:
    - [K, eps]
seeds: {count: 4, start: 10}
store: {snapshot_times: [2], snapshot_fields: [q1, q2], snapshot_dtype: float32}
execution: {workers: 2}
"""


def write(tmp_path: Path, text: str, name: str = "c.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_good_campaign_parses(tmp_path):
    c = load_campaign(write(tmp_path, GOOD))
    assert c.name == "good"
    assert [d.name for d in c.dims] == ["alpha_minus_B", "K"]  # zip dim named by its first
    assert [a.name for a in c.dims[1].axes] == ["K", "eps"]
    # linspace values are normalised: 0.30000000000000004 -> 0.3
    assert c.dims[0].axes[0].values == (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
    assert c.dims[1].axes[0].values == (1e-5, 1e-4, 1e-3)
    assert c.seeds == (10, 11, 12, 13)
    assert c.shape == (7, 3)
    assert c.n_runs == 7 * 3 * 4
    assert c.numerics["snapshot_times"] == [2]
    assert c.store.snapshot_fields == ("q1", "q2")
    assert c.store.snapshot_dtype == "float32"
    assert c.execution.mode == "local"
    assert c.execution.workers == 2


def test_defaults_and_name_from_file(tmp_path):
    c = load_campaign(write(tmp_path, "parameters: {K: 1e-4}\n", "my-campaign.yaml"))
    assert c.name == "my-campaign"
    assert c.seeds == tuple(range(50))  # default: 50 seeds
    assert c.dims == ()
    assert c.n_runs == 50
    assert c.parameters["K"] == 1e-4  # YAML 1.1 would read "1e-4" as a string


def test_figures_empty_list_means_none_and_absent_means_default(tmp_path):
    """figures: [] draws no figure; no figures key (or null) keeps the default (every
    figure that applies: figures is None); validate says which."""
    base = (
        "parameters: {K: 1e-4}\nsweep: {axes: {alpha_minus_B: [0.1, 1.0]}}\nseeds: 1\n"
        "fits: [scaling]\n"
    )
    absent = load_campaign(write(tmp_path, base, "absent.yaml"))
    assert absent.figures is None
    assert load_campaign(write(tmp_path, base + "figures:\n", "null.yaml")).figures is None
    empty = load_campaign(write(tmp_path, base + "figures: []\n", "empty.yaml"))
    assert empty.figures == ()
    assert [p.name for p in empty.fits] == ["scaling"]  # the fits are unaffected
    listed = load_campaign(
        write(tmp_path, base + "figures: [fig3, {fig2: {seed: 1}}]\n", "listed.yaml")
    )
    assert listed.figures is not None
    assert [(p.name, dict(p.options)) for p in listed.figures] == [
        ("fig3", {}),
        ("fig2", {"seed": 1}),
    ]
    runner = CliRunner()
    out = runner.invoke(app, ["validate", str(tmp_path / "empty.yaml")]).output
    assert "fits: scaling; figures: none" in out
    out = runner.invoke(app, ["validate", str(tmp_path / "absent.yaml")]).output
    assert "fits: scaling; figures: every one that applies" in out


def test_seed_list_and_geomspace(tmp_path):
    c = parse_campaign(
        "name: g\nsweep: {axes: {K: {geomspace: [1.0e-5, 1.0e-3, 3]}}}\nseeds: [3, 1, 7]"
    )
    assert c.seeds == (3, 1, 7)
    np.testing.assert_allclose(c.dims[0].axes[0].values, [1e-5, 1e-4, 1e-3])


def test_numerics_axis_and_int_values():
    c = parse_campaign(
        "name: n\n"
        "sweep: {axes: {resolution: [32, 64], mechanics: [linear, finite]}}\n"
        "seeds: 1\nparameters: {noise_modes: 8}"
    )
    assert c.dims[0].axes[0].values == (32, 64)
    assert all(isinstance(v, int) for v in c.dims[0].axes[0].values)
    assert c.dims[1].axes[0].values == ("linear", "finite")


def test_overrides_apply_before_validation(tmp_path):
    path = write(tmp_path, GOOD)
    c = load_campaign(
        path, Overrides(settings={"resolution": 64, "S0": 0.2}, seeds=2, name="reduced", workers=1)
    )
    assert c.numerics["resolution"] == 64
    assert c.parameters["S0"] == 0.2
    assert c.seeds == (0, 1)
    assert c.name == "reduced"
    assert c.execution.workers == 1
    assert any("--set resolution=64" in o for o in c.overrides)
    with pytest.raises(CampaignError) as e:
        load_campaign(path, Overrides(settings={"resolution": 33}))
    assert "--set resolution=33" in str(e.value)
    with pytest.raises(CampaignError) as e:
        load_campaign(path, Overrides(settings={"resolutoin": 64}))
    assert "did you mean 'resolution'" in str(e.value)
    s = load_campaign(path, Overrides(scheduler="tcp://127.0.0.1:8786"))
    assert s.execution.mode == "scheduler"
    assert s.execution.workers is None


def test_parse_assignments():
    assert parse_assignments(["K=1e-4", "resolution=64", "mechanics=linear"]) == {
        "K": 1e-4,
        "resolution": 64,
        "mechanics": "linear",
    }
    with pytest.raises(CampaignError):
        parse_assignments(["K"])


def test_jobqueue_cluster_section_builds_a_job_script():
    from nematic_solids.sweep.run.driver import make_cluster

    c = parse_campaign("""
        name: slurm-test
        execution:
          cluster: {kind: slurm, jobs: 3, cores: 2, memory: 4GB, queue: short,
                    walltime: "00:30:00", processes: 2}
        """)
    assert c.execution.mode == "cluster"
    assert c.execution.cluster is not None
    assert c.execution.cluster.jobs == 3
    cluster = make_cluster(c.execution)  # starts a scheduler, submits nothing
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    assert "#SBATCH -p short" in script
    assert "#SBATCH -t 00:30:00" in script
    assert "--nworkers 2" in script
    assert "--protocol tls://" in script or "tls://" in script  # TLS by default
    assert "--tls-ca-file" in script


# ----------------------------------------------------------------------------- bad input
BASE = "numerics: {resolution: 64, t_final: 4}\n"

#: (YAML text, substrings every one of which must appear in the message)
BAD = {
    "unknown top-level key": (
        "paramters: {K: 1.0e-4}\n",
        ["paramters", "did you mean 'parameters'"],
    ),
    "unknown parameter": ("parameters: {chii: 1}\n", ["parameters.chii", "did you mean 'chi'"]),
    "parameter in numerics": (
        "numerics: {K: 1.0e-4}\n",
        ["numerics.K", "move it under 'parameters:'"],
    ),
    "wrong type": ("parameters: {K: abc}\n", ["parameters.K", "'abc'", "real number"]),
    "impossible value": ("parameters: {K: -1}\n", ["parameters.K", "-1", ">= 0"]),
    "resolution below the initial noise": (
        "parameters: {noise_modes: 40}\n",
        ["numerics.resolution", "noise_modes"],
    ),
    "odd resolution": (
        "numerics: {resolution: 33, t_final: 4}\n",
        ["numerics.resolution", "33", "even"],
    ),
    "unequal zip lengths": (
        "sweep: {axes: {K: [1.0e-4, 1.0e-3], eps: [0, 0.1, 0.2]}, zip: [[K, eps]]}\n",
        ["sweep.zip[0]", "K has 2", "eps has 3", "equal length"],
    ),
    "zip of unknown axis": (
        "sweep: {axes: {K: [1.0e-4, 1.0e-3]}, zip: [[K, chi]]}\n",
        ["sweep.zip[0][1]", "'chi'"],
    ),
    "empty axis": ("sweep: {axes: {chi: []}}\n", ["sweep.axes.chi", "non-empty"]),
    "unknown axis": (
        "sweep: {axes: {alpha_minus_b: [0.1]}}\n",
        ["sweep.axes.alpha_minus_b", "did you mean 'alpha_minus_B'"],
    ),
    "scalar axis": ("sweep: {axes: {chi: 5}}\n", ["sweep.axes.chi", "got 5", "a list"]),
    "bad linspace": (
        "sweep: {axes: {chi: {linspace: [0, 10, 0]}}}\n",
        ["sweep.axes.chi.linspace.num", "got 0"],
    ),
    "unknown range kind": (
        "sweep: {axes: {chi: {linspase: [0, 10, 3]}}}\n",
        ["sweep.axes.chi.linspase", "did you mean 'linspace'"],
    ),
    "duplicate axis values": ("sweep: {axes: {chi: [1, 2, 1]}}\n", ["sweep.axes.chi", "distinct"]),
    "swept and fixed": (
        "parameters: {K: 1.0e-4}\nsweep: {axes: {K: [1.0e-4, 1.0e-3]}}\n",
        ["sweep.axes.K", "both swept and set"],
    ),
    "alpha twice": (
        "parameters: {alpha: 1, alpha_minus_B: 0.5}\n",
        ["parameters.alpha_minus_B", "not both"],
    ),
    "impossible value at a grid point": (
        "sweep: {axes: {eps: [0, 0.7]}}\n",
        ["sweep.axes.eps", "0.7", "eps=0.7"],
    ),
    "name escapes results/": ("name: ../../etc\n", ["name", "'../../etc'"]),
    "absolute name": ("name: /tmp/x\n", ["name", "'/tmp/x'"]),
    "zero seeds": ("seeds: 0\n", ["seeds", "got 0"]),
    "duplicate seeds": ("seeds: [1, 2, 1]\n", ["seeds[2]", "distinct"]),
    "negative seed": ("seeds: [1, -2]\n", ["seeds[1]", "-2"]),
    "workers not an integer": ("execution: {workers: many}\n", ["execution.workers", "'many'"]),
    "scheduler without scheme": (
        "execution: {scheduler: 'localhost:8786'}\n",
        ["execution.scheduler", "'localhost:8786'", "tcp://"],
    ),
    "unknown cluster kind": (
        "execution: {cluster: {kind: slurmm}}\n",
        ["execution.cluster.kind", "did you mean 'slurm'"],
    ),
    "unknown cluster option": (
        "execution: {cluster: {kind: slurm, queu: short}}\n",
        ["execution.cluster.queu", "did you mean 'queue'"],
    ),
    "scheduler and cluster": (
        "execution: {scheduler: 'tcp://h:1', cluster: {kind: pbs}}\n",
        ["execution.cluster", "not both"],
    ),
    "unknown snapshot field": (
        "store: {snapshot_fields: [q1, q3]}\n",
        ["store.snapshot_fields[1]", "'q3'"],
    ),
    "snapshot after t_final": ("store: {snapshot_times: [1, 10]}\n", ["snapshot_times", "t_final"]),
    "not YAML": ("parameters: {K: [1, 2\n", ["not valid YAML"]),
    "not a mapping": ("- 1\n- 2\n", ["<document>", "a mapping"]),
    "duplicate key": (
        "parameters: {K: 1.0e-4}\nparameters: {chi: 1}\n",
        ["parameters", "duplicate key"],
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_campaign_exits_2_naming_the_key(tmp_path, case):
    text, expected = BAD[case]
    prefix = "" if text.startswith("-") or "numerics:" in text else BASE
    path = write(tmp_path, prefix + text, "bad.yaml")
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    message = " ".join(result.output.split())
    assert "bad.yaml" in message
    for part in expected:
        assert part in message, f"{part!r} not in {message!r}"


def test_line_numbers_point_at_the_mistake(tmp_path):
    path = write(tmp_path, "name: x\nnumerics:\n  resolution: 32\n  t_final: -4\n", "l.yaml")
    with pytest.raises(CampaignError) as e:
        load_campaign(path)
    assert f"{path}:4: numerics.t_final" in str(e.value)


def test_all_problems_reported_at_once(tmp_path):
    path = write(tmp_path, "paramters: {}\nseeds: 0\nexecution: {workers: 0}\n")
    with pytest.raises(CampaignError) as e:
        load_campaign(path)
    assert len(e.value.problems) == 3


def test_missing_file_is_bad_input(tmp_path):
    result = CliRunner().invoke(app, ["validate", str(tmp_path / "nope.yaml")])
    assert result.exit_code == 2
    assert "cannot read" in result.output


def test_validate_prints_a_summary(tmp_path):
    result = CliRunner().invoke(app, ["validate", str(write(tmp_path, GOOD))])
    assert result.exit_code == 0, result.output
    assert "runs: 84" in result.output
    assert "K (zipped with K)" not in result.output
    assert "eps (zipped with K)" in result.output
