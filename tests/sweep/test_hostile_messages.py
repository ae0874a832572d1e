"""Messages say literally what the user wrote and nothing of what they should not: rich
markup and emoji codes in values print as typed; ``initial.from`` reads campaign files only,
from the campaign's folder unless ``outside: true``, and shows no content of another file; a
refused campaign leaves no results folder; a full disk is reported as a full disk."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from typer.testing import CliRunner

from nematic_solids.sweep import files
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import StorageError
from nematic_solids.sweep.files import atomic_to_netcdf, atomic_write_text, storage_cause
from nematic_solids.sweep.spec import load_campaign

SMALL = (
    "name: {name}\nparameters: {{noise_modes: 8}}\n"
    "numerics: {{resolution: 32, t_final: 1, save_every: 0.5}}\nseeds: 1\n"
)


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def said(result) -> str:
    return " ".join(result.output.split())


# --------------------------------------------------------------------------- literal values
def test_markup_and_emoji_codes_in_values_print_as_typed(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "name: m\nparameters: {noise_modes: 8}\n"
        'numerics: {resolution: 32, mechanics: "[bold]lin:x: :warning:"}\nseeds: 1\n'
    )
    res = invoke("validate", bad)
    assert res.exit_code == 2, res.output
    assert "got '[bold]lin:x: :warning:'" in said(res)
    assert "\u274c" not in res.output  # the emoji :x: would become
    assert "\u26a0" not in res.output  # and :warning:
    good = tmp_path / "good.yaml"
    good.write_text(SMALL.format(name="good") + 'execution: {scheduler: "tcp://[bold]h:x::1"}\n')
    res = invoke("validate", good, "--results", tmp_path / "r[red]:x:")
    assert res.exit_code == 0, res.output
    assert "dask scheduler tcp://[bold]h:x::1" in said(res)
    assert "r[red]:x:/good" in said(res)


def test_the_console_prints_emoji_codes_and_markup_in_values_literally():
    import io

    from rich.markup import escape

    from nematic_solids.sweep.cli.app import Console

    buf = io.StringIO()
    console = Console(file=buf, width=200)
    console.print(f"[bold]x[/]: {escape('[bold]v[/] :x:')}")
    assert buf.getvalue() == "x: [bold]v[/] :x:\n"


# --------------------------------------------------------------------------- initial.from
@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("../../../../../../etc/passwd", "is not a campaign file (a .yaml or .yml file)"),
        ("sub/passwd.yaml", "is not a campaign file (a YAML mapping"),
        ("../outside/parent.yaml", "lies outside this campaign's folder"),
        ("/etc/hostname.yaml", "lies outside this campaign's folder"),
        ("sub/link.yaml", "lies outside this campaign's folder"),  # a link that leads out
    ],
)
def test_initial_from_reads_campaign_files_of_the_folder_and_echoes_no_other_file(
    tmp_path, name, words
):
    here = tmp_path / "here"
    (here / "sub").mkdir(parents=True)
    secret = "root:x:0:0:SECRET-LINE"
    (here / "sub" / "passwd.yaml").write_text(secret + "\n")
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "parent.yaml").write_text(SMALL.format(name="parent"))
    (here / "sub" / "link.yaml").symlink_to(tmp_path / "outside" / "parent.yaml")
    child = here / "child.yaml"
    child.write_text(SMALL.format(name="child") + f"initial: {{from: {{campaign: {name}}}}}\n")
    res = invoke("validate", child)
    assert res.exit_code == 2, res.output
    assert f"{child}:5: initial.from.campaign" in said(res), said(res)
    assert words in said(res), said(res)
    assert "SECRET" not in res.output
    assert "root:x" not in res.output


def test_a_parent_outside_the_folder_is_read_when_stated(tmp_path):
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "parent.yaml").write_text(SMALL.format(name="parent"))
    (tmp_path / "here").mkdir()
    child = tmp_path / "here" / "child.yaml"
    child.write_text(
        SMALL.format(name="child")
        + "initial: {from: {campaign: ../outside/parent.yaml, outside: true}}\n"
    )
    res = invoke("validate", child)
    assert res.exit_code == 0, res.output
    child.write_text(
        SMALL.format(name="child")
        + "initial: {from: {campaign: ../outside/parent.yaml, outside: yes please}}\n"
    )
    res = invoke("validate", child)
    assert res.exit_code == 2, res.output
    assert "initial.from.outside: got 'yes please'" in said(res)


def test_a_parent_named_without_its_suffix_is_that_file_and_no_other(tmp_path):
    """``campaign: parent`` reads parent.yaml; ``campaign: parent.v2`` reads parent.v2.yaml,
    never parent.yaml (its suffix replaced: another campaign, accepted as the parent), and a
    name with a NUL in it is no campaign file."""
    (tmp_path / "parent.yaml").write_text(SMALL.format(name="parent"))
    (tmp_path / "parent.v2.yaml").write_text(SMALL.format(name="parent_v2"))
    child = tmp_path / "child.yaml"
    for name, parent in (("parent", "parent"), ("parent.v2", "parent_v2")):
        child.write_text(SMALL.format(name="child") + f"initial: {{from: {{campaign: {name}}}}}\n")
        initial = load_campaign(child).initial
        assert initial is not None
        assert (initial.parent.name, Path(initial.path).name) == (parent, f"{name}.yaml")
    child.write_text(SMALL.format(name="child") + 'initial: {from: {campaign: "parent.yaml\\0"}}\n')
    res = invoke("validate", child)
    assert res.exit_code == 2, res.output
    assert f"{child}:5: initial.from.campaign: parent.yaml" in said(res), said(res)
    assert "is not a campaign file" in said(res), said(res)


def test_a_parent_campaign_s_problems_are_shown_when_it_is_a_campaign(tmp_path):
    (tmp_path / "parent.yaml").write_text("name: parent\nseeds: -3\n")
    child = tmp_path / "child.yaml"
    child.write_text(SMALL.format(name="child") + "initial: {from: {campaign: parent.yaml}}\n")
    res = invoke("validate", child)
    assert res.exit_code == 2, res.output
    assert "the parent campaign" in said(res)
    assert "seeds" in said(res)


# --------------------------------------------------------------------------- no folder left
def test_a_campaign_refused_because_its_parent_is_not_done_leaves_no_folder(tmp_path):
    (tmp_path / "parent.yaml").write_text(SMALL.format(name="parent"))
    child = tmp_path / "child.yaml"
    child.write_text(SMALL.format(name="child") + "initial: {from: {campaign: parent.yaml}}\n")
    results = tmp_path / "results"
    res = invoke("run", child, "--results", results, "--quiet")
    assert res.exit_code == 2, res.output
    assert "are not done" in said(res)
    assert not (results / "child").exists()
    # a folder that was there before (runs of its own) is kept as it was
    (results / "child" / "runs").mkdir(parents=True)
    (results / "child" / "runs" / "keep.json").write_text("{}")
    res = invoke("run", child, "--results", results, "--quiet")
    assert res.exit_code == 2, res.output
    assert (results / "child" / "runs" / "keep.json").exists()


# --------------------------------------------------------------------------- a full disk
def test_permission_denied_from_a_library_on_a_full_disk_is_a_full_disk(tmp_path, monkeypatch):
    """netCDF's nc_create on a filesystem with no free block raises ``PermissionError``:
    the cause is read from the filesystem (a test write fails with ENOSPC)."""
    monkeypatch.setattr(
        files, "probe_write", lambda folder: OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    )
    cause = storage_cause(tmp_path / "r.nc", PermissionError(errno.EACCES, "Permission denied"))
    assert cause.startswith("the disk is full"), cause
    # a folder that really refuses the write stays "permission denied"
    monkeypatch.setattr(
        files, "probe_write", lambda folder: OSError(errno.EACCES, os.strerror(errno.EACCES))
    )
    cause = storage_cause(tmp_path / "r.nc", PermissionError(errno.EACCES, "Permission denied"))
    assert cause == "permission denied"


@pytest.fixture
def tiny_disk(tmp_path):
    """A 256 KiB tmpfs (root with mount rights), unmounted afterwards."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root")
    disk = tmp_path / "disk"
    disk.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(disk)],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield disk
    finally:
        subprocess.run(["umount", str(disk)], check=False)


@pytest.mark.parametrize("leave", [0, 1024, 8192, 40_000])
def test_a_full_disk_is_reported_as_a_full_disk(tiny_disk, leave):
    import numpy as np
    import xarray as xr

    vfs = os.statvfs(tiny_disk)
    with open(tiny_disk / "filler", "wb") as f, contextlib.suppress(OSError):
        f.write(b"\0" * max(0, vfs.f_bavail * vfs.f_frsize - leave))
    ds = xr.Dataset({"a": (("x",), np.zeros(20_000))})
    for write in (
        lambda: atomic_to_netcdf(ds, tiny_disk / "run.nc"),
        lambda: atomic_write_text(tiny_disk / "run.json", "x" * 60_000),
    ):
        with pytest.raises(StorageError) as err:
            write()
        assert "the disk is full" in str(err.value), str(err.value)
        assert "permission" not in str(err.value)
    assert sorted(p.name for p in tiny_disk.iterdir()) == ["filler"]  # no temporary left
