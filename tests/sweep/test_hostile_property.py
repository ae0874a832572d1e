"""Property: any campaign file, however mutated, is either refused with every problem at its
file:line (``load_campaign`` raises CampaignError; ``nematic validate`` exits 2 with no
traceback), or accepted, and then its dry run and a short run succeed.

Campaigns are drawn (Hypothesis) from a small valid one that every section can join, in
several forms per section (``store:`` with every key, ``chain:`` with its branches and
``up``, ``initial.from`` with a point, seed, time and ``outside``, ``protocol:`` with steps,
ramps, pulses and sines and a swept protocol number), then mutated: a value anywhere replaced
by a value of another type (numbers huge, NaN, inf, negative; strings with rich markup, emoji
codes and newlines; lists; mappings; deeply nested values; long lists), an unknown key added,
a key removed. The default run draws a bounded number of examples, derandomized (the same
ones on every machine) and runs at most a few accepted campaigns; ``-m slow`` draws many more
and runs every accepted one."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError, Problem
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.spec import load_campaign

BASE: dict[str, Any] = {
    "name": "prop",
    "description": "property test",
    "parameters": {"noise_modes": 8},
    "numerics": {"resolution": 32, "t_final": 0.5, "save_every": 0.25},
    "sweep": {"axes": {"alpha_minus_B": [0.1, 0.2]}},
    "seeds": 1,
    "execution": {"workers": 1},
    "limits": {"max_runs": 8},
}
#: sections that join the base (each form valid with it), then are mutated like the rest
EXTRA: dict[str, list[dict[str, Any]]] = {
    "store": [
        {"store": {"snapshot_dtype": "float32", "snapshot_fields": ["q1", "q2", "A"]}},
        {
            "store": {
                "snapshot_times": [0.25, 0.5],
                "snapshot_fields": ["q1", "q2", "A", "I1bar"],
                "snapshot_dtype": "float64",
                "checkpoint_every": "10 min",
                "end_state": True,
            }
        },
        {"store": {"checkpoint_every": 0.25, "end_state": False}},
    ],
    "fits": [{"fits": []}],
    "figures": [{"figures": []}],
    "protocol": [
        {"protocol": {"eps": {"sine": {"amplitude": 0.01, "period": 0.5}}}},
        {
            "protocol": {
                "eps": {"sine": {"mean": 0.0, "amplitude": 0.01, "period": 0.5, "start": 0.1}},
                "chi": [[0, 0.0], [0.25, 1.0]],
            }
        },
        {"protocol": {"chi": {"ramp": [[0, 0.0], [0.2, 1.0], [0.4, 0.5]]}}},
        {"protocol": {"chi": {"ramp": {"from": 0.0, "to": 1.0, "start": 0.1, "duration": 0.2}}}},
        {
            "protocol": {"chi": {"pulse": {"base": 0.0, "level": 1.0, "start": 0.1}}},
            "sweep": {"axes": {"alpha_minus_B": [0.1, 0.2], "chi_duration": [0.1, 0.2]}},
        },
        {
            "protocol": {"eps": {"sine": {"amplitude": 0.01, "period": 0.5}}},
            "sweep": {"axes": {"alpha_minus_B": [0.1, 0.2], "eps_period": [0.5, 1.0]}},
        },
    ],
    "chain": [
        {"chain": {"axis": "alpha_minus_B", "branches": ["up"]}},
        {"chain": {"axis": "alpha_minus_B", "branches": ["up", "down"], "up": "fresh"}},
        {"chain": {"axis": "alpha_minus_B", "up": "predecessor"}},
    ],
    "verify": [{"verify": {"variants": [{"tolerance": "/10"}], "seeds": 1}}],
    "refine": [
        {
            "refine": {
                "axis": "alpha_minus_B",
                "observable": "sigma2_S",
                "rounds": 1,
                "patterned_above": 0.01,
                "min_spacing": 0.01,
            }
        }
    ],
    "initial": [
        {"initial": {"from": {"campaign": "parent.yaml"}}},
        {
            "initial": {
                "from": {
                    "campaign": "parent.yaml",
                    "point": {"alpha_minus_B": 0.2},
                    "seed": 0,
                    "time": 0.25,
                    "outside": False,
                }
            }
        },
        {"initial": {"from": {"campaign": "parent", "seed": "same", "time": "end"}}},
    ],
}
PARENT = (
    "name: parent\nparameters: {noise_modes: 8}\n"
    "numerics: {resolution: 32, t_final: 0.5, save_every: 0.25, snapshot_times: [0.25]}\n"
    "sweep: {axes: {alpha_minus_B: [0.1, 0.2]}}\nseeds: 1\n"
)

MARKUP = st.sampled_from(
    ["[bold]", "[/]", ":x:", ":warning:", "\n", "'", '"', "{", "}", "*", "&", "%", "\\", "\t"]
)
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1, 2, 1e-320, 1e308, -1e308, 0.5, "auto", "x2", "/0", "x1e400"]),
    st.lists(st.one_of(MARKUP, st.characters(codec="utf-8")), max_size=6).map("".join),
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(st.text(min_size=1, max_size=8), inner, max_size=3),
    ),
    max_leaves=8,
)
deep = st.integers(30, 120).map(lambda n: json.loads("[" * n + "1" + "]" * n))
#: long lists: of numbers (a list of values past what any key takes), of one repeated value
huge = st.one_of(
    st.integers(1000, 20_000).map(lambda n: [i * 1e-4 for i in range(n)]),
    st.tuples(scalars, st.integers(1000, 20_000)).map(lambda vn: [vn[0]] * vn[1]),
)


def _paths(node: Any, path: tuple = ()) -> list[tuple]:
    out = [path]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, (*path, i))
    return out


@st.composite
def campaigns(draw: st.DrawFn) -> dict[str, Any]:
    doc = copy.deepcopy(BASE)
    for name in draw(st.lists(st.sampled_from(sorted(EXTRA)), max_size=2, unique=True)):
        doc.update(copy.deepcopy(draw(st.sampled_from(EXTRA[name]))))
    for _ in range(draw(st.integers(0, 3))):
        paths = [p for p in _paths(doc) if p]
        path = draw(st.sampled_from(paths))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        kind = draw(
            st.sampled_from(["nearby", "nearby", "replace", "unknown", "remove", "deep", "huge"])
        )
        old = parent[path[-1]]
        if kind == "nearby" and isinstance(old, bool | str | list | dict | None):
            continue  # (numbers only: another value of the same kind, often a valid one)
        if kind == "nearby" and isinstance(old, int):
            parent[path[-1]] = draw(st.integers(-1, max(2 * old + 2, 0)))
        elif kind == "nearby" and isinstance(old, float) and math.isfinite(old):
            parent[path[-1]] = draw(st.floats(-abs(old), 4 * abs(old) + 1))
        elif kind == "remove" and path != ("name",):
            del parent[path[-1]]
        elif kind == "unknown" and isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=10))] = draw(scalars)
        elif kind == "deep":
            parent[path[-1]] = draw(deep)
        elif kind == "huge":
            parent[path[-1]] = draw(huge)
        else:
            parent[path[-1]] = draw(values)
    return doc


#: grid points of an accepted campaign whose model objects are rebuilt as a worker does
REBUILT = 64
#: accepted campaigns run for real so far in this session (the default run does a few)
RUNS = {"done": 0}
LINE = re.compile(r"\.yaml:\d+: ")
#: where a problem of this campaign (or of its parent) is: its file and line
AT_LINE = re.compile(r".*(campaign|parent)\.yaml:\d+")


def _check(folder: Path, doc: dict[str, Any], max_runs: int) -> None:
    (folder / "parent.yaml").write_text(PARENT)
    path = folder / "campaign.yaml"
    try:
        text = yaml.safe_dump(doc, allow_unicode=True)
    except (yaml.YAMLError, ValueError):
        return  # not writable as YAML (e.g. a surrogate character): nothing to validate
    path.write_text(text, encoding="utf-8", errors="surrogateescape")
    problems: list[Problem] = []
    try:  # the reader itself: refused with every problem at its line, or a campaign
        campaign = load_campaign(path)
    except CampaignError as e:
        problems = list(e.problems)
    refused = bool(problems)
    for problem in problems:
        assert AT_LINE.fullmatch(problem.location), (text, [str(p) for p in problems])
    if not refused:  # a worker rebuilds each run's model objects from their dicts: the same
        for point in expand(campaign).points[:REBUILT]:
            for accepted in (point.parameters, point.numerics):
                rebuilt = type(accepted).from_dict(accepted.to_dict())
                assert rebuilt.to_dict() == accepted.to_dict(), (text, accepted)
    runner = CliRunner()
    res = runner.invoke(app, ["validate", str(path)])
    out = res.output
    assert "internal error" not in out, (text, out)
    assert "Traceback" not in out, (text, out)
    assert res.exit_code == (2 if refused else 0), (text, out, res.exception)
    if refused:
        assert LINE.search(out), (text, out)
        return
    results = folder / "results"
    res = runner.invoke(app, ["run", str(path), "--results", str(results), "--dry-run"])
    assert res.exit_code == 0, (text, res.output, res.exception)
    if RUNS["done"] >= max_runs:
        return
    RUNS["done"] += 1
    if "initial" in doc:  # its parent's runs first
        res = runner.invoke(app, ["run", str(folder / "parent.yaml"), "--results", str(results)])
        assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["run", str(path), "--results", str(results), "--quiet", "--no-figures"]
    )
    assert res.exit_code in (0, 1), (text, res.output, res.exception)
    assert "internal error" not in res.output, (text, res.output)
    for record in (results / str(doc.get("name", "campaign")) / "runs").glob("*.json"):
        data = json.loads(record.read_text())
        # a run may end physically (a failure of the model's), never by a crash
        assert data.get("reason") != "exception", (text, data)


COMMON = settings(
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    database=None,
)


#: campaigns the property found that failed once (each refused now)
FOUND = [
    # a pulse whose end rounds to its start: validated, then every run failed rebuilding it
    {
        **BASE,
        "protocol": {"chi": {"pulse": {"base": 0.0, "level": 1.0, "start": 0.1}}},
        "sweep": {"axes": {"alpha_minus_B": [0.1, 0.2], "chi_duration": [1e-300, 0.2]}},
    },
    # a ramp piece whose steps do not move the time on: its runs stalled at t = 0.1
    {
        **BASE,
        "protocol": {"chi": {"ramp": {"from": 0.0, "to": 0.4, "start": 0.1, "duration": 2e-17}}},
    },
    # a ramp whose end overflows
    {
        **BASE,
        "protocol": {"chi": {"ramp": {"from": 0.0, "to": 1.0, "start": 1e308, "duration": 1e308}}},
    },
]


def _found(test):
    for doc in FOUND:
        test = example(doc=doc)(test)
    return test


@settings(COMMON, max_examples=40)
@given(doc=campaigns())
@_found
def test_a_mutated_campaign_is_refused_with_its_line_or_runs(tmp_path_factory, doc):
    _check(tmp_path_factory.mktemp("prop"), doc, max_runs=1)


@pytest.mark.slow
@settings(COMMON, max_examples=150)
@given(doc=campaigns())
def test_many_mutated_campaigns_are_refused_with_their_line_or_run(tmp_path_factory, doc):
    _check(tmp_path_factory.mktemp("prop"), doc, max_runs=8)
