"""A collection of campaigns (sweep/spec/collection.py, sweep/cli/collection.py): the file's checks
with file, line and key path; every member's problems in one pass; the cost of the whole
before anything runs (`--dry-run` writes nothing); a real collection of two small campaigns
run in order, with its summary and index page, resumed with nothing to do; a refused member
does not stop the next one, an interrupt does; `status`, `stop` and the other commands."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import typer
from sweep_helpers import outside_references
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.cli.collection import run_collection
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.limits import MAX_COLLECTION_MEMBERS
from nematic_solids.sweep.lock import read_lock_holder
from nematic_solids.sweep.spec.collection import read_collection
from nematic_solids.sweep.spec.yaml_input import MAX_YAML_NODES
from nematic_solids.sweep.store import CampaignStore

ROOT = Path(__file__).resolve().parents[2]

SMALL = """\
name: {name}
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: 2.0, save_every: 1.0, mechanics: linear}}
sweep:
  axes:
    alpha_minus_B: [0.2, 0.8]
seeds: 1
execution: {{workers: 1}}
"""

COLLECTION = """\
name: both
description: two small campaigns
campaigns:
  - one.yaml
  - two.yaml
"""


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    (tmp_path / "one.yaml").write_text(SMALL.format(name="one"))
    (tmp_path / "two.yaml").write_text(SMALL.format(name="two"))
    (tmp_path / "both.yaml").write_text(COLLECTION)
    return tmp_path


def reads_of(module: Any, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The names of the files ``module`` reads with its ``read_text`` from now on."""
    read: list[str] = []
    real = module.read_text

    def counted(path):
        read.append(Path(path).name)
        return real(path)

    monkeypatch.setattr(module, "read_text", counted)
    return read


def problems(path: Path) -> list[str]:
    with pytest.raises(CampaignError) as e:
        read_collection(path)
    return [str(p) for p in e.value.problems]


def test_a_collection_file_is_read_and_a_campaign_file_is_not_one(folder):
    coll = read_collection(folder / "both.yaml")
    assert coll is not None
    assert coll.name == "both"
    assert coll.members == (folder / "one.yaml", folder / "two.yaml")
    assert read_collection(folder / "one.yaml") is None
    assert read_collection(folder / "missing.yaml") is None


def test_collection_mistakes_are_listed_with_line_and_key(folder):
    (folder / "bad.yaml").write_text(
        "name: a/b\ncolour: red\ncampaigns:\n  - one.yaml\n  - nothere.yaml\n  - one.yaml\n"
        "  - both.yaml\n  - 3\n  - notes.txt\n"
    )
    (folder / "notes.txt").write_text("")
    found = problems(folder / "bad.yaml")
    text = "\n".join(found)
    assert "bad.yaml:1" in text and "name" in text  # noqa: PT018
    assert "unknown key 'colour'" in text
    assert "campaigns[1]" in text and "no campaign file" in text  # noqa: PT018
    assert "listed twice" in text
    assert "a collection does not include collections" in text
    assert "campaigns[4]" in text and "got 3" in text  # noqa: PT018
    assert "ending in .yaml" in text
    (folder / "empty.yaml").write_text("campaigns: []\n")
    assert "a non-empty list" in problems(folder / "empty.yaml")[0]


@pytest.mark.parametrize("members", [MAX_COLLECTION_MEMBERS + 1, 90_000])
def test_a_collection_is_refused_by_its_member_count_before_any_member_is_read(
    folder, monkeypatch, members
):
    """A collection of more than MAX_COLLECTION_MEMBERS campaign files is refused at its
    ``campaigns:`` line by the count alone: no member is opened (90000 members were each
    checked, 19 s, before)."""
    import nematic_solids.sweep.spec.collection as collection

    (folder / "many.yaml").write_text("name: many\ncampaigns:\n" + "  - one.yaml\n" * members)
    read = reads_of(collection, monkeypatch)
    out = invoke("validate", folder / "many.yaml")
    assert out.exit_code == 2, out.output
    said = flat(out.output)
    assert (
        f"many.yaml:3: campaigns: {members} campaign files; allowed: at most "
        f"{MAX_COLLECTION_MEMBERS}" in said
    ), said
    assert "1 problem(s)" in said, said
    assert "one.yaml" not in read, read  # no member was read
    (folder / "many.yaml").write_text(
        "campaigns:\n" + "".join(f"  - m{i}.yaml\n" for i in range(MAX_COLLECTION_MEMBERS))
    )
    assert len(problems(folder / "many.yaml")) == MAX_COLLECTION_MEMBERS  # at the bound: checked


