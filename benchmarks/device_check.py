"""The accelerated backend on a device, in float64 and float32: an agreement check against the
numpy reference on a small case, then a timing table (both mechanics, 128^2 to 512^2, B = 1, 8,
50 seeds per batch where memory and the time budget allow). Prints one table, writes JSON, exits 1
if the agreement check fails. Run it through ``benchmarks/device_check.sh`` (which installs what
the machine lacks from ``benchmarks/device_wheels/``); ``--tiny`` is the CPU check CI runs.

Agreement (both mechanics, seeds 0 and 1 as one batch, the reference runs seed 0 on the host):
  * the accelerated float64 run against :func:`nematic_solids.model.simulate.run` (numpy backend)
    at every save: sigma2_S, lambda, mean_S within 1e-6 relative, <cos 2theta> within 1e-6
    absolute (they agree to rounding: the same steps, docs/model/accelerated.md);
  * float32 against float64 on the device: sigma2_S, lambda, mean_S within 1e-3 relative,
    <cos 2theta> within 1e-3 absolute (measured on the CPU: a few 1e-6 to 5e-5,
    docs/guide/precision.md).

Timing: fixed steps (``adaptive: false``, dt = 0.1, 10 steps from the seeded texture), so every
row does the same work (``--tiny``: the adaptive steps to t = 1, reusing the agreement's code);
``wall`` without the compile (reported apart), per step and per seed-step; ``peak_bytes`` the
device's peak memory where it reports one (GPUs). Rows are run in order of importance (B = 8 at
every size first) until ``--budget`` seconds are spent; the rest are listed as skipped, and a
batch the device cannot hold is listed with its error.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

import numpy as np

#: the observables compared, and whether by their absolute difference
COMPARED = {"sigma2_S": False, "lambda": False, "mean_S": False, "cos2theta": True}
REFERENCE_TOL = 1e-6
FLOAT32_TOL = 1e-3


def params_for(n: int):
    from nematic_solids.model.parameters import Parameters

    return Parameters.from_dict({"alpha_minus_B": 0.6, "noise_modes": min(8, n // 2 - 1)})


#: below this size a value is compared by its absolute difference (sigma2_S is ~1e-33 at t = 0,
#: the band texture's S being uniform: a relative difference of round-off would be noise)
FLOOR = 1e-9


def worst(a: np.ndarray, b: np.ndarray, absolute: bool) -> float:
    """The largest difference of b from a (relative to max(|a|, FLOOR) unless ``absolute``)
    where both are finite; infinite where neither is."""
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.any():
        return float("inf")
    diff = np.abs(b[ok] - a[ok])
    if not absolute:
        diff = diff / np.maximum(np.abs(a[ok]), FLOOR)
    return float(diff.max())


def agreement(device: str, n: int, t_final: float) -> list[dict]:
    """The agreement rows: per mechanics, float64 vs the reference, float32 vs float64."""
    from nematic_solids.model.accelerated import run_batch
    from nematic_solids.model.parameters import Numerics
    from nematic_solids.model.simulate import run

    rows = []
    params = params_for(n)
    for mech in ("linear", "finite"):
        num = Numerics(resolution=n, t_final=t_final, save_every=t_final / 4, mechanics=mech)
        t0 = time.perf_counter()
        ref = run(params, num.replace(backend="numpy"), 0)
        ref_s = time.perf_counter() - t0
        acc = {
            p: run_batch(params, num.replace(precision=p), [0, 1], device=device)
            for p in ("float64", "float32")
        }
        a64, a32 = acc["float64"], acc["float32"]
        checks = {}
        for name, absolute in COMPARED.items():
            checks[f"{name} float64 vs reference"] = (
                worst(np.asarray(ref[name].values), a64.series[name][0], absolute),
                REFERENCE_TOL,
            )
            checks[f"{name} float32 vs float64"] = (
                worst(a64.series[name], a32.series[name], absolute),
                FLOAT32_TOL,
            )
        ok = a64.status == a32.status == ["ok", "ok"] and all(
            d <= tol for d, tol in checks.values()
        )
        rows.append(
            {
                "mechanics": mech,
                "resolution": n,
                "t_final": t_final,
                "ok": bool(ok),
                "status": {p: r.status for p, r in acc.items()},
                "reference_s": ref_s,
                "compile_s": {p: r.compile for p, r in acc.items()},
                "checks": {k: {"difference": d, "tolerance": t} for k, (d, t) in checks.items()},
            }
        )
    return rows


def timing_rows(sizes: list[int], batches: list[int]) -> list[tuple[str, int, int, str]]:
    """(mechanics, N, B, precision) in order of importance: B = 8 (or the middle batch) at every
    size first, then the largest batch, then the rest."""
    order = sorted(batches, key=lambda b: (b != 8, -b))
    return [
        (mech, n, b, p)
        for b in order
        for n in sizes
        for mech in ("linear", "finite")
        for p in ("float64", "float32")
    ]


def timing(
    device: str, rows: list[tuple[str, int, int, str]], budget: float, fixed: bool = True
) -> list[dict]:
    """Time each row until ``budget`` seconds have gone: 10 fixed steps, or (``fixed`` false:
    the tiny check, which so reuses the agreement's compiled code) the adaptive steps to t = 1."""
    import jax

    from nematic_solids.model.accelerated import run_batch, select_device
    from nematic_solids.model.parameters import Numerics

    dev = select_device(device)
    out = []
    start = time.perf_counter()
    for mech, n, b, precision in rows:
        row: dict = {"mechanics": mech, "resolution": n, "batch": b, "precision": precision}
        if time.perf_counter() - start > budget:
            out.append({**row, "skipped": f"the time budget ({budget:g} s) was spent"})
            continue
        control: dict = {"dt": 0.1, "adaptive": False} if fixed else {}
        num = Numerics(resolution=n, t_final=1.0, save_every=1.0, mechanics=mech, **control)
        num = num.replace(precision=precision)
        try:
            r = run_batch(params_for(n), num, list(range(b)), device=device)
        except Exception as exc:  # noqa: BLE001 - a batch the device cannot hold: listed
            out.append({**row, "error": f"{type(exc).__name__}: {str(exc)[:300]}"})
            if fixed:
                jax.clear_caches()
            continue
        steps = float(np.mean(r.work["steps"]))
        stats = dev.memory_stats() or {}
        row.update(
            status=sorted(set(r.status)),
            steps=steps,
            wall_s=r.wall,
            compile_s=r.compile,
            wall_per_step_ms=1e3 * r.wall / max(steps, 1.0),
            wall_per_seed_step_ms=1e3 * r.wall / max(steps, 1.0) / b,
            transforms_per_step=float(np.mean(r.work["transforms"])) / max(steps, 1.0),
            peak_bytes=stats.get("peak_bytes_in_use"),
        )
        out.append(row)
        if fixed:
            jax.clear_caches()  # each shape compiles once; its code is not kept for later rows
    return out


def print_table(agree: list[dict], rows: list[dict]) -> None:
    print("agreement:")
    for a in agree:
        print(f"  {a['mechanics']:7s} {a['resolution']}^2: {'ok' if a['ok'] else 'FAILED'}")
        for name, c in a["checks"].items():
            flag = "" if c["difference"] <= c["tolerance"] else "   <-- over"
            print(f"    {name:32s} {c['difference']:9.2e} (tol {c['tolerance']:.0e}){flag}")
    print(
        f"{'mechanics':9s} {'N':>5s} {'B':>3s} {'prec':7s} {'steps':>5s} {'compile s':>9s} "
        f"{'ms/step':>9s} {'ms/seed-step':>12s} {'peak MB':>8s}"
    )
    for r in rows:
        head = f"{r['mechanics']:9s} {r['resolution']:5d} {r['batch']:3d} {r['precision']:7s}"
        if "skipped" in r or "error" in r:
            print(f"{head} {r.get('skipped') or r.get('error')}")
            continue
        peak = f"{r['peak_bytes'] / 2**20:8.0f}" if r["peak_bytes"] else f"{'-':>8s}"
        print(
            f"{head} {r['steps']:5.0f} {r['compile_s']:9.1f} {r['wall_per_step_ms']:9.2f} "
            f"{r['wall_per_seed_step_ms']:12.3f} {peak}"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tiny", action="store_true", help="the CPU check of CI: 32^2, B = 2")
    ap.add_argument("--device", default=None, help="cpu, gpu or auto (default: auto; cpu --tiny)")
    ap.add_argument("--budget", type=float, default=300.0, help="seconds for the timing rows")
    ap.add_argument("--out", type=Path, default=Path("device_check.json"))
    args = ap.parse_args(argv)
    device = args.device or ("cpu" if args.tiny else "auto")
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", "/tmp/nematic-device-check-jax-cache")
    import jax

    from nematic_solids.model.accelerated import select_device
    from nematic_solids.model.accelerated.device import describe

    if args.tiny:
        small, t_small, sizes, batches = 32, 2.0, [32], [2]
    else:
        small, t_small, sizes, batches = 64, 5.0, [128, 256, 512], [1, 8, 50]
    began = time.perf_counter()
    record: dict = {
        "what": "accelerated backend: agreement with the numpy reference, float64 and float32 "
        "timings (benchmarks/device_check.py)",
        "device": describe(select_device(device)),
        "jax": jax.__version__,
        "python": platform.python_version(),
        "host": platform.node(),
        "tiny": args.tiny,
    }
    try:
        agree = agreement(device, small, t_small)
    except Exception:  # noqa: BLE001 - the check could not run: a failure, traceback kept
        error = traceback.format_exc()
        agree = [{"mechanics": "-", "resolution": small, "ok": False, "error": error}]
        print(agree[0]["error"], file=sys.stderr)
    record["agreement"] = agree
    record["timing"] = timing(device, timing_rows(sizes, batches), args.budget, not args.tiny)
    record["total_s"] = time.perf_counter() - began
    passed = all(a["ok"] for a in agree)
    record["passed"] = passed
    args.out.write_text(json.dumps(record, indent=1))
    print(f"device: {record['device']} (JAX {record['jax']})")
    print_table([a for a in agree if "checks" in a], record["timing"])
    verdict = "PASSED" if passed else "FAILED"
    print(f"{verdict}: agreement check; {record['total_s']:.0f} s; {args.out}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
