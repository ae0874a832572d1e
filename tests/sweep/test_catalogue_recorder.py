"""The driver's writer of the catalogue: runs finishing every 50 ms all recorded while a reader
polls the changes, a campaign's driver recording its runs, a catalogue that cannot be opened
failing no run, and the catch-up from the run records."""

from __future__ import annotations

import json
import shutil
import threading
import time

import pandas as pd
import pytest

from nematic_solids.sweep.catalogue import location, open_catalogue
from nematic_solids.sweep.catalogue.recorder import Recorder
from nematic_solids.sweep.store import CampaignStore


@pytest.fixture(autouse=True)
def no_env(monkeypatch):
    monkeypatch.delenv(location.ENV, raising=False)


def fake_record(i: int, campaign: str = "stream") -> dict:
    return {
        "run_id": f"run{i:05d}",
        "status": "ok" if i % 7 else "failed",
        "reason": "" if i % 7 else "nan",
        "seed": i,
        "wall_time": 0.05,
        "finished": "2026-12-07T12:00:00+00:00",
        "nc_bytes": 100 if i % 7 else None,
        "scalars": {"x": float(i)},
        "parameters": {"p": i / 10},
        "numerics": {"t_final": 1.0},
        "coords": {"p": i / 10},
        "campaign": campaign,
        "trajectory": f"traj{i}",
        "end_state": 1.0,
    }


def test_runs_finishing_every_50_ms_are_all_recorded_and_seen_by_a_poller(tmp_path):
    store = CampaignStore(tmp_path, "stream")
    store.ensure()
    n = 120
    seen: dict[str, int] = {}
    done = threading.Event()
    errors: list[BaseException] = []

    def poll() -> None:
        try:
            cat = open_catalogue(tmp_path)
            since = 0
            while True:
                finished = done.is_set()
                new = cat.changes(since)
                for rid, seq in zip(new["run_id"], new["seq"], strict=True):
                    seen[rid] = int(seq)
                if len(new):
                    since = int(new["seq"].max())
                if finished:
                    break
                time.sleep(0.1)
            cat.close()
        except BaseException as e:  # noqa: BLE001 - handed to the test
            errors.append(e)

    with Recorder(store) as recorder:
        reader = threading.Thread(target=poll)
        reader.start()
        for i in range(n):
            recorder.add(fake_record(i))
            time.sleep(0.05)
    done.set()
    reader.join(60)
    assert not errors
    assert recorder.problem is None
    assert recorder.written == n
    cat = open_catalogue(tmp_path)
    runs = cat.runs(campaign="stream")
    assert sorted(runs["run_id"]) == [f"run{i:05d}" for i in range(n)]
    assert set(seen) == set(runs["run_id"])  # the poller missed none
    assert sorted(runs["seq"]) == list(range(1, n + 1))  # one seq per run, no gaps
    assert int((runs["status"] == "failed").sum()) == len(range(0, n, 7))
    failed = runs.set_index("run_id").loc["run00007"]
    assert pd.isna(failed["path"])
    assert failed["reason"] == "nan"
    assert runs.set_index("run_id").loc["run00008", "path"] == "stream/runs/run00008.nc"
    cat.close()


def test_a_catalogue_that_cannot_be_opened_fails_no_run(tmp_path, caplog):
    store = CampaignStore(tmp_path, "c")
    store.ensure()
    recorder = Recorder(store, url="postgresql+psycopg://nobody@127.0.0.1:1/none")
    for i in range(5):
        recorder.add(fake_record(i, "c"))
    recorder.close()
    assert recorder.written == 0
    assert recorder.problem
    assert "not recorded" in caplog.text


def test_off_records_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv(location.ENV, "off")
    store = CampaignStore(tmp_path, "c")
    store.ensure()
    with Recorder(store) as recorder:
        recorder.add(fake_record(1, "c"))
    assert recorder.off
    assert not (tmp_path / "catalogue.sqlite").exists()


def test_a_campaigns_driver_records_its_runs(small):
    """The small campaign ran through ``nematic run`` (conftest): every run in its records
    is in the catalogue of its results root, made by it."""
    cat = open_catalogue(small.results)
    runs = cat.runs(campaign="small").set_index("run_id")
    for path in small.runs.glob("*.json"):
        rec = json.loads(path.read_text())
        assert runs.loc[path.stem, "status"] == rec["status"]
        assert runs.loc[path.stem, "origin"] == "made"
    assert len(runs) == len(list(small.runs.glob("*.json")))
    cat.close()


def test_the_recorder_catches_up_with_runs_recorded_without_it(small, tmp_path):
    root = tmp_path / "results"
    shutil.copytree(small.results, root, symlinks=True)
    for extra in ("", "-wal", "-shm"):
        (root / f"catalogue.sqlite{extra}").unlink(missing_ok=True)
    cat = open_catalogue(root, index=False)  # an empty catalogue
    assert cat.runs().empty
    cat.close()
    with Recorder(CampaignStore(root, "small")) as recorder:
        pass
    assert recorder.written == len(list((root / "small" / "runs").glob("*.json")))
    cat = open_catalogue(root)
    assert len(cat.runs(campaign="small")) == recorder.written
    cat.close()
