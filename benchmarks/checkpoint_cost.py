"""What do checkpoints cost a 128^2 finite-strain run? (a benchmark, not a test)

One run (128^2, finite strain, alpha - B = 1, seed 0, save_every 2) through the worker's own
code (:func:`sweep.run.task.execute_run`: the simulation, the rolling checkpoints, the run file
with its end state and the record), in three settings, alternated A B C A B C ... in one
process so that the machine's drift falls on all three alike:

- ``off``: ``checkpoint_every: false``, ``end_state: false`` (the run file alone);
- ``default``: the defaults (a checkpoint every 10 minutes of wall time, the end state kept);
- ``dense``: a checkpoint every ``--dense`` tau (default 5: 20 checkpoints to t = 100).

Prints, per setting, the median wall time with the solver's step and transform counts (the
same in all three: the checkpoints change no step), the checkpoints written, the run file's
size, the size of one checkpoint; then the cost of one checkpoint (from ``dense`` against
``off``) and what it adds at the default interval to a run longer than that interval
(one checkpoint per 10 minutes), and what the defaults add to this run. Writes
benchmarks/checkpoint_cost.json.

    python benchmarks/checkpoint_cost.py [--t-final 100] [--repeat 3] [--dense 5]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from model.warmup import warm_up  # noqa: E402
from sweep.campaign import DEFAULT_CHECKPOINT_WALL, StoreSpec  # noqa: E402
from sweep.expand import expand  # noqa: E402
from sweep.run.task import RunTask, execute_run  # noqa: E402
from sweep.spec import parse_campaign  # noqa: E402
from sweep.store import CampaignStore  # noqa: E402

CAMPAIGN = """\
name: ckpt
parameters: {{alpha_minus_B: 1.0}}
numerics: {{resolution: 128, t_final: {t_final}, save_every: 2.0, mechanics: finite}}
seeds: [0]
"""


def settings(dense: float) -> dict[str, StoreSpec]:
    return {
        "off": StoreSpec(checkpoint_tau=math.inf, checkpoint_wall=math.inf, end_state=False),
        "default": StoreSpec(),
        "dense": StoreSpec(checkpoint_tau=dense, checkpoint_wall=math.inf),
    }


def one(task: RunTask, store: CampaignStore) -> dict[str, float]:
    from sweep.run import continuation

    written: list[int] = []
    original = continuation.Checkpointer.__call__

    def counting(self, state):  # type: ignore[no-untyped-def]
        original(self, state)
        written.append(self.path.stat().st_size)

    continuation.Checkpointer.__call__ = counting  # type: ignore[method-assign]
    try:
        store.discard(task.run_id)
        t0 = time.perf_counter()
        record = execute_run(task)
        wall = time.perf_counter() - t0
    finally:
        continuation.Checkpointer.__call__ = original  # type: ignore[method-assign]
    assert record["status"] == "ok", record
    import xarray as xr

    with xr.open_dataset(store.nc_path(task.run_id)) as ds:
        steps, fft = int(ds.attrs["solver_steps"]), int(ds.attrs["fft_count"])
    return {
        "wall": wall,
        "steps": steps,
        "fft": fft,
        "checkpoints": len(written),
        "checkpoint_bytes": max(written, default=0),
        "run_file_bytes": int(record["nc_bytes"] or 0),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--t-final", type=float, default=100.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dense", type=float, default=5.0)
    args = ap.parse_args()
    campaign = parse_campaign(CAMPAIGN.format(t_final=args.t_final), "ckpt.yaml")
    expansion = expand(campaign)
    warm_up([(expansion.points[0].parameters, expansion.points[0].numerics)])
    out: dict[str, list[dict[str, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        store = CampaignStore(Path(tmp), "ckpt")
        store.ensure()
        specs = settings(args.dense)
        for _ in range(args.repeat):
            for name, spec in specs.items():
                task = RunTask.from_spec(expansion.run(0), store, "ckpt", spec)
                out.setdefault(name, []).append(one(task, store))
                print(f"  {name:8s} {out[name][-1]}", flush=True)
    med = {
        name: {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        for name, runs in out.items()
    }
    per_checkpoint = (med["dense"]["wall"] - med["off"]["wall"]) / max(
        med["dense"]["checkpoints"], 1
    )
    at_default = per_checkpoint / DEFAULT_CHECKPOINT_WALL
    default_here = med["default"]["wall"] / med["off"]["wall"] - 1.0
    print()
    print(
        f"128^2 finite strain, t = 0..{args.t_final:g}, {args.repeat} alternated repeats (medians)"
    )
    print(
        f"{'setting':9s} {'wall s':>8s} {'steps':>6s} {'transforms':>11s} "
        f"{'ckpts':>6s} {'run file':>10s}"
    )
    for name, m in med.items():
        print(
            f"{name:9s} {m['wall']:8.2f} {m['steps']:6.0f} {m['fft']:11.0f} "
            f"{m['checkpoints']:6.0f} {m['run_file_bytes'] / 1e6:8.2f} MB"
        )
    print(
        f"one checkpoint: {med['dense']['checkpoint_bytes'] / 1e6:.2f} MB, {per_checkpoint:.3f} s"
    )
    print(
        f"at the default interval ({DEFAULT_CHECKPOINT_WALL / 60:g} min of wall time) a longer "
        f"run pays {100 * at_default:.3f} % for its checkpoints"
    )
    print(
        "the defaults on this run (no rolling checkpoint, the end state kept): "
        f"{100 * default_here:+.1f} %"
    )
    result = {
        "command": "python benchmarks/checkpoint_cost.py " + " ".join(sys.argv[1:]),
        "t_final": args.t_final,
        "repeat": args.repeat,
        "dense_tau": args.dense,
        "runs": out,
        "medians": med,
        "seconds_per_checkpoint": per_checkpoint,
        "overhead_at_default_interval": at_default,
        "overhead_of_defaults_on_this_run": default_here,
    }
    (ROOT / "benchmarks" / "checkpoint_cost.json").write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
