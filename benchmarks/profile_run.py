"""Where a run's time goes: the share of each compiled function, of FFTW, numpy and the Python
interpreter in one run of the default parameters at alpha - B = 1 (seed 0), sampled by Linux
``perf`` (``apt install linux-perf``) at 4 kHz. Not a test: the shares depend on the machine.

    .venv/bin/python benchmarks/profile_run.py                        # 128^2 linear, t = 300
    .venv/bin/python benchmarks/profile_run.py --mechanics finite --t-final 100
    .venv/bin/python benchmarks/profile_run.py --resolution 256 --t-final 30 --top 30

The run is a child process with an empty numba cache of its own (a temporary
``NUMBA_CACHE_DIR``: its kernels are compiled in it, about two minutes, so that their machine
code keeps its symbol table); after a short run (t = 1) it lists the address of every function
of every compiled kernel's library, then this script samples the timed run with ``perf record
-p``. A sample in compiled code counts for the function whose entry is the nearest below it
(a kernel inlined into its caller counts for the caller). Prints the shares and writes
``benchmarks/profile_MECHANICS_N.json`` (``--out``).
"""

from __future__ import annotations

import argparse
import bisect
import collections
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, os, sys, time
cfg = json.loads(sys.argv[1])
from numba.core.registry import CPUDispatcher
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run
params = Parameters.from_dict({"alpha_minus_B": 1.0})
num = Numerics(resolution=cfg["N"], t_final=cfg["t_final"], mechanics=cfg["mechanics"])
run(params, num.replace(t_final=1.0, save_every=1.0), 0)
symbols = set()
for name, module in list(sys.modules.items()):
    if not name.startswith("nematic_solids.model.compiled"):
        continue
    for obj in vars(module).values():
        if not isinstance(obj, CPUDispatcher):
            continue
        for cres in obj.overloads.values():
            lib = cres.library
            for f in lib._final_module.functions:
                if not f.is_declaration:
                    symbols.add((lib.get_pointer_to_function(f.name), f.name))
with open(cfg["symbols"], "w") as fh:
    json.dump(sorted(symbols), fh)
print("READY", flush=True)
sys.stdin.readline()  # the profiler is attached
t0 = time.perf_counter()
ds = run(params, num, 0)
print("WALL", time.perf_counter() - t0, ds.attrs["fft_count"], ds.attrs["solver_steps"], flush=True)
os._exit(0)  # no interpreter shutdown in the samples
"""

#: a compiled function's mangled name -> module.function
_MANGLED = re.compile(r"compiled\d+([A-Za-z_]+?)\d+([A-Za-z_][A-Za-z0-9_]*?)B\d")


def short(name: str) -> str:
    m = _MANGLED.search(name)
    return f"{m.group(1)}.{m.group(2)}" if m else name[:40]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--t-final", type=float, default=300.0)
    ap.add_argument("--mechanics", default="linear")
    ap.add_argument("--top", type=int, default=20, help="compiled functions listed")
    ap.add_argument("--out", help="JSON file (default benchmarks/profile_MECHANICS_N.json)")
    a = ap.parse_args()
    if shutil.which("perf") is None:
        print("error: Linux perf is not installed (apt install linux-perf)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        cfg = {"N": a.resolution, "t_final": a.t_final, "mechanics": a.mechanics}
        cfg["symbols"] = os.path.join(tmp, "symbols.json")
        env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba"))
        child = subprocess.Popen(
            [sys.executable, "-c", CHILD, json.dumps(cfg)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=env,
        )
        assert child.stdin is not None
        assert child.stdout is not None
        if child.stdout.readline().strip() != "READY":
            print("error: the run did not start", file=sys.stderr)
            return 1
        data = os.path.join(tmp, "perf.data")
        perf = subprocess.Popen(
            ["perf", "record", "-F", "4000", "-p", str(child.pid), "-o", data, "-q"],
            stderr=subprocess.DEVNULL,
        )
        time.sleep(1.0)  # perf attached
        child.stdin.write("\n")
        child.stdin.flush()
        _, wall, transforms, steps = child.stdout.readline().split()
        child.wait()
        perf.wait()
        script = subprocess.run(
            ["perf", "script", "-i", data, "-F", "ip,dso"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        with open(cfg["symbols"]) as fh:
            symbols = [(int(addr), name) for addr, name in json.load(fh)]
    symbols.sort()
    starts = [s for s, _ in symbols]
    parts: collections.Counter[str] = collections.Counter()
    kernels: collections.Counter[str] = collections.Counter()
    for line in script.splitlines():
        fields = line.split()
        if len(fields) < 2:
            continue
        ip, dso = int(fields[0], 16), fields[1]
        if "fftw" in dso:
            parts["FFTW"] += 1
        elif "perf-" in dso or "JIT" in dso:
            i = bisect.bisect_right(starts, ip) - 1
            parts["compiled (numba)"] += 1
            kernels[short(symbols[i][1]) if i >= 0 else "?"] += 1
        elif "multiarray" in dso or "numpy" in dso:
            parts["numpy"] += 1
        elif "libpython" in dso:
            parts["Python"] += 1
        else:
            parts[Path(dso.strip("()")).name or "other"] += 1
    total = sum(parts.values())
    print(
        f"{a.mechanics} {a.resolution}^2 t = {a.t_final:g}: wall {float(wall):.2f} s, "
        f"{steps} steps, {transforms} transforms, {total} samples"
    )
    for name, n in parts.most_common(8):
        print(f"  {100 * n / total:5.1f} %  {name}")
    print("compiled functions:")
    for name, n in kernels.most_common(a.top):
        print(f"  {100 * n / total:5.1f} %  {name}")
    result = {
        "config": {k: v for k, v in cfg.items() if k != "symbols"},
        "wall_s": float(wall),
        "steps": int(steps),
        "transforms": int(transforms),
        "samples": total,
        "parts": {k: n / total for k, n in parts.most_common()},
        "compiled": {k: n / total for k, n in kernels.most_common()},
    }
    out = Path(a.out or HERE / f"profile_{a.mechanics}_{a.resolution}.json")
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
