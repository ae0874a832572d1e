"""Hostile input is refused before anything is expanded or allocated (measured: CPU time and
an address-space limit in a subprocess), and no command answers a user or environment error
with a traceback (one message, exit 2; ``--debug`` shows the traceback)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import MAX_SAVES, Numerics
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.limits import run_memory_bytes
from nematic_solids.sweep.spec import parse_campaign


def _bomb(levels: int = 9, width: int = 9) -> str:
    lines = [f"a0: &a0 [{', '.join(['x'] * width)}]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels + 1)]
    return "\n".join([*lines, f"description: *a{levels}"]) + "\n"


#: name -> (campaign text, words the refusal must contain)
HOSTILE = {
    "seeds": ("seeds: 1000000000\n", "at most 1000000 seeds"),
    "seed_count": ("seeds: {count: 1000000000, start: 5}\n", "an integer from 1 to 1000000"),
    "alias_bomb": (_bomb(), "expands to more than 100000 values"),
    "recursive_alias": ("a: &a [*a]\n", "expands to more than"),
    "grid": (
        "sweep:\n  axes:\n    K: {linspace: [1e-5, 1e-3, 1000]}\n"
        "    eps: {linspace: [0, 0.1, 1000]}\nseeds: 10\n",
        "10000000 runs (1000 (K) x 1000 (eps) x 10 seeds); allowed: at most 1000000",
    ),
    "linspace_num": (
        "sweep: {axes: {K: {linspace: [1e-5, 1e-3, 1000000000]}}}\n",
        "at most 1000000 values",
    ),
    "resolution": ("numerics: {resolution: 100000}\nseeds: 1\n", "needs about 16 TiB"),
    "t_final": ("numerics: {t_final: 1.0e30}\nseeds: 1\n", "at most 1000000 saved times"),
    "steps": (
        "numerics: {t_final: 1.0e8, save_every: 1000, dt_max: 0.5}\nseeds: 1\n",
        "at most 1e+08 time steps",
    ),
    "workers": ("execution: {workers: 100000}\nseeds: 1\n", "execution.workers: got 100000"),
    "jobs": (
        "execution: {cluster: {kind: slurm, jobs: 10000000, cores: 1, memory: 1GB}}\nseeds: 1\n",
        "an integer from 0 to 100000",
    ),
    "empty": ("# nothing but a comment\n", "the campaign file is empty"),
    "fit_axis": (
        "sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}\nseeds: 1\n"
        "fits: [{transition: {axis: nonexistent}}]\n",
        "fits[0].transition.axis: got 'nonexistent'; allowed: a sweep axis",
    ),
    "fit_option": (
        "sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}\nseeds: 1\n"
        "fits: [{transition: {n_boot: -3}}]\n",
        "n_boot = -3",
    ),
    "figure_select": (
        "sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}\nseeds: 1\n"
        "figures: [{fig2: {select: {nope: 1}}}]\n",
        "got 'nope'",
    ),
    "figure_option": (
        "sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}\nseeds: 1\nfigures: [{fig2: {colour: red}}]\n",
        "unknown option 'colour'",
    ),
    "max_runs": (
        "sweep: {axes: {K: [1e-5, 2e-5, 3e-5]}}\nseeds: 2\nlimits: {max_runs: 5}\n",
        "6 runs (3 (K) x 2 seeds); allowed: at most 5",
    ),
    "run_memory": (
        "numerics: {resolution: 1024}\nseeds: 1\nlimits: {run_memory: 500MB}\n",
        "more than limits.run_memory allows",
    ),
}

#: Validates every hostile text in one process under a 1 GiB address-space limit; prints
#: {name: [refusal message, CPU seconds]} as JSON.
PROBE = """
import json, resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (2**30, 2**30))
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.spec import parse_campaign
# imported before the clock starts
import nematic_solids.sweep.analysis.registry
import nematic_solids.sweep.figures.registry
cases = json.load(sys.stdin)
out = {}
for name, text in cases.items():
    t0 = time.process_time()
    try:
        parse_campaign(text, name + ".yaml", default_name=name)
        message = "accepted"
    except CampaignError as e:
        message = str(e)
    out[name] = [message, time.process_time() - t0]