def test_a_collection_of_a_million_members_is_refused_by_its_size(folder):
    """A million members in 2 MB (a flow list of one-letter names) stop at the YAML's node
    bound while it is parsed, with the file and line, before anything else is read."""
    (folder / "million.yaml").write_text("campaigns: [" + "a," * 999_999 + "a]\n")
    out = invoke("validate", folder / "million.yaml")
    assert out.exit_code == 2, out.output
    said = flat(out.output)
    assert f"million.yaml:1: <document>: the file has more than {MAX_YAML_NODES} YAML" in said
    assert "internal error" not in said


def test_validate_reports_every_members_problems_and_shared_names(folder):
    (folder / "two.yaml").write_text(SMALL.format(name="two").replace("seeds: 1", "seeds: 0"))
    (folder / "one.yaml").write_text(SMALL.format(name="one").replace("32", "31"))
    out = invoke("validate", folder / "both.yaml")
    assert out.exit_code == 2
    assert "one.yaml" in out.output and "two.yaml" in out.output  # noqa: PT018
    (folder / "one.yaml").write_text(SMALL.format(name="same"))
    (folder / "two.yaml").write_text(SMALL.format(name="same"))
    out = invoke("validate", folder / "both.yaml")
    assert out.exit_code == 2
    assert "two members would share results/same/" in flat(out.output)
    out = invoke("validate", folder / "both.yaml", "--name", "x")
    assert out.exit_code == 2
    assert "keep their own names" in flat(out.output)


def test_dry_run_prints_the_cost_of_the_whole_and_writes_nothing(folder):
    results = folder / "results"
    out = invoke("run", folder / "both.yaml", "--results", results, "--dry-run")
    assert out.exit_code == 0, out.output
    text = flat(out.output)
    assert "collection both" in text
    assert "one: 2 planned, 0 done, 2 to do" in text
    assert "two: 2 planned, 0 done, 2 to do" in text
    assert "total now: 4 runs" in text
    assert not results.exists()
    out = invoke("validate", folder / "both.yaml", "--results", results, "--estimate")
    assert out.exit_code == 0
    assert "total now: 4 runs" in flat(out.output)


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_a_collection_runs_its_campaigns_in_order_and_resumes(folder):
    results = folder / "results"
    out = invoke("run", folder / "both.yaml", "--results", results, "--no-dashboard")
    assert out.exit_code == 0, out.output
    text = flat(out.output)
    assert text.index("== campaign one (1 of 2)") < text.index("== campaign two (2 of 2)")
    assert "one: done" in text and "two: done" in text  # noqa: PT018
    for name in ("one", "two"):
        assert (results / name / "phase.nc").is_file()
        assert (results / name / "report.html").is_file()
    index = (results / "both" / "index.html").read_text()
    assert '<a href="../one/report.html">' in index
    assert '<a href="../two/report.html">' in index
    # every page written works offline: it links its own folder's files only
    assert outside_references(index) == []
    for name in ("one", "two"):
        assert outside_references((results / name / "report.html").read_text()) == []
    again = invoke("run", folder / "both.yaml", "--results", results, "--no-dashboard")
    assert again.exit_code == 0, again.output
    assert "total now: 0 runs" in flat(again.output)
    status = invoke("status", folder / "both.yaml", "--results", results)
    assert status.exit_code == 0
    assert flat(status.output).count("2 done, 0 failed, 0 pending of 2") == 2
    js = json.loads(invoke("status", folder / "both.yaml", "--results", results, "--json").output)
    assert js["collection"] == "both"
    assert set(js["campaigns"]) == {"one", "two"}
    stop = invoke("stop", folder / "both.yaml", "--results", results)
    assert stop.exit_code == 1
    assert "no driver is running a campaign of collection both" in flat(stop.output)
    # the commands for one campaign say what to give them
    out = invoke("aggregate", folder / "both.yaml", "--results", results)
    assert out.exit_code == 2
    assert "is a collection of campaigns" in flat(out.output)


