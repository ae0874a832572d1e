"""The first run on a machine: the model's kernels are compiled once (by one worker, before
the campaign's runs start), not by every worker at once (:mod:`model.warmup`)."""

from __future__ import annotations

from pathlib import Path

import pytest
from sweep_helpers import write_campaign

from model.parameters import Numerics, Parameters
from sweep.execute import RunSummary, dask_client, run_campaign
from sweep.expand import expand
from sweep.plan import plan_runs
from sweep.spec import load_campaign
from sweep.store import CampaignStore
from sweep.task import warm_kinds


def test_warm_kinds_one_per_kind_of_run(tmp_path):
    path = write_campaign(tmp_path, values="[0.1, 0.2, 0.3]")
    kinds = warm_kinds(expand(load_campaign(path)))
    assert len(kinds) == 1  # three points, one kind (finite, etdrk4, adaptive)
    params, numerics = kinds[0]
    assert numerics["mechanics"] == "finite"
    assert params["noise_modes"] == 8  # the campaign's own parameters
    text = path.read_text().replace("save_every: 0.5", "save_every: 0.5, mechanics: linear")
    path.write_text(text.replace("alpha_minus_B: [0.1, 0.2, 0.3]",
                                 "alpha_minus_B: [0.1, 0.2]\n    incompressible: [false, true]"))
    kinds = warm_kinds(expand(load_campaign(path)))
    assert sorted(n["incompressible"] for _, n in kinds) == [False, True]


def test_warm_up_runs_a_tiny_simulation_and_counts_kernels():
    from model.warmup import compile_counts, warm_numerics, warm_up

    small = warm_numerics(Numerics(resolution=64, t_final=40, snapshot_times=(10.0,)))
    assert (small.resolution, small.t_final, small.snapshot_times) == (16, 0.5, ())
    info = warm_up([(Parameters(), Numerics(mechanics="linear"))])
    assert info["errors"] == []
    counts = compile_counts()
    assert counts["compiled"] + counts["loaded"] > 0  # the run used compiled kernels


def test_the_numba_cache_is_named_by_the_compiled_sources(tmp_path, monkeypatch):
    """A change to any compiled module starts a fresh cache (numba alone would keep the stale
    machine code of a function whose callee in another file changed)."""
    import shutil

    import numba

    import model.compiled as compiled

    here = compiled.cache_dir()
    assert here.name == f"numba-{compiled.source_digest()}"
    if not __import__("os").environ.get("NUMBA_CACHE_DIR"):
        assert str(here) == numba.config.CACHE_DIR  # type: ignore[attr-defined]
    copy = tmp_path / "compiled"
    shutil.copytree(Path(compiled.__file__).parent, copy,
                    ignore=shutil.ignore_patterns("__pycache__"))
    assert compiled.source_digest(copy) == compiled.source_digest()
    krylov = copy / "krylov.py"
    krylov.write_text(krylov.read_text() + "\n# an edit\n")
    assert compiled.source_digest(copy) != compiled.source_digest()


def test_stale_kernel_caches_are_pruned_and_the_current_one_kept(tmp_path):
    from model.compiled import prune_stale_caches

    current = tmp_path / "numba-current"
    (current / "x").mkdir(parents=True)
    for name in ("numba-old1", "numba-old2"):
        (tmp_path / name / "y").mkdir(parents=True)
    (tmp_path / "other").mkdir()
    removed = prune_stale_caches(current)
    assert sorted(p.name for p in removed) == ["numba-old1", "numba-old2"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["numba-current", "other"]
    assert (current / "x").is_dir()


@pytest.mark.slow
def test_the_second_worker_compiles_nothing(tmp_path, monkeypatch):
    """With an empty numba cache (NUMBA_CACHE_DIR: a fresh folder) a two-worker campaign
    compiles the kernels on one worker (the warm-up); the other loads them all from the
    cache. About a minute of compilation."""
    from model.warmup import compile_counts

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba-cache"))
    path = write_campaign(tmp_path, values="[0.1, 0.2]", seeds=2, t_final=1.0)
    expansion = expand(load_campaign(path))
    store = CampaignStore(tmp_path / "results", expansion.campaign.name)
    store.ensure()
    plan = plan_runs(expansion, store)
    with dask_client(expansion.campaign.execution) as client:
        summary: RunSummary = run_campaign(expansion, store, client, plan)
        counts = client.run(compile_counts)
    assert summary.ok == 4
    assert len(counts) == 2
    warm, second = sorted(counts.values(), key=lambda c: c["compiled"], reverse=True)
    assert warm["compiled"] > 0, counts  # the warm-up worker compiled the kernels
    assert second["compiled"] == 0, counts  # the second worker: everything from the cache,
    assert second["loaded"] > 0, counts  # and it did run (it used compiled kernels)
