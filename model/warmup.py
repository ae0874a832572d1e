"""Compile the model's numba kernels once, before any real run needs them.

The kernels are compiled on first use and cached on disk (``cache=True``: ``*.nbi`` /
``*.nbc`` files in a folder named by the hash of the compiled sources,
:func:`nematic_solids.model.compiled.cache_dir`), so only the first run on a machine (or after a
change to the compiled code) pays the compilation. Without a warm-up, every worker of a campaign's
first run compiles the same kernels at the same time. :func:`warm_up` runs a tiny simulation (16^2,
to t = 0.5) of each kind a campaign uses, in one process; afterwards every other process loads the
compiled code from the cache. A campaign's warm-up
(:func:`nematic_solids.sweep.run.task.warm_worker`) is this, on one worker of each host.

``python -m nematic_solids.model.warmup`` (run by ``scripts/bootstrap.sh``) first compiles the
kernels' entry points in parallel processes (:func:`compile_in_parallel`, ``--jobs``; numba compiles
in one thread per process): the signatures with which the tiny finite and linear runs call compiled
code from Python, listed in ``model/compiled/entry_points.txt`` (made by
``scripts/kernel_entry_points.py``), one task per module, each after the modules it imports
(:func:`entry_groups`). Each process writes the disk cache, and loads from it the callees another
process has saved already; then :func:`warm_up` runs in the calling process and loads everything
from it, compiling only what the list missed (reported). The list's format is
:mod:`nematic_solids.model.entry_points`; the compiling processes hold a file lock around numba's
cache reads and writes (:func:`nematic_solids.model.kernel_cache.lock_cache_files`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import sys
import time
import traceback
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

# the names imported ``as`` themselves are importable from here too, where they used to be
# defined (the tests, scripts/kernel_entry_points.py)
from .entry_points import ENTRY_POINTS_FILE, EntryPoint, compile_entry_point, read_entry_points
from .entry_points import read_types as read_types
from .entry_points import type_text as type_text
from .kernel_cache import KERNEL_MODULES as KERNEL_MODULES
from .kernel_cache import compile_counts, lock_cache_files
from .kernel_cache import kernel_dispatchers as kernel_dispatchers
from .parameters import Numerics, Parameters

WARM_RESOLUTION = 16
WARM_T_FINAL = 0.5
#: At most this many compiling processes unless ``--jobs`` says otherwise (each holds a
#: numba compiler, a few hundred MB; the tasks are the 8 kernel modules of the list).
MAX_DEFAULT_JOBS = 8


def warm_numerics(numerics: Numerics) -> Numerics:
    """The tiny numerics that take the same code paths as ``numerics``."""
    return numerics.replace(
        resolution=WARM_RESOLUTION,
        t_final=WARM_T_FINAL,
        save_every=WARM_T_FINAL,
        snapshot_times=(),
        dt=min(numerics.dt, 0.05),
    )


def warm_up(kinds: Iterable[tuple[Parameters, Numerics]] | None = None) -> dict[str, Any]:
    """Run a tiny simulation for each ``(parameters, numerics)`` (default: the model's
    defaults with finite and with linear mechanics, and linear mechanics under a protocol,
    whose ETDRK4 step calls the right-hand side stage by stage instead of the compiled whole
    step) so that every kernel they use is compiled (or loaded from the cache). Returns the
    wall time and :func:`compile_counts`. Never raises for a failed tiny run (the real run
    reports its own failure)."""
    from .simulate import run

    if kinds is None:
        ramp = {"chi": {"ramp": {"start": 0.0, "duration": 1.0, "from": 10.0, "to": 5.0}}}
        kinds = [
            (Parameters(), Numerics(mechanics="finite")),
            (Parameters(), Numerics(mechanics="linear")),
            (Parameters.from_dict({"protocol": ramp}), Numerics(mechanics="linear")),
        ]
    t0 = time.perf_counter()
    errors = []
    for params, numerics in kinds:
        small = params.replace(noise_modes=min(params.noise_modes, WARM_RESOLUTION // 2 - 1))
        try:
            run(small, warm_numerics(numerics), seed=0)
        except Exception as e:  # noqa: BLE001 - a warm-up never stops the real work
            errors.append(f"{type(e).__name__}: {e}")
    return {"seconds": time.perf_counter() - t0, **compile_counts(), "errors": errors}


def one_line(e: BaseException) -> str:
    """``Type: first line of the message`` (numba's typing errors run to pages; their first
    line names only the compiler's step, so the second is added)."""
    lines = [t.strip() for t in str(e).splitlines() if t.strip()]
    text = ": ".join(lines[:2] if lines and lines[0].startswith("Failed in ") else lines[:1])
    more = " (-v: the whole message)" if len(lines) > 2 else ""
    return f"{type(e).__name__}: {text or '(no message)'}{more}"


def default_jobs() -> int:
    """The cores this process may use, at most :data:`MAX_DEFAULT_JOBS`."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, MAX_DEFAULT_JOBS))


def _compile_group(entries: list[EntryPoint], verbose: bool) -> list[dict[str, Any]]:
    """In a compiling process: :func:`compile_entry_point` for each of ``entries``, in turn;
    returns, for each, what it compiled and loaded or its error (one line, and the traceback
    if ``verbose``). Never raises, so that numba's exceptions need not pickle."""
    out: list[dict[str, Any]] = []
    for entry in entries:
        try:
            before = compile_counts()
            t0, cpu0 = time.perf_counter(), time.process_time()
            compile_entry_point(entry)
            after = compile_counts()
        except Exception as e:  # noqa: BLE001 - reported by the parent
            out.append(
                {"error": one_line(e), "traceback": traceback.format_exc() if verbose else ""}
            )
            continue
        out.append(
            {
                "seconds": time.perf_counter() - t0,
                "cpu_seconds": time.process_time() - cpu0,
                "pid": os.getpid(),
                **{k: after[k] - before[k] for k in after},
            }
        )
    return out


def _imports(module: str) -> set[str]:
    """The modules of ``module``'s package that its source imports (``from . import x``,
    ``from .x import y``)."""
    import ast
    import importlib.util

    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return set()
    package = module.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(Path(spec.origin).read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                out.add(f"{package}.{node.module}")
            else:
                out.update(f"{package}.{a.name}" for a in node.names)
    return out


def entry_groups(entries: list[EntryPoint]) -> list[list[EntryPoint]]:
    """``entries`` as the tasks of :func:`compile_in_parallel`: one per module (its kernels
    share callees, and the overloads that numba compiles again in every process), each after
    the modules it imports (directly or not), so that their kernels tend to be in the cache by
    the time it needs them; otherwise the longest first, as are the entries of a module."""
    groups: dict[str, list[EntryPoint]] = {}
    for e in sorted(entries, key=lambda e: -e.seconds):
        groups.setdefault(e.function.rpartition(".")[0], []).append(e)
    reach: dict[str, set[str]] = {}

    def below(module: str) -> set[str]:
        if module not in reach:
            reach[module] = set()  # a cycle stops here
            for m in _imports(module):
                reach[module] |= {m} | below(m)
        return reach[module]

    cost = {m: sum(e.seconds for e in group) for m, group in groups.items()}
    left = sorted(groups, key=lambda m: -cost[m])
    order: list[str] = []
    while left:
        ready = [m for m in left if not (below(m) - {m}) & (set(left) - {m})] or left[:1]
        order.append(ready[0])
        left.remove(ready[0])
    return [groups[m] for m in order]


def compile_in_parallel(
    entries: list[EntryPoint], jobs: int, verbose: bool = False
) -> dict[str, Any]:
    """Compile ``entries`` (into the disk cache) in ``jobs`` fresh processes (spawned, each
    with :func:`lock_cache_files`), a module's entries in one process (:func:`entry_groups`).
    Returns the wall time, the CPU time of the compiling (the processes' CPU seconds in
    :func:`compile_entry_point`, which the machine's load hardly changes), the processes used,
    the signatures they compiled and loaded (a
    callee compiled by two processes counts twice) and the errors, one line each
    (``module.function(types): Type: message``, the traceback after it with ``verbose``)."""
    groups = entry_groups(entries)
    workers = max(1, min(jobs, len(groups)))
    t0 = time.perf_counter()
    done: list[dict[str, Any]] = []
    errors: list[str] = []
    lost = 0
    with ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=lock_cache_files,
    ) as pool:
        futures = {pool.submit(_compile_group, group, verbose): group for group in groups}
        for fut in as_completed(futures):
            group = futures[fut]
            try:
                results = fut.result()
            except BrokenProcessPool:
                lost += len(group)
                continue
            except Exception as e:  # noqa: BLE001 - e.g. a result that did not pickle
                results = [{"error": one_line(e), "traceback": ""}] * len(group)
            for entry, result in zip(group, results, strict=True):
                if "error" in result:
                    errors.append(
                        f"{entry.label()}: {result['error']}"
                        + (f"\n{result['traceback']}" if result["traceback"] else "")
                    )
                else:
                    done.append(result)
    if lost:
        errors.append(
            f"a compiling process died ({lost} of {len(entries)} entry points not "
            f"compiled); python -m nematic_solids.model.warmup --jobs 1 compiles them in one "
            f"process"
        )
    return {
        "seconds": time.perf_counter() - t0,
        "cpu_seconds": sum(r["cpu_seconds"] for r in done),
        "processes": len({r["pid"] for r in done}),
        "compiled": sum(r["compiled"] for r in done),
        "loaded": sum(r["loaded"] for r in done),
        "errors": errors,
    }


def _ready_stamp(entry_points: Path) -> dict[str, str]:
    """What a complete warm-up's :func:`_ready_file` records: the compiled sources, numba,
    Python and the entry points it compiled."""
    import hashlib

    import numba

    from .compiled import source_digest

    try:
        listed = hashlib.sha256(entry_points.read_bytes()).hexdigest()[:16]
    except OSError:
        listed = ""
    return {
        "sources": source_digest(),
        "numba": numba.__version__,
        "python": sys.version,
        "entry_points": listed,
    }


def _ready_file() -> Path:
    """``nematic-ready.json`` in numba's cache folder: written after a complete warm-up, so
    that the next ``python -m nematic_solids.model.warmup`` goes straight to loading (no compiling
    processes to start). If it is wrong (cache files deleted), :func:`warm_up` compiles what is
    missing."""
    import numba

    from . import compiled  # noqa: F401 - points numba's cache at the compiled sources' folder

    return Path(numba.config.CACHE_DIR) / "nematic-ready.json"  # type: ignore[attr-defined]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m nematic_solids.model.warmup",
        description="Compile the model's numba kernels into the disk cache (a few seconds "
        "when they are there already).",
    )
    parser.add_argument(
        "-j",
        "--jobs",
        type=int,
        default=None,
        help=f"compiling processes (default: the usable cores, at most "
        f"{MAX_DEFAULT_JOBS}; 1: compile in this process only)",
    )
    parser.add_argument(
        "--entry-points",
        type=Path,
        default=ENTRY_POINTS_FILE,
        help="the kernel signatures to compile in parallel (default: %(default)s)",
    )
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="the full traceback of a failed compilation"
    )
    args = parser.parse_args(argv)
    jobs = args.jobs if args.jobs is not None else default_jobs()
    if jobs < 1:
        parser.error("--jobs must be at least 1")
    print(
        "compiling the model's numba kernels (cached on disk; once, then a few seconds) ...",
        flush=True,
    )
    if not os.environ.get("NUMBA_CACHE_DIR"):  # the hashed folders are ours to tidy
        from .compiled import prune_stale_caches

        for path in prune_stale_caches():
            print(f"removed the kernel cache of an earlier version: {path}", flush=True)
    stamp = _ready_stamp(args.entry_points)
    try:
        ready = json.loads(_ready_file().read_text()) == stamp
    except (OSError, ValueError):
        ready = False
    entries: list[EntryPoint] = []
    if jobs > 1 and not ready:
        try:
            entries = read_entry_points(args.entry_points)
            for entry in entries:
                entry.arg_types()
        except Exception as exc:  # noqa: BLE001 - then compile in this process (--jobs 1)
            print(
                f"warning: cannot read the kernels' entry points ({one_line(exc)}): "
                f"compiling in this process only",
                file=sys.stderr,
                flush=True,
            )
            entries = []
    if entries:
        par = compile_in_parallel(entries, jobs, verbose=args.verbose)
        for line in par["errors"]:
            print(f"error: compiling {line}", file=sys.stderr)
        if par["errors"]:
            return 1
        print(
            f"{len(entries)} entry points ready in {par['seconds']:.0f} s in "
            f"{par['processes']} processes, {par['cpu_seconds']:.0f} CPU-s "
            f"({par['compiled']} signatures compiled, {par['loaded']} loaded from the cache)",
            flush=True,
        )
    info = warm_up()
    print(
        f"kernels ready in {info['seconds']:.0f} s ({info['compiled']} compiled, "
        f"{info['loaded']} loaded from the cache)",
        flush=True,
    )
    if entries and info["compiled"]:
        print(
            f"note: {info['compiled']} kernel signatures were compiled here, not in "
            f"parallel: {args.entry_points} misses them (scripts/kernel_entry_points.py "
            f"remakes it)",
            flush=True,
        )
    for e in info["errors"]:
        print(f"warning: warm-up run failed: {e}", file=sys.stderr)
    if not info["errors"]:
        with contextlib.suppress(OSError):  # only a shortcut for the next call
            _ready_file().write_text(json.dumps(stamp))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
