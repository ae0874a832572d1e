"""Remake the list of the kernels' entry points (``model/compiled/entry_points.txt``) that
``python -m nematic_solids.model.warmup`` compiles in parallel processes.

    .venv/bin/python scripts/kernel_entry_points.py     # ~1.5 min: compiles every kernel once

Runs :func:`nematic_solids.model.warmup.warm_up` (a tiny finite and two tiny linear runs, one under
a protocol) in this process with an empty numba cache (a temporary ``NUMBA_CACHE_DIR``, removed
afterwards) and lists every signature with which Python called a compiled function (numba's
"numba:compile" events that no other compilation encloses) with its compile time, the longest
first. Run it after a change to the
kernels' signatures or to the code that calls them (``python -m nematic_solids.model.warmup`` says
so when the list misses something; tests/model/test_warmup.py checks it).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

HEADER = """\
# The signatures with which Python calls the model's compiled kernels in a tiny finite and two
# tiny linear runs, one under a protocol (nematic_solids.model.warmup.warm_up), with their
# compile times in seconds when listed: python -m nematic_solids.model.warmup compiles them in
# parallel processes, the longest first. Made by scripts/kernel_entry_points.py; columns:
# seconds, function, numba types (tab-separated).
"""


def main() -> int:
    cache = tempfile.mkdtemp(prefix="nematic-numba-")
    os.environ["NUMBA_CACHE_DIR"] = cache  # before numba is imported: an empty cache
    try:
        from numba.core import event

        from nematic_solids.model.warmup import ENTRY_POINTS_FILE, EntryPoint, type_text, warm_up

        t0 = time.perf_counter()
        with event.install_recorder("numba:compile") as recorder:
            info = warm_up()
        if info["errors"] or info["loaded"]:
            print(f"the warm-up did not compile everything afresh: {info}", file=sys.stderr)
            return 1
        seconds: dict[tuple[str, str], float] = {}
        types: dict[tuple[str, str], tuple] = {}
        started: list[float] = []
        for stamp, ev in recorder.buffer:
            if ev.is_start:
                started.append(stamp)
                continue
            begin = started.pop()
            if started:  # a callee, compiled with its caller
                continue
            func = ev.data["dispatcher"].py_func
            key = (
                f"{func.__module__}.{func.__qualname__}",
                f"tup({', '.join(type_text(t) for t in ev.data['args'])})",
            )
            seconds[key] = seconds.get(key, 0.0) + stamp - begin
            types[key] = tuple(ev.data["args"])
        entries = sorted(
            (EntryPoint(f, a, s) for (f, a), s in seconds.items()), key=lambda e: -e.seconds
        )
        for e in entries:  # each line reads back as what numba compiled
            if e.arg_types() != types[e.function, e.args] or e.dispatcher() is None:
                raise AssertionError(f"{e.line()} does not read back")
        tmp = Path(ENTRY_POINTS_FILE).with_suffix(".tmp")
        tmp.write_text(HEADER + "".join(e.line() + "\n" for e in entries))
        os.replace(tmp, ENTRY_POINTS_FILE)
        print(
            f"{len(entries)} entry points ({sum(e.seconds for e in entries):.0f} s of "
            f"compilation, {time.perf_counter() - t0:.0f} s in all) written to "
            f"{ENTRY_POINTS_FILE}"
        )
        return 0
    finally:
        shutil.rmtree(cache, ignore_errors=True)


if __name__ == "__main__":
    argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    ).parse_args()  # no options: --help prints the above and exits
    sys.exit(main())