print(json.dumps(out))
"""


def test_hostile_campaigns_are_refused_fast_in_little_memory():
    proc = subprocess.run(
        [sys.executable, "-c", PROBE],
        capture_output=True,
        text=True,
        input=json.dumps({k: v[0] for k, v in HOSTILE.items()}),
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    for name, (_, words) in HOSTILE.items():
        message, cpu = result[name]
        assert words in " ".join(message.split()), (name, message)
        assert cpu < 2.0, (name, cpu)


def test_the_ceilings_are_configurable():
    text = "sweep: {axes: {K: [1e-5, 2e-5, 3e-5]}}\nseeds: 2\nlimits: {max_runs: 6}\n"
    assert parse_campaign(text, default_name="x").n_runs == 6
    big = "numerics: {resolution: 1024}\nseeds: 1\nlimits: {run_memory: 64GB}\n"
    assert parse_campaign(big, default_name="x").numerics["resolution"] == 1024
    with pytest.raises(CampaignError, match="limits.max_runs: got 0"):
        parse_campaign("limits: {max_runs: 0}\n", default_name="x")


def test_memory_estimate_grows_with_the_square_of_the_resolution():
    small, large = run_memory_bytes(256, "finite"), run_memory_bytes(512, "finite")
    assert (
        280e6 < small < 1e9
    )  # measured 372 MB at 256^2 (docstring of nematic_solids.sweep.limits)
    assert (large - run_memory_bytes(0)) == 4 * (small - run_memory_bytes(0))
    assert run_memory_bytes(256, "linear") < small


def test_numerics_bound_the_saved_times_and_steps():
    with pytest.raises(ParameterError, match="saved times"):
        Numerics(t_final=MAX_SAVES * 5.0 + 5, save_every=5.0)
    with pytest.raises(ParameterError, match="time steps"):
        Numerics(t_final=1e8, save_every=1e3, dt_max=0.5)
    with pytest.raises(ParameterError, match="time steps"):
        Numerics(t_final=1e7, save_every=1e3, adaptive=False, dt=0.01)
    Numerics(t_final=3e5, save_every=1.0)  # a long run is fine


# --------------------------------------------------------------------------- no tracebacks
def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def assert_message(result, code: int, *words: str) -> None:
    """Exit ``code`` through typer.Exit (no exception escaped: no traceback), with ``words``."""
    assert result.exit_code == code, result.output
    assert isinstance(result.exception, SystemExit | type(None)), repr(result.exception)
    out = " ".join(result.output.split())
    for w in words:
        assert w in out, out


FAST = [
    "--set",
    "resolution=32",
    "--set",
    "noise_modes=6",
    "--set",
    "t_final=1",
    "--set",
    "mechanics=linear",
    "--quiet",
]


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--seed", "-1"], ["'seed': -1", "between 0 and"]),
        (["--set", "resolution=100000"], ["resolution", "needs about", "TiB"]),
        (["--set", "t_final=1e30"], ["t_final", "at most 1000000 saved times"]),
    ],
)
def test_simulate_refuses_hostile_values_before_running(args, words):
    assert_message(invoke("simulate", *args, "--quiet"), 2, *words)


def test_simulate_checks_out_before_running(tmp_path):
    res = invoke("simulate", *FAST, "--out", tmp_path)
    assert_message(res, 2, "is a folder; give a file name")
    assert "t = " not in res.output  # nothing ran
    blocker = tmp_path / "file"
    blocker.write_text("")
    res = invoke("simulate", *FAST, "--out", blocker / "run.nc")
    assert_message(res, 2, "does not exist")


def test_commands_on_unusable_paths_give_one_message(tmp_path):
    campaign = tmp_path / "c.yaml"
    campaign.write_text("sweep: {axes: {K: [1e-5, 2e-5]}}\nseeds: 1\n")
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert_message(
        invoke("run", campaign, "--results", blocker), 2, "cannot create", "not a folder"
    )
    assert_message(
        invoke("status", campaign, "--results", blocker),
        2,
        "not a folder",
        "--debug shows the traceback",
    )
    assert_message(invoke("validate", tmp_path), 2, "cannot read the file")
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"\xff\xfe not text")
    assert_message(invoke("validate", bad), 2, "not a UTF-8 text file")
    odd = tmp_path / "[red]x"  # a path that looks like console markup is printed as it is
    odd.write_text("")
    assert_message(invoke("status", campaign, "--results", odd), 2, "[red]x", "not a folder")
    # --debug lets the exception through (CliRunner keeps it; the program prints it)
    res = invoke("--debug", "status", campaign, "--results", blocker)
    assert res.exit_code != 0
    assert isinstance(res.exception, OSError)


def test_validate_cli_refuses_a_hostile_file_with_exit_2(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(textwrap.dedent(_bomb()))
    assert_message(invoke("validate", path), 2, "expands to more than 100000 values")
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert_message(invoke("validate", empty), 2, "the campaign file is empty")
    assert Path(empty).exists()
