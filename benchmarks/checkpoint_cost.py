"""What do checkpoints cost a 128^2 finite-strain run? (a benchmark, not a test)

One run (128^2, finite strain, alpha - B = 1, seed 0, save_every 2) through the worker's own
code (:func:`nematic_solids.sweep.run.task.execute_run`: the simulation, the rolling checkpoints,
the run file with its end state and the record), in three settings, alternated A B C A B C ... in
one process so that the machine's drift falls on all three alike:

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
    python benchmarks/checkpoint_cost.py --only default   # one run of one setting
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

from nematic_solids.model.warmup import warm_up  # noqa: E402
from nematic_solids.sweep.campaign import DEFAULT_CHECKPOINT_WALL, StoreSpec  # noqa: E402
from nematic_solids.sweep.expand import expand  # noqa: E402
from nematic_solids.sweep.run.task import RunTask, execute_run  # noqa: E402
from nematic_solids.sweep.spec import parse_campaign  # noqa: E402
from nematic_solids.sweep.store import CampaignStore  # noqa: E402

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
    """One run through the worker's code; the checkpoints' own time measured around each."""
    from nematic_solids.sweep.run import continuation

    written: list[tuple[int, float]] = []
    original = continuation.Checkpointer.__call__

    def timed(self, state):  # type: ignore[no-untyped-def]
        t0 = time.perf_counter()
        original(self, state)
        written.append((self.path.stat().st_size, time.perf_counter() - t0))

    continuation.Checkpointer.__call__ = timed  # type: ignore[method-assign]
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
        "checkpoint_bytes": max((b for b, _ in written), default=0),
        "checkpoint_seconds": statistics.median(s for _, s in written) if written else 0.0,
        "run_file_bytes": int(record["nc_bytes"] or 0),
    }


def end_state_write(task: RunTask, store: CampaignStore, repeat: int = 5) -> tuple[float, float]:
    """Median seconds to write the run file without and with its end state (the worker's
    own atomic write, fsync included)."""
    from nematic_solids.model.simulate import run as simulate
    from nematic_solids.sweep.files import atomic_to_netcdf
    from nematic_solids.sweep.run.continuation import STATE_GROUP
    from nematic_solids.sweep.run.task import prepare_dataset

    params, numerics = expansion_model(task)
    ds, end = simulate(params, numerics, task.seed, keep_state=True)
    assert end is not None
    ds, encoding = prepare_dataset(ds, task)
    path = store.root / "write-test.nc"
    times: dict[bool, list[float]] = {False: [], True: []}
    for _ in range(repeat):
        for with_state in (False, True):
            groups = {STATE_GROUP: end.to_dataset(snapshots=False)} if with_state else {}
            t0 = time.perf_counter()
            atomic_to_netcdf(ds, path, encoding, groups)
            times[with_state].append(time.perf_counter() - t0)
    return statistics.median(times[False]), statistics.median(times[True])


def expansion_model(task: RunTask):  # type: ignore[no-untyped-def]
    from nematic_solids.model.parameters import Numerics, Parameters

    return Parameters.from_dict(task.parameters), Numerics.from_dict(task.numerics)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--t-final", type=float, default=100.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dense", type=float, default=5.0)
    ap.add_argument(
        "--only",
        choices=("off", "default", "dense"),
        help="one run of one setting, printed, no JSON (to time two settings as processes)",
    )
    args = ap.parse_args()
    campaign = parse_campaign(CAMPAIGN.format(t_final=args.t_final), "ckpt.yaml")
    expansion = expand(campaign)
    warm_up([(expansion.points[0].parameters, expansion.points[0].numerics)])
    out: dict[str, list[dict[str, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        store = CampaignStore(Path(tmp), "ckpt")
        store.ensure()
        specs = settings(args.dense)
        if args.only:
            task = RunTask.from_spec(expansion.run(0), store, "ckpt", specs[args.only])
            print(args.only, one(task, store))
            return
        for _ in range(args.repeat):
            for name, spec in specs.items():
                task = RunTask.from_spec(expansion.run(0), store, "ckpt", spec)
                out.setdefault(name, []).append(one(task, store))
                print(f"  {name:8s} {out[name][-1]}", flush=True)
    med = {
        name: {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        for name, runs in out.items()
    }
    per_checkpoint = med["dense"]["checkpoint_seconds"]
    at_default = per_checkpoint / DEFAULT_CHECKPOINT_WALL
    dense_share = med["dense"]["checkpoints"] * per_checkpoint / med["off"]["wall"]
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
        f"one checkpoint: {med['dense']['checkpoint_bytes'] / 1e6:.2f} MB, written in "
        f"{per_checkpoint:.3f} s (measured around each write)"
    )
    print(
        f"at the default interval ({DEFAULT_CHECKPOINT_WALL / 60:g} min of wall time) a run "
        f"longer than that pays {100 * at_default:.3f} % for its checkpoints; the dense "
        f"setting ({med['dense']['checkpoints']:.0f} checkpoints) "
        f"{100 * dense_share:.1f} % of this run"
    )
    with tempfile.TemporaryDirectory() as tmp:
        store = CampaignStore(Path(tmp), "ckpt")
        store.ensure()
        task = RunTask.from_spec(expansion.run(0), store, "ckpt", StoreSpec())
        plain, with_state = end_state_write(task, store)
    end_share = (with_state - plain) / med["off"]["wall"]
    print(
        f"the run file: written in {plain:.3f} s alone, {with_state:.3f} s with its end state: "
        f"the end state adds {100 * end_share:.1f} % to this run"
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
        "overhead_of_dense_checkpoints_on_this_run": dense_share,
        "run_file_write_seconds": {"alone": plain, "with_end_state": with_state},
        "overhead_of_end_state_on_this_run": end_share,
    }
    (ROOT / "benchmarks" / "checkpoint_cost.json").write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
