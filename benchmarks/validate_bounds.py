"""How long and how much memory does ``nematic validate`` take on large or hostile campaign
files? (a benchmark, not a test; ``tests/sweep/test_hostile_limits.py`` holds the bounds)

Each file is read and checked by ``load_campaign`` in one fresh process per file: CPU seconds
of the read and check, and the growth of the process's peak resident memory over the peak
after the imports. Also the model's check of every grid point (``grid_<n>``, ``grid_<n>x<m>``:
an accepted campaign of that many grid points, one seed; ``protocol_<n>x<n>``: each point with
a pulse and a sine), which is linear in the grid points: the largest accepted grids have
sweep.limits.MAX_GRID_POINTS points, and ``grid_1000x1000`` is refused by its size. And
collections (``collection_*``: the collection read and checked, then each member as
``nematic validate`` does): the largest accepted, sweep.limits.MAX_COLLECTION_MEMBERS small
campaigns, and hostile ones refused by their member count or the YAML's node bound.

    python benchmarks/validate_bounds.py [CASE ...]

Prints a table and writes benchmarks/validate_bounds.json (with CASEs: only those cases, the
others kept as they were).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

PROBE = """
import json, resource, sys, time
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.spec.collection import read_collection
import nematic_solids.sweep.analysis.registry, nematic_solids.sweep.figures.registry
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.process_time()
try:
    collection = read_collection(sys.argv[1])
    for member in collection.members if collection is not None else [sys.argv[1]]:
        load_campaign(member)
    outcome = "accepted"
except CampaignError as e:
    outcome = " ".join(str(e).split())[-110:]
cpu = time.process_time() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"cpu_s": round(cpu, 3), "peak_growth_mib": round((peak - base) / 1024, 1),
                  "outcome": outcome}))
"""


def _flat(n: int) -> str:
    return "name: flat\nsweep:\n  axes:\n    eps: [" + ",".join("0" for _ in range(n)) + "]\n"


def _grid(n: int, m: int = 1) -> str:
    """An accepted grid of n x m points (one seed), its values written out."""
    eps = ", ".join(f"{i * 1e-6:.6f}" for i in range(n))
    ks = (
        f"\n    K: [{', '.join(f'{1e-5 * (1 + i * 1e-3):.8g}' for i in range(m))}]" if m > 1 else ""
    )
    return f"name: grid\nsweep:\n  axes:\n    eps: [{eps}]{ks}\nseeds: 1\n"


def _protocol_grid(n: int) -> str:
    """n x n points, each with a pulse of alpha - B and an eps sine (the moduli fit checks
    save_every against the period at every point): the costliest point check."""
    levels = ", ".join(f"{0.05 + i * 1e-3:.6f}" for i in range(n))
    durations = ", ".join(f"{25 + i * 0.5:.3f}" for i in range(n))
    return (
        "name: protocol\nprotocol:\n  alpha_minus_B: {pulse: {base: 1.0, start: 150}}\n"
        "  eps: {sine: {amplitude: 0.01, period: 40}}\nfits: [moduli]\nsweep:\n  axes:\n"
        f"    alpha_minus_B_level: [{levels}]\n    alpha_minus_B_duration: [{durations}]\n"
        "seeds: 1\n"
    )


def cases(folder: Path) -> dict[str, Path]:
    texts = {
        "flat_2096000_values_4MiB": _flat(2_096_000),
        "flat_385000_values_0.77MB": _flat(385_000),
        "aliases_1e9": "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n"
        + "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]\n" for i in range(1, 9))
        + "description: *a8\n",
        "nested_3000_deep": "x: " + "[" * 3000 + "]" * 3000 + "\n",
        "string_4MiB": "name: s\ndescription: " + "x" * (4 * 2**20 - 100) + "\nseeds: 1\n",
        "grid_1000": _grid(1000),
        "grid_10000": _grid(10_000),
        "grid_100x100": _grid(100, 100),
        "protocol_100x100": _protocol_grid(100),
        "grid_1000x1000": "name: big\nsweep:\n  axes:\n    eps: {linspace: [0, 0.1, 1000]}\n"
        "    K: {linspace: [1.0e-5, 1.0e-3, 1000]}\nseeds: 1\n",
    }
    member = "parameters: {noise_modes: 8}\nsweep: {axes: {eps: [0.0, 0.01]}}\nseeds: 1\n"
    for i in range(100):
        (folder / f"member{i}.yaml").write_text(f"name: member{i}\n{member}")
    texts["collection_100_members"] = "campaigns:\n" + "".join(
        f"  - member{i}.yaml\n" for i in range(100)
    )
    texts["collection_90000_members"] = "campaigns:\n" + "  - member0.yaml\n" * 90_000
    texts["collection_1000000_members"] = "campaigns: [" + "a," * 999_999 + "a]\n"
    out = {}
    for name, text in texts.items():
        out[name] = folder / f"{name}.yaml"
        out[name].write_text(text)
    out["sparse_10GiB"] = folder / "sparse.yaml"
    with open(out["sparse_10GiB"], "wb") as f:
        f.truncate(10 * 2**30)
    return out


def main() -> None:
    out = Path(__file__).with_suffix(".json")
    only = sys.argv[1:]
    results = json.loads(out.read_text()) if only and out.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in cases(Path(tmp)).items():
            if only and name not in only:
                continue
            done = subprocess.run(
                [sys.executable, "-c", PROBE, str(path)], capture_output=True, text=True
            )
            results[name] = json.loads(done.stdout)
            r = results[name]
            print(f"{name:28s} {r['cpu_s']:7.3f} s {r['peak_growth_mib']:7.1f} MiB  {r['outcome']}")
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
