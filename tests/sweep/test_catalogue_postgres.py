"""The catalogue of runs on a real PostgreSQL server (``pytest -m postgres``; CI installs
Debian's postgresql): the test starts its own server with ``initdb`` and ``pg_ctl`` in a
temporary folder on a free port (as the ``postgres`` user when run as root, since initdb
refuses root), then checks what the SQLite tests check: migrations, recording and reading, ranges
across campaigns, the changes since a seq, indexing the shipped results folders, concurrent
openers, and runs arriving every 50 ms from the driver's recorder."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

from nematic_solids.sweep.catalogue import RunRow, location, open_catalogue
from nematic_solids.sweep.catalogue.database import head_revision

pytestmark = pytest.mark.postgres

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "docs" / "results"


def _bin_dir() -> Path | None:
    found = shutil.which("pg_ctl")
    if found:
        return Path(found).parent
    base = Path("/usr/lib/postgresql")
    versions = sorted(base.glob("*/bin/pg_ctl")) if base.is_dir() else []
    return versions[-1].parent if versions else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A PostgreSQL server of its own: yields its URL (database ``postgres``)."""
    bin_dir = _bin_dir()
    if bin_dir is None:
        pytest.skip("PostgreSQL's server is not installed (Debian: apt-get install postgresql)")
    pytest.importorskip("psycopg", reason="psycopg 3 is not installed (the postgres extra)")
    as_root = os.geteuid() == 0
    prefix: list[str] = []
    base = tmp_path_factory.mktemp("pg")
    if as_root:
        if shutil.which("runuser") is None:
            pytest.skip("running as root without runuser: initdb refuses root")
        try:
            import pwd

            pw = pwd.getpwnam("postgres")
        except KeyError:
            pytest.skip("running as root and there is no user postgres for initdb")
        os.chmod(base, 0o755)
        for parent in base.parents:  # the postgres user must reach its folder
            if parent == Path("/"):
                break
            with contextlib.suppress(OSError):
                os.chmod(parent, os.stat(parent).st_mode | 0o011)
        os.chown(base, pw.pw_uid, pw.pw_gid)
        prefix = ["runuser", "-u", "postgres", "--"]
    data, log = base / "data", base / "server.log"
    port = _free_port()
    subprocess.run(
        [
            *prefix,
            str(bin_dir / "initdb"),
            "-D",
            str(data),
            "-U",
            "postgres",
            "-A",
            "trust",
            "--no-sync",
        ],
        check=True,
        capture_output=True,
    )
    options = f"-p {port} -k {base} -c listen_addresses=127.0.0.1 -c fsync=off"
    subprocess.run(
        [
            *prefix,
            str(bin_dir / "pg_ctl"),
            "-D",
            str(data),
            "-l",
            str(log),
            "-o",
            options,
            "-w",
            "-t",
            "60",
            "start",
        ],
        check=True,
        capture_output=True,
    )
    try:
        yield f"postgresql+psycopg://postgres@127.0.0.1:{port}/postgres", port, prefix, bin_dir
    finally:
        subprocess.run(
            [*prefix, str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "immediate", "stop"],
            check=False,
            capture_output=True,
        )


@pytest.fixture
def url(server, request):
    """A fresh database on the server for each test."""
    import psycopg

    base_url, port, _, _ = server
    name = "t_" + request.node.name.lower().replace("[", "_").replace("]", "")[:50]
    with psycopg.connect(
        f"host=127.0.0.1 port={port} user=postgres dbname=postgres", autocommit=True
    ) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}"')
        conn.execute(f'CREATE DATABASE "{name}"')
    return base_url.rsplit("/", 1)[0] + f"/{name}"


@pytest.fixture(autouse=True)
def no_env(monkeypatch):
    monkeypatch.delenv(location.ENV, raising=False)


def test_migrated_recorded_and_queried_across_campaigns(url, tmp_path):
    import sqlalchemy as sa

    cat = open_catalogue(url, root=tmp_path)
    assert cat.state == "created"
    assert cat.db.dialect == "postgresql"
    with cat.engine.connect() as conn:
        version = conn.execute(sa.text("select version_num from alembic_version")).scalar()
    assert version == head_revision()
    rows = [
        RunRow(
            f"r{i}",
            "one" if i < 3 else "two",
            "ok",
            seed=i,
            parameters={"K": k, "word": "finite"},
            numerics={"resolution": res},
            scalars={"s": 1e-3 * i, "bad": float("nan")},
            coords={"alpha_minus_B": a},
            path=f"x/runs/r{i}.nc",
            trajectory_id="T",
            end_state=float(i),
            t_final=9.0,
        )
        for i, (a, k, res) in enumerate(
            [
                (0.4, 1e-5, 128),
                (0.6, 1e-5, 256),
                (0.65, 1e-5, 256),
                (0.6, 5e-5, 256),
                (0.9, 1e-5, 256),
            ]
        )
    ]
    cat.record(rows)
    found = cat.runs(where={"K": 1e-5, "alpha_minus_B": (0.5, 0.7), "resolution": 256})
    assert sorted(found["run_id"]) == ["r1", "r2"]
    assert list(cat.runs(where={"word": "finite", "s": (3e-3, None)})["run_id"]) == ["r3", "r4"]
    seen = cat.last_seq()
    cat.record([RunRow("r0", "one", "failed", reason="nan")])
    assert list(cat.changes(seen)["run_id"]) == ["r0"]
    assert cat.campaigns().set_index("name").loc["one", "failed"] == 1
    assert cat.longest_finished(["T"])["T"][0][:2] == (4.0, "r4")
    cat.close()
    again = open_catalogue(url)  # the root it recorded
    assert again.root == tmp_path.resolve()
    assert again.state == "opened"
    again.close()


