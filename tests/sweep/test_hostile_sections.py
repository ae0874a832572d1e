"""Every section attacked the same way: each value of a valid campaign that uses every
section (four of them: plain with a protocol, store, fits, figures, limits and verify; adaptive
with refine and precision; a child with initial.from; a chain) is replaced in turn by hostile
values of every type. Validation refuses each with the file:line of the problem (a
:class:`CampaignError`) or accepts it, never an internal error; and the cases that used to fail
at run time or with a traceback are refused with their line."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.spec import parse_campaign

BASES = {
    "plain": """
name: t
description: d
parameters: {noise_modes: 8, B: 0.5}
protocol:
  alpha_minus_B: {pulse: {base: 1.0, start: 1, duration: 0.5}}
  eps: {sine: {amplitude: 0.01, period: 3}}
numerics: {resolution: 32, t_final: 2, save_every: 0.5, snapshot_times: [1]}
sweep:
  axes:
    alpha_minus_B_level: [0.05, 0.5]
    K: {logspace: [-5, -4, 2]}
    chi: {linspace: [1, 2, 2]}
  zip: [[K, chi]]
seeds: {count: 2, start: 3}
store: {snapshot_dtype: float32, snapshot_fields: [q1, q2, A]}
fits: [transition, {scaling: {select: {alpha_minus_B_level: 0.05}}}]
figures: []
execution: {workers: 2, threads_per_worker: 1}
limits: {max_runs: 1000, run_memory: 4GB}
verify: {variants: [{resolution: x2}, {tolerance: /10}], seeds: 1}
""",
    "adaptive": """
name: t
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2, save_every: 0.5}
sweep: {axes: {alpha_minus_B: [0.1, 0.2, 0.3]}}
seeds: 2
refine: {axis: alpha_minus_B, observable: sigma2_S, rounds: 2, patterned_above: 0.01,
         min_spacing: 0.01}
precision: {observable: sigma2_S, width: 0.1}
""",
    "initial": """
name: kid
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2, save_every: 0.5}
sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}
seeds: 2
initial: {from: {campaign: par.yaml, seed: same, time: end}}
""",
    "chain": """