def test_a_refused_member_does_not_stop_the_next_one(folder):
    results = folder / "results"
    lock = CampaignStore(results, "one").lock()
    CampaignStore(results, "one").ensure()
    lock.acquire(command="another driver")
    try:
        out = invoke("run", folder / "both.yaml", "--results", results, "--no-dashboard")
    finally:
        lock.release()
    assert out.exit_code == 2, out.output
    text = flat(out.output)
    assert "one: refused or stopped" in text
    assert "two: done" in text
    assert (results / "two" / "phase.nc").is_file()


def test_an_interrupt_stops_the_collection(folder):
    coll = read_collection(folder / "both.yaml")
    assert coll is not None
    ran: list[Path] = []

    def fake_run(member: Path, **options: object) -> None:
        ran.append(member)
        raise typer.Exit(130)

    options = {
        "results": folder / "results",
        "set_": None,
        "seeds": None,
        "scheduler": None,
        "workers": None,
        "retry_failed": False,
        "dry_run": False,
        "detach": False,
        "prune": False,
        "quiet": True,
    }
    with pytest.raises(typer.Exit) as e:
        run_collection(coll, fake_run, options)
    assert e.value.exit_code == 130
    assert ran == [folder / "one.yaml"]


def test_the_paper_collection_is_valid():
    out = invoke("validate", ROOT / "campaigns" / "paper.yaml")
    assert out.exit_code == 0, out.output
    assert "valid: collection paper" in out.output


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_a_detached_collection_is_stopped_by_nematic_stop(folder):
    """`run COLLECTION --detach` runs the collection's driver in the background (its log in
    results/NAME/driver.log); `nematic stop COLLECTION` stops the member running, which ends
    the collection: the rest is not run, and the summary says so."""
    (folder / "one.yaml").write_text(
        SMALL.format(name="one")
        .replace("[0.2, 0.8]", "[0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]")
        .replace("t_final: 2.0", "t_final: 6.0")
    )
    results = folder / "results"
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "nematic_solids.sweep",
            "run",
            str(folder / "both.yaml"),
            "--results",
            str(results),
            "--no-figures",
            "--no-dashboard",
            "--detach",
        ],
        capture_output=True,
        text=True,
        timeout=240,
        env=dict(os.environ, COLUMNS="300"),
    )
    assert out.returncode == 0, out.stdout + out.stderr
    log = results / "both" / "driver.log"
    assert f"nematic stop {folder / 'both.yaml'}" in out.stdout
    lock = results / "one" / ".lock"
    holder = read_lock_holder(lock)
    assert holder is not None, log.read_text()
    pid = int(holder["pid"])
    deadline = time.monotonic() + 240
    while not list((results / "one" / "runs").glob("*.json")) and time.monotonic() < deadline:
        time.sleep(0.5)
    stop = invoke("stop", folder / "both.yaml", "--results", results)
    assert stop.exit_code == 0, stop.output
    assert "stopped the driver of one" in flat(stop.output)
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.2)
    text = flat(log.read_text())
    assert "one: interrupted" in text, text
    assert "two: not run" in text, text
    assert not (results / "two").exists()


def test_a_collection_is_refused_once_its_members_grid_points_pass_the_bound(folder, monkeypatch):
    """Members are checked one after the other and the collection is refused as soon as their
    grid points together pass MAX_COLLECTION_POINTS: the members after it are not read (the
    work of checking a collection is bounded, not only each campaign's)."""
    import nematic_solids.sweep.limits as limits
    import nematic_solids.sweep.spec as spec

    for name in ("three", "four"):
        (folder / f"{name}.yaml").write_text(SMALL.format(name=name))
    (folder / "all.yaml").write_text(
        "name: all\ncampaigns: [one.yaml, two.yaml, three.yaml, four.yaml]\n"
    )
    monkeypatch.setattr(limits, "MAX_COLLECTION_POINTS", 3)  # each member has 2 points
    read = reads_of(spec, monkeypatch)
    out = invoke("validate", folder / "all.yaml")
    assert out.exit_code == 2, out.output
    said = flat(out.output)
    assert "more than 3 grid points in all (4 up to two.yaml" in said, said
    assert read == ["one.yaml", "two.yaml"], read  # three.yaml and four.yaml were not read
    monkeypatch.setattr(limits, "MAX_COLLECTION_POINTS", 8)  # at the bound: accepted
    assert invoke("validate", folder / "all.yaml").exit_code == 0
