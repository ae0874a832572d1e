"""The catalogue of runs on SQLite: schema and migrations, recording and reading runs, queries
by parameter ranges across campaigns, indexing results folders (the shipped docs/results/* and
a real campaign's run records), a corrupt catalogue rebuilt from the files, and the refusal of
SQLite on a network filesystem (the mount table faked through ``location.mount_table``)."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest
import xarray as xr

from nematic_solids.sweep.catalogue import (
    CatalogueError,
    RunRow,
    index_root,
    location,
    open_catalogue,
    parse_condition,
)
from nematic_solids.sweep.catalogue.database import head_revision

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "docs" / "results"


@pytest.fixture(autouse=True)
def no_env(monkeypatch):
    monkeypatch.delenv(location.ENV, raising=False)


def row(run_id: str, campaign: str, **kw) -> RunRow:
    kw.setdefault("status", "ok")
    return RunRow(run_id=run_id, campaign=campaign, **kw)


def test_a_new_catalogue_is_migrated_to_the_head_in_wal_mode(tmp_path):
    cat = open_catalogue(tmp_path)
    assert cat.state == "created"
    path = tmp_path / "catalogue.sqlite"
    with sqlite3.connect(path) as db:
        assert db.execute("select version_num from alembic_version").fetchall() == [
            (head_revision(),)
        ]
        assert db.execute("pragma journal_mode").fetchone() == ("wal",)
        tables = {r[0] for r in db.execute("select name from sqlite_master where type='table'")}
    assert {"runs", "campaigns", "campaign_runs", "lineage", "run_values", "meta"} <= tables
    cat.close()
    again = open_catalogue(tmp_path)
    assert again.state == "opened"
    again.close()


def test_no_column_is_named_after_a_model_parameter_or_observable():
    from nematic_solids.model.parameters import Numerics, Parameters
    from nematic_solids.sweep.catalogue import schema

    names = set(Parameters.names()) | set(Numerics.names()) - {"t_final"}
    names |= {"sigma2_S", "lambda", "alpha", "alpha_minus_B", "mean_S", "cos2theta"}
    columns = {c.name for table in schema.metadata.tables.values() for c in table.columns}
    assert not columns & names, columns & names


def test_runs_recorded_are_read_back_with_ranges_across_campaigns(tmp_path):
    cat = open_catalogue(tmp_path)
    rows = []
    for i, (a, k, res) in enumerate(
        [(0.4, 1e-5, 128), (0.6, 1e-5, 256), (0.65, 1e-5, 256), (0.6, 5e-5, 256), (0.9, 1e-5, 256)]
    ):
        rows.append(
            row(
                f"r{i}",
                "one" if i < 3 else "two",
                seed=i,
                parameters={"K": k, "mechanics_word": "finite"},
                numerics={"resolution": res, "t_final": 10.0},
                scalars={"sigma2_S": 1e-3 * i, "bad": float("nan")},
                coords={"alpha_minus_B": a},
                path=f"x/runs/r{i}.nc",
            )
        )
    assert cat.record(rows) == 5
    found = cat.runs(where={"K": 1e-5, "alpha_minus_B": (0.5, 0.7), "resolution": 256})
    assert sorted(found["run_id"]) == ["r1", "r2"]
    assert set(found["campaigns"]) == {"one"}
    # the command line's text, a word, a space prefix, and an open range
    conds = [
        parse_condition(t) for t in ("K=0.00001", "alpha_minus_B=0.5:", "numerics.resolution=256")
    ]
    assert sorted(cat.runs(where=conds)["run_id"]) == ["r1", "r2", "r4"]
    assert list(
        cat.runs(where={"mechanics_word": "finite", "sigma2_S": (3e-3, None)})["run_id"]
    ) == ["r3", "r4"]
    assert cat.runs(where={"parameters.alpha_minus_B": 0.6}).empty  # a swept value, not a parameter
    one = cat.runs(campaign="two")
    assert list(one["run_id"]) == ["r3", "r4"]
    assert set(one["origin"]) == {"made"}
    assert one.loc[0, "bad"] is None or one["bad"].isna().all()  # NaN stored as null
    camps = cat.campaigns().set_index("name")
    assert camps.loc["one", "runs"] == 3
    assert camps.loc["two", "ok"] == 2
    ds = cat.dataset(campaign="one")
    assert isinstance(ds, xr.Dataset)
    assert ds.sizes["run"] == 3
    cat.close()


def test_every_update_takes_a_new_seq_and_changes_returns_it(tmp_path):
    cat = open_catalogue(tmp_path)
    cat.record([row("a", "c"), row("b", "c")])
    seen = cat.last_seq()
    assert seen == 2
    assert cat.changes(seen).empty
    cat.record([row("a", "c", status="failed", reason="nan")])
    new = cat.changes(seen)
    assert list(new["run_id"]) == ["a"]
    assert list(new["status"]) == ["failed"]
    assert new["seq"].iloc[0] == seen + 1
    cat.record([row("a", "d", origin="reused")])  # a second campaign holds it
    one = cat.run("a")
    assert one is not None
    assert one["campaigns"] == [
        {"campaign": "c", "origin": "made", "coords": None},
        {"campaign": "d", "origin": "reused", "coords": None},
    ]
    cat.close()


def test_lineage_of_a_continued_run_and_of_a_chain(tmp_path):
    from nematic_solids.sweep.catalogue import row_from_record

    cat = open_catalogue(tmp_path)
    rec = {
        "run_id": "b",
        "status": "ok",
        "campaign": "c",
        "continued_from": "a",
        "initial_from": "c/p@end",
        "nc_bytes": 10,
        "numerics": {"t_final": 4.0},
        "trajectory": "T",
        "end_state": 4.0,
        "finished": "2026-01-01T00:00:10+00:00",
        "wall_time": 10.0,
    }
    r = row_from_record(rec, "c", "c/runs/b.nc")
    assert r.started == "2026-01-01T00:00:00+00:00"
    assert r.t_final == 4.0
    cat.record([r])
    assert cat.lineage("b") == [("p", "chain"), ("a", "continued")]
    assert cat.longest_finished(["T"]) == {"T": [(4.0, "b", "c/runs/b.nc", "c")]}
    assert cat.finished(["b", "zz"]) == {"b": {"path": "c/runs/b.nc", "campaign": "c"}}
    cat.close()


def test_the_shipped_results_folders_are_indexed_from_their_phase_files(tmp_path):
    root = tmp_path / "results"
    names = ["fig2", "fig2_precision", "figA1"]
    for name in names:
        shutil.copytree(SHIPPED / name, root / name)
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}
    cat = open_catalogue(root)  # new: indexed on open
    after = {
        p: p.stat().st_mtime_ns
        for p in root.rglob("*")
        if p.is_file() and not p.name.startswith("catalogue.sqlite")
    }
    assert after == before  # nothing written into the folders, nothing recomputed
    for name in names:
        with xr.open_dataset(root / name / "phase.nc") as ds:
            ran = int((ds["status"] > 0).sum())
            ok = int((ds["status"] == 1).sum())
            sample = ds.isel({d: 0 for d in ds["run_id"].dims})
            rid = str(sample["run_id"].values)
            s2 = float(sample["sigma2_S"].values)
        runs = cat.runs(campaign=name)
        assert len(runs) == ran
        assert int((runs["status"] == "ok").sum()) == ok
        got = runs.set_index("run_id").loc[rid]
        assert got["sigma2_S"] == pytest.approx(s2, rel=1e-12)
        assert got["source"] == "phase"
        assert got["path"] is None
    # fig2 and fig2_precision share their first seeds: one run, two campaigns
    shared = cat.runs(where={"K": 5e-5, "alpha_minus_B": 0.4, "seed": (0, 0)})
    both = shared[shared["campaigns"] == "fig2,fig2_precision"]
    assert len(both) == 1
    camps = cat.campaigns().set_index("name")
    assert camps.loc["fig2", "campaign_sha256"]
    cat.close()


def test_a_campaigns_run_records_are_indexed_with_their_files(small, tmp_path):
    root = tmp_path / "results"
    shutil.copytree(small.results, root, symlinks=True)
    (root / "catalogue.sqlite").unlink(missing_ok=True)
    cat = open_catalogue(root)
    runs = cat.runs(campaign="small")
    records = {p.stem: json.loads(p.read_text()) for p in (root / "small" / "runs").glob("*.json")}
    assert set(runs["run_id"]) == set(records)
    for _, r in runs.iterrows():
        rec = records[r["run_id"]]
        assert r["status"] == rec["status"]
        assert r["seed"] == rec["seed"]
        if rec.get("nc_bytes") is not None:
            assert r["path"] == f"small/runs/{r['run_id']}.nc"
            assert (root / r["path"]).exists()
            assert r["trajectory_id"] == rec["trajectory"]
        assert r["wall_time"] == pytest.approx(rec["wall_time"])
    cat.close()


def test_a_corrupt_catalogue_is_rebuilt_from_the_files_with_nothing_lost(small, tmp_path):
    root = tmp_path / "results"
    shutil.copytree(small.results, root, symlinks=True)
    shutil.copytree(SHIPPED / "fig2", root / "fig2")
    (root / "catalogue.sqlite").unlink(missing_ok=True)
    cat = open_catalogue(root)
    want = cat.runs().drop(columns=["seq"]).sort_values("run_id").reset_index(drop=True)
    cat.close()
    path = root / "catalogue.sqlite"
    data = bytearray(path.read_bytes())
    data[:100] = b"\x00garbage" * 12 + b"gar\x00"
    path.write_bytes(bytes(data))
    cat = open_catalogue(root)
    assert cat.state == "rebuilt"
    assert cat.moved_to is not None
    assert cat.moved_to.exists()
    got = cat.runs().drop(columns=["seq"]).sort_values("run_id").reset_index(drop=True)
    assert got.equals(want)
    cat.close()
    path.unlink()  # deleted: created again, indexed again
    for extra in ("-wal", "-shm", ".lock"):
        Path(f"{path}{extra}").unlink(missing_ok=True)
    cat = open_catalogue(root)
    assert cat.state == "created"
    assert (
        cat.runs().drop(columns=["seq"]).sort_values("run_id").reset_index(drop=True).equals(want)
    )
    cat.close()


@pytest.mark.parametrize("fstype", ["nfs4", "lustre", "fuse.sshfs", "cifs"])
def test_sqlite_on_a_network_filesystem_is_refused_with_what_to_do(tmp_path, monkeypatch, fstype):
    mounts = [("/", "ext4"), (str(tmp_path), fstype)]
    monkeypatch.setattr(location, "mount_table", lambda: mounts)
    with pytest.raises(CatalogueError) as e:
        open_catalogue(tmp_path)
    text = str(e.value)
    assert fstype in text
    assert "postgresql+psycopg://" in text
    assert location.ENV in text
    assert "\n" not in text
    assert not (tmp_path / "catalogue.sqlite").exists()
    # a local SQLite file elsewhere is taken
    local = tmp_path.parent / f"local-{fstype}"
    local.mkdir()
    monkeypatch.setattr(location, "mount_table", lambda: [("/", "ext4"), (str(tmp_path), fstype)])
    monkeypatch.setenv(location.ENV, str(local / "cat.sqlite"))
    cat = open_catalogue(tmp_path)
    assert cat.state == "created"
    assert (local / "cat.sqlite").exists()
    cat.close()


def test_the_mount_table_is_read_from_mountinfo(tmp_path, monkeypatch):
    info = tmp_path / "mountinfo"
    info.write_text(
        "22 1 8:1 / / rw,relatime shared:1 - ext4 /dev/sda1 rw\n"
        "40 22 0:50 / /mnt/my\\040data rw shared:3 - nfs4 srv:/x rw,vers=4.2\n"
    )
    monkeypatch.setattr(location, "MOUNTINFO", info)
    assert location.mount_table() == [("/", "ext4"), ("/mnt/my data", "nfs4")]
    assert location.network_filesystem(Path("/mnt/my data/results")) == "nfs4"
    assert location.network_filesystem(Path("/mnt/my")) is None
    assert location.filesystem_type(Path("/mnt/my data2")) == "ext4"


def test_a_catalogue_of_another_root_is_refused(tmp_path):
    url = f"sqlite:///{tmp_path / 'shared.sqlite'}"
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    open_catalogue(url, root=tmp_path / "a").close()
    with pytest.raises(CatalogueError, match="one catalogue per results root"):
        open_catalogue(url, root=tmp_path / "b")
    cat = open_catalogue(url)  # the root it recorded
    assert cat.root == (tmp_path / "a").resolve()
    cat.close()


def test_bad_urls_and_conditions_give_one_line_errors(tmp_path):
    with pytest.raises(CatalogueError, match="SQLite or PostgreSQL"):
        open_catalogue("mysql://x@y/z", root=tmp_path)
    for text in ("K", "K=", "=1", "K=2:1", "K=nan"):
        with pytest.raises(ValueError, match="K|expected"):
            parse_condition(text)


def test_index_root_counts_each_folder(tmp_path):
    root = tmp_path / "results"
    shutil.copytree(SHIPPED / "fig2", root / "fig2")
    (root / "not_results").mkdir()
    cat = open_catalogue(root, index=False)
    assert cat.runs().empty
    found = index_root(cat)
    assert found.runs == {"fig2": 110}
    assert found.sources == {"fig2": "phase.nc"}
    again = index_root(cat)  # idempotent
    assert again.total == 110
    assert len(cat.runs()) == 110
    cat.close()


def test_processes_opening_a_new_catalogue_at_once_migrate_it_one_at_a_time(tmp_path):
    """No opener mistakes another's half-made schema for a corrupt file."""
    import threading

    states: list[str] = []
    errors: list[BaseException] = []

    def opener() -> None:
        try:
            cat = open_catalogue(tmp_path)
            states.append(cat.state)
            cat.record([row(f"r{threading.get_ident()}", "c")])
            cat.close()
        except BaseException as e:  # noqa: BLE001 - handed to the test
            errors.append(e)

    threads = [threading.Thread(target=opener) for _ in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    assert not errors
    assert "rebuilt" not in states
    assert not list(tmp_path.glob("*.corrupt-*"))
    cat = open_catalogue(tmp_path)
    assert len(cat.runs()) == 4
    cat.close()


def test_a_read_only_catalogue_writes_nothing_beside_its_file(tmp_path):
    import sqlalchemy as sa

    cat = open_catalogue(tmp_path)
    cat.record([row("a", "c", parameters={"K": 1e-5})])
    cat.close()
    for extra in ("-wal", "-shm", ".lock"):
        Path(f"{tmp_path / 'catalogue.sqlite'}{extra}").unlink(missing_ok=True)
    before = {p.name: p.stat().st_mtime_ns for p in tmp_path.iterdir()}
    ro = open_catalogue(tmp_path, readonly=True)
    assert list(ro.runs(where={"K": 1e-5})["run_id"]) == ["a"]
    with pytest.raises(sa.exc.OperationalError):
        ro.record([row("b", "c")])
    ro.close()
    assert {p.name: p.stat().st_mtime_ns for p in tmp_path.iterdir()} == before
    with pytest.raises(CatalogueError, match="no catalogue"):
        open_catalogue(tmp_path / "elsewhere", readonly=True)


@pytest.mark.slow
def test_every_shipped_results_folder_is_indexed_whole(tmp_path):
    """Each of docs/results/*: as many runs as its phase.nc has cells that ran, each with its
    phase.nc status (protocol campaigns, chains and adaptive grids included)."""
    root = tmp_path / "results"
    shutil.copytree(SHIPPED, root)
    cat = open_catalogue(root, index=False)
    found = index_root(cat)
    assert not found.problems
    assert set(found.runs) == {p.name for p in SHIPPED.iterdir() if (p / "phase.nc").exists()}
    for name, n in found.runs.items():
        with xr.open_dataset(root / name / "phase.nc") as ds:
            ran = int((ds["status"] > 0).sum())
            failed = int((ds["status"] == 2).sum())
        assert n == ran, name
        runs = cat.runs(campaign=name)
        assert len(runs) == ran, name
        assert int((runs["status"] == "failed").sum()) == failed, name
    cat.close()