name: ch
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2, save_every: 0.5}
sweep: {axes: {alpha_minus_B: [0.1, 0.2, 0.3]}}
seeds: 1
chain: {axis: alpha_minus_B, branches: [up, down]}
""",
}
PARENT = (
    "name: par\nparameters: {noise_modes: 8}\n"
    "numerics: {resolution: 32, t_final: 2, save_every: 0.5, snapshot_times: [1]}\n"
    "sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}\nseeds: 2\n"
)
#: a value of every type (the default run); -m slow adds the rest
HOSTILE: list[Any] = [None, "x", [1, 2], {"a": 1}, float("nan"), -1e308, ":x: [bold]y[/]"]
MORE: list[Any] = [
    True,
    0,
    -1,
    10**30,
    2**63,
    float("inf"),
    "",
    [],
    [[1]],
    {},
    {"a": {"b": [1]}},
    0.5,
    "1e-5",
    [None],
    [{}],
    "auto",
    -0.0,
    1e-320,
    "line\nnext",
    {1: 2},
    [1e308, -1e308],
    {"linspace": [-1e308, 1e308, 3]},
    {"logspace": [0, 400, 2]},
    "x2",
    "/0",
    "x1e400",
]


def _paths(node: Any, path: tuple = ()) -> list[tuple]:
    out = [path] if path else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, (*path, i))
    return out


def _attack(folder: Path, values: list[Any]) -> list[tuple]:
    (folder / "par.yaml").write_text(PARENT)
    source = str(folder / "x.yaml")
    bad = []
    for name, text in BASES.items():
        base = yaml.safe_load(text)
        parse_campaign(text, source)  # each base is valid
        for path in _paths(base):
            for value in values:
                doc = copy.deepcopy(base)
                target = doc
                for k in path[:-1]:
                    target = target[k]
                target[path[-1]] = value
                try:
                    parse_campaign(yaml.safe_dump(doc), source)
                except CampaignError as e:
                    if f"{source}:" not in str(e):
                        bad.append((name, path, value, "no line", str(e)))
                except Exception as e:  # noqa: BLE001 - what the test looks for
                    bad.append((name, path, value, type(e).__name__, str(e)))
    return bad


def test_every_value_of_every_section_replaced_by_a_hostile_one(tmp_path):
    assert _attack(tmp_path, HOSTILE) == []


@pytest.mark.slow
def test_every_value_of_every_section_replaced_by_every_hostile_value(tmp_path):
    assert _attack(tmp_path, MORE) == []


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        # a verify variant is bounded by the run memory as the grid is
        (
            "verify:\n  variants:\n    - tolerance: /10\n    - resolution: x1000000\n  seeds: 1\n",
            7,
            "verify.variants[1]: the variant resolution x1000000 runs at resolution 32000000",
        ),
        # an axis name of the wrong type: no "unhashable type"
        (
            "chain: {axis: [alpha_minus_B, K]}\n",
            4,
            "chain.axis: got ['alpha_minus_B', 'K']; allowed: the name of one swept axis",
        ),
        ("limits: {run_memory: .inf}\n", 4, "limits.run_memory"),
        (
            "verify: {variants: [{resolution: x1e300}], seeds: 1}\n",
            4,
            "verify.variants[0]",
        ),
        # a pulse or ramp whose end the sum cannot hold (rounded to its start, or past the
        # largest float): validated, then every run failed rebuilding its protocol
        (
            "protocol: {eps: {pulse: {base: 0.0, level: 0.1, start: 0.1, duration: 1.0e-300}}}\n",
            4,
            "protocol.eps.pulse.duration: got 1e-300; allowed: a duration that ends after its "
            "start (0.1) at a finite time (start + duration is 0.1)",
        ),
        (
            "protocol: {chi: {ramp: {from: 0, to: 1, start: 1.0e+308, duration: 1.0e+308}}}\n",
            4,
            "protocol.chi.ramp.duration: got 1e+308; allowed: a duration that ends after its "
            "start (1e+308) at a finite time (start + duration is inf)",
        ),
        # a ramp piece below the float spacing of its time: validated, then its run stalled
        # at t = 0.1 forever (each step of 1/8 of the piece left the time unchanged)
        (
            "protocol: {chi: {ramp: {from: 0, to: 0.4, start: 0.1, duration: 2.0e-17}}}\n",
            4,
            "protocol.chi.ramp: got 'a piece from t = 0.1 to t = 0.10000000000000002'; allowed: "
            "ramp pieces at least 8 times the spacing of floating-point times",
        ),
    ],
)
def test_what_failed_at_run_time_is_refused_with_its_line(tmp_path, text, line, words):
    path = tmp_path / "c.yaml"
    path.write_text(
        "name: c\nparameters: {noise_modes: 8}\nnumerics: {resolution: 32, t_final: 1}\n"
        + text
        + "sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}\nseeds: 1\n"
    )
    res = CliRunner().invoke(app, ["validate", str(path)])
    said = " ".join(res.output.split())
    assert res.exit_code == 2, said
    assert f"{path}:{line}: {words}" in said, said
    assert "internal error" not in said


@pytest.mark.parametrize(
    ("axis", "words"),
    [
        ("{linspace: [-1.0e308, 1.0e308, 3]}", "end points whose difference is a finite number"),
        ("{logspace: [0, 400, 2]}", "exponents from -300 to 300"),
    ],
)
def test_ranges_whose_values_overflow_are_refused(axis, words):
    with pytest.raises(CampaignError, match=words) as err:
        parse_campaign(f"name: r\nsweep: {{axes: {{eps: {axis}}}}}\nseeds: 1\n", "r.yaml")
    assert "r.yaml:2: sweep.axes.eps" in str(err.value)
