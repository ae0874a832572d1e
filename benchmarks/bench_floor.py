"""A run's wall time against its transform floor: for the default parameters at alpha - B = 1
(seed 0, default numerics), linear and finite mechanics at 128^2 (t = 300), 256^2 (t = 100)
and 512^2 (t = 30; the larger grids shortened), the steps, the transforms, the time of one
real 2-D transform measured in the same process (a forward and an inverse of the run's FFTW
plans on aligned arrays, their mean, measured before and after the run: the median of the
batches), the floor = transforms x that time, the wall time, wall / floor and the time per
step. Not a test: the numbers depend on the machine and its load.

    .venv/bin/python benchmarks/bench_floor.py                      # this checkout
    .venv/bin/python benchmarks/bench_floor.py --before ../main --repeat 2 --fingerprint
    .venv/bin/python benchmarks/bench_floor.py --configs 128:50 --mechanics linear   # quick

Each run is a fresh process (``python -c`` of the checkout's own ``.venv``, whose editable
install imports that checkout; the checkout's folder first on ``sys.path``) that
first runs t = 1 (the kernels loaded from numba's cache, the plans made), then the timed run.
With ``--before PATH`` (another checkout of the project, e.g. the main branch) every
configuration runs alternately on the two codes, before, after, before, after ... (``--repeat``
pairs), so that the machine's drift falls on both alike; the table gives the medians and the
median of the pairwise wall ratios after / before. ``--fingerprint`` also runs
``scripts/fingerprint.py`` on both codes and says whether the outputs are byte-identical (else
the largest relative difference of its scalars). ``--perf`` (Linux perf, ``apt install
linux-perf``) also samples each timed run and gives the share of its time spent in FFTW: its
inverse is wall / floor measured inside the run, with no transform timed apart
(``perf_ratio``). Writes ``benchmarks/bench_floor.json`` (``--out``): the rows of each code with
its git commit.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, sys, time
import numpy as np
cfg = json.loads(sys.argv[1])
sys.path.insert(0, cfg["code"])
from nematic_solids.model.compiled import fftw as fx
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run
params = Parameters.from_dict({"alpha_minus_B": 1.0})
num = Numerics(resolution=cfg["N"], t_final=cfg["t_final"], mechanics=cfg["mechanics"])
run(params, num.replace(t_final=1.0, save_every=1.0), 0)  # the kernels loaded, the plans made

def transform_time():
    # one real 2-D transform of this size: the mean of a forward and an inverse (FFTW's
    # new-array execute on aligned arrays, as the compiled code runs them), median of batches
    n = cfg["N"]
    pf, pi = fx.plans(n)
    a = fx.aligned_empty((n, n), np.float64)
    a[...] = np.random.default_rng(0).standard_normal((n, n))
    b = fx.aligned_empty((n, n // 2 + 1), np.complex128)
    s = fx.aligned_half(n)
    reps = max(5, int(2e6 / n**2))
    wall, cpu = [], []
    for _ in range(7):
        c0, t0 = time.process_time(), time.perf_counter()
        for _ in range(reps):
            fx.rfft2(pf, a, b)
            fx.irfft2_via(pi, b, a, s)
        wall.append((time.perf_counter() - t0) / (2 * reps))
        cpu.append((time.process_time() - c0) / (2 * reps))
    return wall, cpu

fft, fft_cpu = transform_time()
if cfg.get("perf"):  # the parent attaches perf to the run alone
    print("READY", flush=True)
    sys.stdin.readline()
c0, t0 = time.process_time(), time.perf_counter()
ds = run(params, num, 0)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
if cfg.get("perf"):
    print("RUN_DONE", flush=True)
    sys.stdin.readline()
w, c = transform_time()
fft, fft_cpu = fft + w, fft_cpu + c
a = ds.attrs
print("RESULT " + json.dumps({
    "wall_s": wall, "cpu_s": cpu, "fft_s": float(np.median(fft)),
    "fft_cpu_s": float(np.median(fft_cpu)), "status": a["status"],
    "steps": int(a["solver_steps"]), "rejected": int(a["solver_rejected"]),
    "rhs": int(a["solver_rhs"]), "transforms": int(a["fft_count"]),
    "sigma2_S": float(ds["sigma2_S"].values[-1]), "lambda": float(ds["lambda"].values[-1])}))
"""


