"""The first run on a machine: the model's kernels are compiled once (by one worker, before
the campaign's runs start), not by every worker at once (:mod:`nematic_solids.model.warmup`)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from sweep_helpers import write_campaign

from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.run.driver import RunSummary, dask_client, run_campaign
from nematic_solids.sweep.run.task import warm_kinds
from nematic_solids.sweep.run.todo import plan_runs
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.store import CampaignStore


def test_warm_kinds_one_per_kind_of_run(tmp_path):
    path = write_campaign(tmp_path, values="[0.1, 0.2, 0.3]")
    kinds = warm_kinds(expand(load_campaign(path)))
    assert len(kinds) == 1  # three points, one kind (finite, etdrk4, adaptive)
    params, numerics = kinds[0]
    assert numerics["mechanics"] == "finite"
    assert params["noise_modes"] == 8  # the campaign's own parameters
    text = path.read_text().replace("save_every: 0.5", "save_every: 0.5, mechanics: linear")
    path.write_text(
        text.replace(
            "alpha_minus_B: [0.1, 0.2, 0.3]",
            "alpha_minus_B: [0.1, 0.2]\n    incompressible: [false, true]",
        )
    )
    kinds = warm_kinds(expand(load_campaign(path)))
    assert sorted(n["incompressible"] for _, n in kinds) == [False, True]


def test_warm_up_runs_a_tiny_simulation_and_counts_kernels():
    from nematic_solids.model.warmup import compile_counts, warm_numerics, warm_up

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

    import nematic_solids.model.compiled as compiled

    here = compiled.cache_dir()
    assert here.name == f"numba-{compiled.source_digest()}"
    if not __import__("os").environ.get("NUMBA_CACHE_DIR"):
        assert str(here) == numba.config.CACHE_DIR  # type: ignore[attr-defined]
    copy = tmp_path / "compiled"
    shutil.copytree(
        Path(compiled.__file__).parent, copy, ignore=shutil.ignore_patterns("__pycache__")
    )
    assert compiled.source_digest(copy) == compiled.source_digest()
    krylov = copy / "krylov.py"
    krylov.write_text(krylov.read_text() + "\n# an edit\n")
    assert compiled.source_digest(copy) != compiled.source_digest()


def test_stale_kernel_caches_are_pruned_and_the_current_one_kept(tmp_path):
    from nematic_solids.model.compiled import prune_stale_caches

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
    from nematic_solids.model.warmup import compile_counts

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


def test_the_listed_entry_points_read_back_as_numba_types():
    """model/compiled/entry_points.txt names existing kernels with signatures that read back
    (tuples and named tuples included); whether it is complete is the slow test below."""
    from typing import NamedTuple

    import numpy as np
    from numba import typeof
    from numba.core import types

    from nematic_solids.model.warmup import read_entry_points, read_types, type_text

    entries = read_entry_points()
    assert entries
    for e in entries:
        assert hasattr(e.dispatcher(), "compile"), e.function
        assert type_text(types.Tuple(list(e.arg_types()))) == e.args

    class Pair(NamedTuple):
        a: int
        b: float

    pair = typeof(Pair(1, 2.0))
    with pytest.raises(ValueError, match="does not read back"):  # a local class: no name
        type_text(types.Tuple([pair]))
    same = (
        typeof(np.zeros((2, 2))[:, ::2]),
        typeof((np.zeros(3), np.zeros(3))),
        types.int64,
        typeof((1, 2.0)),
    )
    assert read_types(type_text(types.Tuple(list(same)))) == same


def test_entry_points_are_compiled_by_module_after_the_modules_they_import():
    from nematic_solids.model.warmup import entry_groups, read_entry_points

    entries = read_entry_points()
    groups = entry_groups(entries)
    modules = [g[0].function.rpartition(".")[0] for g in groups]
    assert sorted(e.line() for g in groups for e in g) == sorted(e.line() for e in entries)
    assert len(set(modules)) == len(modules)  # one task per module
    assert all(
        e.function.startswith(m + ".") for m, g in zip(modules, groups, strict=True) for e in g
    )
    order = {m.rpartition(".")[2]: i for i, m in enumerate(modules)}
    for caller, callees in (
        ("finite_krylov", ("fftw", "constitutive", "spectral")),
        ("linear_step", ("fftw", "etd", "rates")),
        ("wellposedness", ("constitutive",)),
    ):
        assert all(order[c] < order[caller] for c in callees), modules


def _save_many(path: str, worker: int, count: int) -> None:
    from numba.core.caching import IndexDataCacheFile

    from nematic_solids.model.warmup import lock_cache_files

    lock_cache_files()
    cache = IndexDataCacheFile(path, "kernel-1.py311", source_stamp="s")
    for i in range(count):
        cache.save(("key", worker, i), f"data {worker} {i}")


def test_cache_writes_from_several_processes_keep_every_entry(tmp_path):
    """numba rewrites a function's cache index without a lock: processes that save at once
    can lose entries or give one data file to two signatures. With lock_cache_files every
    entry of every process is kept and loads its own data."""
    import multiprocessing

    from numba.core.caching import IndexDataCacheFile

    ctx = multiprocessing.get_context("spawn")
    workers, count = 3, 100  # without the lock, some entries are lost or wrong at this count
    procs = [ctx.Process(target=_save_many, args=(str(tmp_path), w, count)) for w in range(workers)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
        assert p.exitcode == 0
    cache = IndexDataCacheFile(str(tmp_path), "kernel-1.py311", source_stamp="s")
    for w in range(workers):
        for i in range(count):
            assert cache.load(("key", w, i)) == f"data {w} {i}"


def _in_fresh_process(tmp_path: Path, *args: str) -> Any:
    """``python *args`` with the numba cache in ``tmp_path`` (empty at first)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    return subprocess.run(
        [sys.executable, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=1200,
        cwd=Path(__file__).resolve().parents[2],
    )


def _warmup(tmp_path: Path, *args: str) -> Any:
    return _in_fresh_process(tmp_path, "-m", "nematic_solids.model.warmup", *args)


def test_a_failure_in_a_compiling_process_is_one_line_and_a_nonzero_exit(tmp_path):
    listed = tmp_path / "entry_points.txt"
    listed.write_text(
        "# two entry points that cannot compile\n"
        "2.0\tnematic_solids.model.compiled.spectral.grad_hat_kernel\ttup(int64, int64, int64)\n"
        "1.0\tnematic_solids.model.compiled.spectral.no_such_kernel\ttup(int64)\n"
    )
    done = _warmup(tmp_path, "--jobs", "2", "--entry-points", str(listed))
    assert done.returncode == 1, done
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 2, done.stderr  # one line per failure, no traceback
    assert "Traceback" not in done.stderr
    by_kernel = {line.split("(")[0]: line for line in lines}
    assert (
        "TypingError: Failed in nopython mode pipeline"
        in by_kernel["error: compiling nematic_solids.model.compiled.spectral.grad_hat_kernel"]
    )
    assert (
        "AttributeError"
        in by_kernel["error: compiling nematic_solids.model.compiled.spectral.no_such_kernel"]
    )
    assert "kernels ready" not in done.stdout  # it stopped there


@pytest.mark.slow
def test_the_parallel_warm_up_leaves_a_cache_a_fresh_process_only_loads(tmp_path):
    """python -m nematic_solids.model.warmup with an empty cache compiles the listed entry points in
    two processes; the warm-up in its own process then compiles nothing (the list is complete), nor
    does a fresh process; a second call starts no compiling process. About a minute on 2 cores."""
    first = _warmup(tmp_path, "--jobs", "2")
    assert first.returncode == 0, first
    assert re.search(
        r"ready in \d+ s in 2 processes, \d+ CPU-s \([1-9]\d* signatures compiled", first.stdout
    ), first.stdout
    assert re.search(r"kernels ready in \d+ s \(0 compiled, [1-9]\d* loaded", first.stdout), (
        first.stdout
    )
    fresh = _in_fresh_process(
        tmp_path,
        "-c",
        "import json; from nematic_solids.model.warmup import warm_up; "
        "print(json.dumps(warm_up()))",
    )
    assert fresh.returncode == 0, fresh
    info = json.loads(fresh.stdout.strip().splitlines()[-1])
    assert info["errors"] == [], info
    assert info["compiled"] == 0, info  # everything from the cache
    assert info["loaded"] > 0, info
    second = _warmup(tmp_path, "--jobs", "2")
    assert second.returncode == 0, second
    assert "entry points ready" not in second.stdout  # straight to loading
    assert "(0 compiled" in second.stdout, second.stdout