def test_the_shipped_results_folders_are_indexed(url, tmp_path):
    root = tmp_path / "results"
    for name in ("fig2", "fig2_precision"):
        shutil.copytree(SHIPPED / name, root / name)
    cat = open_catalogue(url, root=root)
    camps = cat.campaigns().set_index("name")
    assert camps.loc["fig2", "runs"] == 110
    assert camps.loc["fig2_precision", "runs"] == 190
    shared = cat.runs(where={"K": 5e-5, "seed": (0, 9)})
    assert int((shared["campaigns"] == "fig2,fig2_precision").sum()) == 110
    cat.close()


def test_concurrent_openers_migrate_once(url, tmp_path):
    errors: list[BaseException] = []

    def opener(k: int) -> None:
        try:
            cat = open_catalogue(url, root=tmp_path)
            cat.record([RunRow(f"r{k}", "c", "ok")])
            cat.close()
        except BaseException as e:  # noqa: BLE001 - handed to the test
            errors.append(e)

    threads = [threading.Thread(target=opener, args=(k,)) for k in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    assert not errors
    cat = open_catalogue(url, root=tmp_path)
    assert sorted(cat.runs()["run_id"]) == ["r0", "r1", "r2", "r3"]
    assert sorted(cat.runs()["seq"]) == [1, 2, 3, 4]
    cat.close()


def test_the_recorder_writes_runs_arriving_every_50_ms(url, tmp_path):
    from nematic_solids.sweep.catalogue.recorder import Recorder
    from nematic_solids.sweep.store import CampaignStore

    store = CampaignStore(tmp_path, "stream")
    store.ensure()
    n = 60
    with Recorder(store, url=url) as recorder:
        for i in range(n):
            recorder.add(
                {
                    "run_id": f"run{i:03d}",
                    "status": "ok",
                    "seed": i,
                    "nc_bytes": 1,
                    "parameters": {"p": i},
                    "finished": "2026-12-07T12:00:00+00:00",
                }
            )
            time.sleep(0.05)
    assert recorder.problem is None
    cat = open_catalogue(url)
    runs = cat.runs(campaign="stream")
    assert sorted(runs["run_id"]) == [f"run{i:03d}" for i in range(n)]
    assert sorted(runs["seq"]) == list(range(1, n + 1))
    cat.close()


def test_concurrent_writers_keep_the_campaign_counts(url, tmp_path):
    """Two writers record the same runs in turn into different campaigns (one reuses the
    other's), their statuses changing: the counts kept by the writers equal a recount."""
    from nematic_solids.sweep.catalogue.query import campaign_counts, recount_campaigns

    errors: list[BaseException] = []

    def write(campaign: str, origin: str, offset: int) -> None:
        try:
            cat = open_catalogue(url, root=tmp_path)
            for k in range(15):
                cat.record(
                    RunRow(
                        run_id=f"r{(i + k) % 12}",
                        campaign=campaign,
                        origin=origin,
                        status="ok" if (i + k + offset) % 3 else "failed",
                    )
                    for i in range(6)
                )
            cat.close()
        except BaseException as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [
        threading.Thread(target=write, args=("a", "made", 0)),
        threading.Thread(target=write, args=("b", "reused", 1)),
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    cat = open_catalogue(url, root=tmp_path)
    with cat.engine.connect() as conn:
        kept = [dict(r._mapping) for r in conn.execute(campaign_counts())]
        counted = [dict(r._mapping) for r in conn.execute(recount_campaigns())]
    assert kept == counted
    assert [r["runs"] for r in kept] == [12, 12]
    cat.close()


def test_a_campaign_page_follows_the_changes_on_postgresql(url, tmp_path, monkeypatch):
    """The service's campaign page on a PostgreSQL catalogue: updates after a cursor, and
    runs recorded every 50 ms all shown (the SQLite tests of test_service_deltas.py)."""
    pytest.importorskip("fastapi")
    import test_service_deltas as deltas

    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    monkeypatch.setenv(location.ENV, url)
    deltas.test_a_run_recorded_after_a_cursor_is_in_the_update_after_it_and_no_other(
        tmp_path / "one"
    )
    monkeypatch.setenv(location.ENV, url.rsplit("/", 1)[0] + "/" + _fresh(url, "two"))
    deltas.test_runs_recorded_every_50_ms_are_all_shown_none_lost(tmp_path / "two")


def _fresh(url: str, suffix: str) -> str:
    """A new empty database beside ``url``'s; returns its name."""
    import psycopg
    import sqlalchemy as sa

    parsed = sa.engine.make_url(url)
    name = f"{parsed.database}_{suffix}"
    with psycopg.connect(
        f"host={parsed.host} port={parsed.port} user={parsed.username} dbname=postgres",
        autocommit=True,
    ) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}"')
        conn.execute(f'CREATE DATABASE "{name}"')
    return name