def commit(code: Path) -> str:
    """The checkout's commit, with "+dirty" where its model/ differs from it."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(code), *args], capture_output=True, text=True
        ).stdout.strip()

    head = git("rev-parse", "--short=12", "HEAD")
    return head + ("+dirty" if git("status", "--porcelain", "model") else "")


def python_of(code: Path) -> str:
    """The Python that imports ``code``'s package: its own ``.venv`` (the package is an editable
    install whose finder maps ``nematic_solids`` to that checkout, whatever ``sys.path`` says);
    this process's Python for this checkout."""
    if code.resolve() == HERE.parent.resolve():
        return sys.executable
    venv = code / ".venv" / "bin" / "python"
    if not venv.exists():
        sys.exit(
            f"error: {code} has no .venv of its own (run 'bash scripts/bootstrap.sh' there): "
            "this environment's nematic_solids is this checkout, not that one"
        )
    return str(venv)


def child(code: Path, cfg: dict, perf: bool = False) -> dict:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    env["PYTHONPATH"] = str(code)
    args = [python_of(code), "-c", CHILD, json.dumps({**cfg, "code": str(code), "perf": perf})]
    if perf:
        stdout, stderr, share = sampled(args, code, env)
    else:
        proc = subprocess.run(args, capture_output=True, text=True, cwd=code, env=env)
        stdout, stderr, share = proc.stdout, proc.stderr, None
    for line in stdout.splitlines():
        if line.startswith("RESULT "):
            r = {**cfg, **json.loads(line[7:])}
            if share is not None:
                # the run's own time in FFTW (perf's samples): wall / floor without the
                # transform timed apart, so without the drift between that timing and the run
                r["fftw_share"] = share
                r["perf_ratio"] = 1.0 / share if share > 0 else float("nan")
            r["floor_s"] = r["transforms"] * r["fft_s"]
            r["ratio"] = r["wall_s"] / r["floor_s"]
            # the same in CPU time (this process's own: less sensitive to other load)
            r["cpu_ratio"] = r["cpu_s"] / (r["transforms"] * r["fft_cpu_s"])
            r["ms_per_step"] = 1e3 * r["wall_s"] / max(r["steps"], 1)
            return r
    raise RuntimeError(f"benchmark child failed:\n{stdout}\n{stderr}")


def sampled(args: list[str], code: Path, env: dict) -> tuple[str, str, float]:
    """Run the child under ``perf record`` (attached for its timed run only); returns its
    output and the share of the run's samples that fall in FFTW."""
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        proc = subprocess.Popen(
            args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=code, env=env
        )
        assert proc.stdin is not None
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.strip() == "READY":
                break
        rec = subprocess.Popen(
            ["perf", "record", "-F", "2000", "-p", str(proc.pid), "-o", data, "-q"],
            stderr=subprocess.DEVNULL,
        )
        time.sleep(1.0)  # perf attached
        proc.stdin.write("\n")
        proc.stdin.flush()
        for line in proc.stdout:
            lines.append(line)
            if line.strip() == "RUN_DONE":
                break
        rec.send_signal(signal.SIGINT)
        rec.wait()
        proc.stdin.write("\n")
        proc.stdin.flush()
        lines += proc.stdout.readlines()
        proc.wait()
        samples = subprocess.run(
            ["perf", "script", "-i", data, "-F", "ip,dso"], capture_output=True, text=True
        ).stdout.splitlines()  # "address (library)" per sample
    samples = [line for line in samples if line.strip()]
    share = sum("fftw" in line for line in samples) / max(len(samples), 1)
    return "".join(lines), "", share


def fingerprint(code: Path) -> str:
    env = {**os.environ, "PYTHONPATH": str(code)}
    return subprocess.run(
        [python_of(code), str(code / "scripts" / "fingerprint.py")],
        capture_output=True,
        text=True,
        cwd=code,
        env=env,
        check=True,
    ).stdout


def compare_fingerprints(a: str, b: str) -> dict:
    """Byte-identical, or the largest relative difference of the scalars and the records
    that differ."""
    if a == b:
        return {"identical": True}
    ja, jb = json.loads(a), json.loads(b)
    worst, differ = 0.0, []
    for name in ja:
        if ja[name] != jb.get(name):
            differ.append(name)
        for k, v in ja[name]["scalars"].items():
            w = jb[name]["scalars"].get(k)
            try:
                x, y = float(v), float(w)
            except (TypeError, ValueError):
                continue
            if x != y:
                worst = max(worst, abs(x - y) / max(abs(x), abs(y), 1e-300))
    return {"identical": False, "runs_differing": differ, "max_rel_scalar_diff": worst}


def median_row(rows: list[dict]) -> dict:
    keys = ("wall_s", "cpu_s", "fft_s", "fft_cpu_s", "floor_s", "ratio", "cpu_ratio", "ms_per_step")
    out = {k: statistics.median(r[k] for r in rows) for k in keys}
    out.update({k: rows[0][k] for k in ("N", "t_final", "mechanics", "steps", "transforms")})
    out.update({k: rows[0][k] for k in ("sigma2_S", "lambda", "status")})
    if all("perf_ratio" in r for r in rows):
        out["perf_ratio"] = statistics.median(r["perf_ratio"] for r in rows)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", default="128:300,256:100,512:30", help="N:t_final,...")
    ap.add_argument("--mechanics", default="linear,finite")
    ap.add_argument("--before", type=Path, help="another checkout to run alternately")
    ap.add_argument("--repeat", type=int, default=1, help="runs (pairs) per configuration")
    ap.add_argument("--fingerprint", action="store_true", help="compare scripts/fingerprint.py")
    ap.add_argument(
        "--perf", action="store_true", help="also the run's own share of time in FFTW (Linux perf)"
    )
    ap.add_argument("--out", default=str(HERE / "bench_floor.json"))
    args = ap.parse_args()
    after = HERE.parent
    codes = {"after": after} if args.before is None else {"before": args.before, "after": after}
    rows: dict[str, list[dict]] = {k: [] for k in codes}
    table: dict[str, list[dict]] = {k: [] for k in codes}
    print(
        f"{'code':6s} {'mech':6s} {'N':>4s} {'t':>4s} {'steps':>6s} {'transforms':>10s} "
        f"{'fft us':>7s} {'floor s':>8s} {'wall s':>7s} {'ratio':>6s} {'cpu r':>6s} "
        f"{'ms/step':>8s} "
        f"{'sigma2_S':>10s}"
    )
    pairs = []
    for spec in args.configs.split(","):
        n, t_final = spec.split(":")
        for mech in args.mechanics.split(","):
            cfg = {"N": int(n), "t_final": float(t_final), "mechanics": mech}
            got: dict[str, list[dict]] = {k: [] for k in codes}
            for _ in range(args.repeat):
                for label, code in codes.items():
                    got[label].append(child(code, cfg, args.perf))
            for label in codes:
                rows[label] += got[label]
                m = median_row(got[label])
                table[label].append(m)
                print(
                    f"{label:6s} {mech:6s} {m['N']:4d} {m['t_final']:4.0f} {m['steps']:6d} "
                    f"{m['transforms']:10d} {1e6 * m['fft_s']:7.1f} {m['floor_s']:8.2f} "
                    f"{m['wall_s']:7.2f} {m['ratio']:6.2f} {m['cpu_ratio']:6.2f} "
                    f"{m['ms_per_step']:8.2f} "
                    f"{m['sigma2_S']:10.6g}"
                    + (
                        f"  in-run FFTW: wall / transforms {m['perf_ratio']:.2f}"
                        if args.perf
                        else ""
                    ),
                    flush=True,
                )
            if "before" in codes:
                zipped = list(zip(got["after"], got["before"], strict=True))
                ratios = [a["wall_s"] / b["wall_s"] for a, b in zipped]
                cpu = [a["cpu_s"] / b["cpu_s"] for a, b in zipped]
                pairs.append(
                    {**cfg, "wall_after_over_before": ratios, "cpu_after_over_before": cpu}
                )
                print(
                    f"       after / before, pairwise: wall {[round(r, 3) for r in ratios]}, "
                    f"cpu {[round(r, 3) for r in cpu]}"
                )
    out: dict = {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "parameters": 'Parameters.from_dict({"alpha_minus_B": 1.0}), seed 0, default numerics',
        "pairs": pairs,
    }
    for label, code in codes.items():
        out[label] = {"commit": commit(code), "table": table[label], "runs": rows[label]}
    if args.fingerprint and "before" in codes:
        out["fingerprint"] = compare_fingerprints(
            fingerprint(codes["before"]), fingerprint(codes["after"])
        )
        print(f"fingerprint: {out['fingerprint']}")
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
