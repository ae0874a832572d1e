"""Cost before launch: the runs a campaign has still to do, their CPU time and the wall time
on its workers (``nematic run --dry-run``, ``nematic validate --estimate``).

It reads the results folder, if there is one, and writes nothing (no lock, no manifest, no
folder). A run to do is costed, in this order of preference:

- **at a point already run** (the same parameters and numerics, other seeds): the median of
  that point's measured run times (the records' ``wall_time``);
- **scaled** from the campaign's other finished runs: the cost model's seconds for the run
  (:mod:`nematic_solids.sweep.cost.model`: resolution, length, saves, mechanics) times the median of
  measured / model over the finished runs of the same kind and resolution (else of the
  same kind, else all of them);
- **the cost model** alone when the campaign has no finished run.

The spread is the 10-90 % range of the run times, summed over the runs to do: at measured
points the seed-to-seed spread of the points with several runs (else the spread of the
ratios below), for scaled runs the 10 % and 90 % quantiles of measured / model, for the cost
model its calibration's :data:`~nematic_solids.sweep.cost.model.MODEL_SPREAD`. The wall time on W
workers is the runs dealt in the campaign's order to the first free worker (as the driver's window
does), whose makespan lies between the CPU time over W and that plus the longest run, plus the
driver's own time (:data:`DRIVER_OVERHEAD`). On a local cluster the cost model's run times (a free
core each) and part of the driver's time are stretched by the machine's load (:func:`slowdown`: W
workers beside a load average L on C cores get C / (L + W) of a core each); measured run times
already carry the load they ran under. An adaptive campaign is costed for the round its results have
reached (round 0 without results) plus a bound on the later rounds
(:func:`nematic_solids.sweep.refine.plan.run_bound`); a campaign with seeds by precision for its
current round plus the seeds each point is expected to need
(:mod:`nematic_solids.sweep.precision.forecast`), each at its point's cost.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from nematic_solids.model.resolution import is_rule, read_rule

from ..campaign import Campaign, ExecutionSpec, local_worker_count
from ..expand import Expansion, GridPoint, continued_runs, expand
from ..store import RETRYABLE_REASONS, CampaignStore, Record
from .later import Prior, campaign_prior, point_key, precision_rounds, refine_rounds
from .model import MODEL_SPREAD, has_cost_model, kind, model_seconds, point_seconds
from .result import Costed, Estimate, fmt_seconds

#: the quantiles of the spread
QUANTILES = (0.1, 0.9)
#: the driver's own wall time around the runs of a local campaign (seconds): the command's
#: start, the cluster's, the kernels' warm-up from the disk cache, the results written (a few
#: tenths of a second per run), phase.nc, fits, figures and report: a fixed part and a part
#: stretched by the machine's load like a run (:func:`slowdown`). Measured with
#: campaigns/quickstart.yaml on the 2-core VM (docs/campaigns/cost.md, *Cost before launch*): the
#: command's wall time less the runs' makespan: about 13 s on the quiet machine (the 19.1 s
#: quickstart of benchmarks/first_run.md, load average 0.5), 23-33 s at load average 3-5
#: and 40-45 s at 11-14
DRIVER_OVERHEAD = (8.0, 4.7)


def point_label(point: GridPoint) -> str:
    return ", ".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in point.coords.items()
    )


def _seconds(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) and value > 0 else None


def run_length(point: GridPoint, record: Mapping[str, Any]) -> float:
    """The model time a finished run covered: ``t_stopped`` when it stopped early."""
    scalars = record.get("scalars") or {}
    if scalars.get("stopped_early") and _seconds(scalars.get("t_stopped")) is not None:
        return float(scalars["t_stopped"])
    return point.numerics.t_final


def makespan(times: Sequence[float], workers: int) -> float:
    """The wall time of ``times`` dealt in order to the first free of ``workers``."""
    free = [0.0] * max(1, min(workers, len(times)))
    for t in times:
        heapq.heapreplace(free, free[0] + t)
    return max(free) if times else 0.0


def machine_load() -> tuple[float, int]:
    """This machine's 1-minute load average (0 where the system has none) and its cores."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = 0.0
    return load, os.cpu_count() or 1


def driver_overhead(stretch: float) -> float:
    """The driver's own wall time at a machine's :func:`slowdown` (:data:`DRIVER_OVERHEAD`)."""
    return DRIVER_OVERHEAD[0] + DRIVER_OVERHEAD[1] * stretch


def slowdown(workers: int, load: float, cores: int) -> float:
    """How much longer a run takes than on a free core when ``workers`` runs share ``cores``
    with ``load`` other runnable processes: 1 while each has a core of its own."""
    return max(1.0, (load + workers) / max(1, cores))


def concurrency(execution: ExecutionSpec) -> tuple[int, str]:
    """How many runs go at once, and where that comes from."""
    if execution.mode == "cluster" and execution.cluster is not None:
        cl = execution.cluster
        jobs = cl.adapt[1] if cl.adapt else cl.jobs
        cores = cl.options.get("cores")
        per = int(cores) if isinstance(cores, int) and cores > 0 else 1
        what = "adapt.maximum_jobs" if cl.adapt else "jobs"
        return jobs * per, (
            f"{cl.kind} cluster: {what} {jobs} x cores {per}"
            + (" (queue waits not included)" if jobs else "")
        )
    local = local_worker_count(execution) * execution.threads_per_worker
    if execution.mode == "scheduler":
        return local, (
            f"an external scheduler ({execution.scheduler}): its workers are not "
            f"known here, this machine's {local} assumed"
        )
    return local, "local cluster"


class Basis:
    """The campaign's measured runs and how a run to do is costed from them."""

    def __init__(
        self,
        measured: list[tuple[str, tuple[Any, ...], int, float, float]],
        prior: Prior | None = None,
    ):
        #: (point label, kind, resolution, seconds, model seconds) of every measured run
        self.measured = measured
        #: the campaign's prior: its measured run times at the points this campaign has
        #: not measured yet
        self.prior = prior
        self.by_point: dict[str, list[float]] = {}
        for label, _, _, seconds, _ in measured:
            self.by_point.setdefault(label, []).append(seconds)
        within = [s / float(np.median(v)) for v in self.by_point.values() if len(v) > 1 for s in v]
        self.seed_spread = _spread(within) if len(within) >= 3 else None

    def ratios(self, kind_: tuple[object, ...], resolution: int) -> list[float]:
        for keep in (
            lambda k, n: k == kind_ and n == resolution,
            lambda k, n: k == kind_,
            lambda k, n: True,
        ):
            r = [s / m for _, k, n, s, m in self.measured if keep(k, n) and m > 0]
            if r:
                return r
        return []

    def cost(self, point: GridPoint, label: str, model: float) -> tuple[float, float, float, str]:
        """(seconds, low, high, basis) of one run at ``point``."""
        if label in self.by_point:
            times = self.by_point[label]
            est = float(np.median(times))
            lo, hi = self.seed_spread or self.ratio_spread(point)
            n = len(times)
            return est, est * lo, est * hi, f"its {n} finished run{'s' if n > 1 else ''}"
        known = self.prior.point_seconds(point.coords) if self.prior is not None else None
        if known is not None and self.prior is not None:
            lo, hi = self.seed_spread or MODEL_SPREAD
            why = "the prior's measured runs there"
            grid = self.prior.resolution.get(point_key(point.coords))
            own = getattr(point.numerics, "resolution", None)
            if grid is not None and own is not None and grid != own:  # another grid: scaled
                known *= model / model_seconds(
                    dataclasses.replace(point.numerics, resolution=grid),
                    protocol=point.parameters.protocol,
                )
                why += f" on {grid}^2, scaled to {own}^2 by the cost model"
            return known, known * lo, known * hi, why
        ratios = self.ratios(*kind(point.numerics))
        if ratios:
            med = float(np.median(ratios))
            lo, hi = _spread(ratios) if len(ratios) >= 3 else MODEL_SPREAD
            return model * med, model * med * lo, model * med * hi, "scaled"
        why = "cost model" if has_cost_model(point.numerics) else NO_COST_MODEL
        return model, model * MODEL_SPREAD[0], model * MODEL_SPREAD[1], why

    def ratio_spread(self, point: GridPoint) -> tuple[float, float]:
        ratios = self.ratios(*kind(point.numerics))
        return _spread(ratios) if len(ratios) >= 3 else MODEL_SPREAD


def _spread(values: Sequence[float]) -> tuple[float, float]:
    """The 10 % and 90 % quantiles of ``values`` over their median."""
    med = float(np.median(values))
    lo, hi = (float(q) for q in np.quantile(values, QUANTILES))
    return lo / med, hi / med


def classify(
    expansion: Expansion,
    store: CampaignStore,
    records: Mapping[str, Record],
    *,
    retry_failed: bool = False,
) -> tuple[list[int], int, int]:
    """(positions to do, done, failed and not redone), as ``nematic run`` would plan them
    (:func:`nematic_solids.sweep.run.todo.plan_runs`) but without touching the folder: a record
    whose file is not intact is a run to do."""
    todo: list[int] = []
    done = failed = 0
    for i, rid in enumerate(expansion.run_ids):
        rec = records.get(rid)
        if rec is None or store.check_run_file(rid, rec) is not None:
            todo.append(i)
        elif rec.get("status") == "ok":
            done += 1
        elif retry_failed or rec.get("reason") in RETRYABLE_REASONS:
            todo.append(i)
        else:
            failed += 1
    return todo, done, failed


def reused_elsewhere(
    expansion: Expansion, store: CampaignStore, todo: list[int]
) -> tuple[list[int], dict[str, int]]:
    """The runs to do that ``nematic run`` would take from other campaigns of the results
    root instead of running them (read only: an existing catalogue alone), and how many
    from which campaign."""
    from ..catalogue.reuse import open_for_reuse, reusable

    catalogue = open_for_reuse(store.results_root, create=False) if todo else None
    if catalogue is None:
        return todo, {}
    with catalogue:
        found = reusable(catalogue, store, [expansion.run_ids[i] for i in todo])
    counts: dict[str, int] = {}
    for src in found.values():
        counts[src.campaign] = counts.get(src.campaign, 0) + 1
    return [i for i in todo if expansion.run_ids[i] not in found], counts


#: the basis of a run's price for a model without a cost model, before any run is measured
NO_COST_MODEL = "cost model (none: 1 s a run until runs are measured)"


def measurements(
    expansion: Expansion, records: Mapping[str, Record], prior: Prior | None = None
) -> Basis:
    """Every successful run of ``expansion`` with a recorded run time (and the campaign's
    ``prior``, for the points it has not measured)."""
    measured = []
    models: dict[tuple[int, float], float] = {}
    for i, rid in enumerate(expansion.run_ids):
        rec = records.get(rid)
        if rec is None or rec.get("status") != "ok":
            continue
        seconds = _seconds(rec.get("wall_time"))
        if seconds is None:
            continue
        point = expansion.run(i).point
        length = run_length(point, rec)
        key = (id(point), length)
        if key not in models:
            models[key] = point_seconds(point.parameters, point.numerics, length)
        measured.append((point_label(point), *kind(point.numerics), seconds, models[key]))
    return Basis(measured, prior)


def estimate(
    campaign: Campaign,
    store: CampaignStore,
    *,
    retry_failed: bool = False,
    load_cores: tuple[float, int] | None = None,
    started: float | None = None,
) -> Estimate:
    """The estimate of what ``nematic run`` would do now (see the module docstring);
    ``load_cores``: the machine's load average and cores (default :func:`machine_load`);
    ``started``: made by a running driver that took this many seconds to start (its cluster
    and warm-up are behind it: the driver's own time left is :func:`driver_overhead` less
    them, at least nothing; and on a local cluster its own workers, which the load average
    still counts, are not taken as other load)."""
    from ..outputs.changes import campaign_changes

    records = store.scan(save=False)
    later = None
    round_note = ""
    if campaign.refine is None and campaign.precision is None:
        expansion: Expansion = expand(campaign)
        dense = expansion
    elif campaign.refine is not None:
        from ..refine.rounds import replay

        ref = replay(campaign, store, records)
        expansion, dense = ref.run_list(), ref.expansion()
        round_note = (
            f"adaptive: round {ref.current.number} "
            + ("(the grid)" if ref.current.number == 0 else "")
            + (f"; refinement finished ({ref.stop})" if ref.finished else "")
        )
    else:
        from ..precision.rounds import replay as replay_seeds

        seeds = replay_seeds(campaign, store, records)
        expansion, dense = seeds.run_list(), seeds.expansion()
        round_note = f"seeds by precision: round {seeds.current.number}" + (
            f"; finished ({seeds.stop})" if seeds.finished else ""
        )
    todo, done, failed = classify(expansion, store, records, retry_failed=retry_failed)
    todo, reused = reused_elsewhere(expansion, store, todo)
    done += sum(reused.values())
    basis = measurements(expansion, records, campaign_prior(campaign)[0])
    costs: dict[str, Costed] = {}
    runs: list[tuple[float, float, float, bool]] = []  # (seconds, low, high, cost model?)
    per_point: dict[int, tuple[str, float, float, float, str]] = {}
    # a run that continues a finished shorter run of its trajectory (t_final grew) does only
    # the rest of its time: priced at that fraction of a whole run's cost
    continuing = continued_runs(expansion, todo, records)
    setting = campaign.numerics.get("resolution")
    rule = read_rule(setting) if is_rule(setting) else None  # resolution: auto
    for i in todo:
        point = expansion.run(i).point
        if id(point) not in per_point:
            label = point_label(point)
            model = point_seconds(point.parameters, point.numerics)
            per_point[id(point)] = (label, *basis.cost(point, label, model))
        label, est, lo, hi, why = per_point[id(point)]
        if i in continuing:
            rest = max(0.0, 1.0 - continuing[i][1] / point.numerics.t_final)
            est, lo, hi = est * rest, lo * rest, hi * rest
            why = f"{why}; the rest of a run from t = {continuing[i][1]:g}"
        runs.append((est, lo, hi, why.startswith("cost model")))
        shown = label
        if rule is not None:  # each point's grid, and whether the cap holds it below the rule
            held = rule.capped(point.parameters.K, point.parameters.A0)
            shown += f", {point.numerics.resolution}^2" + (" (held at the cap)" if held else "")
        entry = costs.setdefault(label, Costed(shown, 0, est, lo, hi, why))
        entry.runs += 1
    workers, where = concurrency(campaign.execution)
    local = local_worker_count(campaign.execution.__class__())
    load, cores = machine_load() if load_cores is None else load_cores
    here = campaign.execution.mode == "local"
    if started is not None and here:  # the load average still counts our own workers
        load = max(load - workers, 0.0)
    stretch = slowdown(workers if here else 1, load, cores)
    local_stretch = slowdown(local, load, cores)
    modelled = any(r[3] for r in runs)

    def own_time(slow: float) -> float:
        """The driver's own wall time still to come (none without runs to do)."""
        return max(driver_overhead(slow) - (started or 0.0), 0.0) if todo else 0.0

    def walls(w: int, slow: float) -> tuple[float, float, float]:
        est, lo, hi = ([r[k] * (slow if r[3] else 1.0) for r in runs] for k in range(3))
        return makespan(est, w), makespan(lo, w), makespan(hi, w)

    n = len(basis.measured)
    text = "no finished runs"
    if n:
        seconds = [m[3] for m in basis.measured]
        text = (
            f"from {n} finished run{'s' if n > 1 else ''} of this campaign (run times "
            f"{fmt_seconds(min(seconds))} to {fmt_seconds(max(seconds))}, median "
            f"{fmt_seconds(float(np.median(seconds)))})"
        )
    model_text = (
        "cost model (sweep/cost/model.py, calibrated on a 2-core VM: benchmarks/cost_model.json)"
    )
    from_prior = sum(1 for c in costs.values() if c.basis.startswith("the prior"))
    if from_prior and basis.prior is not None:
        text += (
            "; "
            f"{from_prior} point(s) at the measured run times of the {basis.prior.label} "
            "(on the machine that ran it)"
        )
        if not n and any(c.basis == "cost model" for c in costs.values()):
            text += f"; the other points by the {model_text}"
    elif not n:
        text = model_text.replace("cost model", "cost model, no finished runs", 1)
    if campaign.refine is not None and not ref.finished:
        later = refine_rounds(
            campaign,
            ref.current.number,
            ref.n_runs,
            [*(r[0] for r in runs), *(m[3] for m in basis.measured)],
            workers,
            {(point_key(run.point.coords), run.seed) for run in expansion},
        )
    elif campaign.refine is None and campaign.precision is not None and not seeds.finished:
        # (with refine: too, the refinement's replay holds the seed rounds: forecast above)
        later = precision_rounds(
            campaign,
            seeds,
            lambda point: basis.cost(
                point,
                point_label(point),
                point_seconds(point.parameters, point.numerics),
            )[0],
            workers,
        )
    changed = campaign_changes(campaign, store, dense, records)
    return Estimate(
        campaign=campaign.name,
        folder=str(store.root),
        total=len(expansion),
        done=done,
        failed=failed,
        to_do=len(todo),
        measured=n,
        basis=text,
        workers=workers,
        where=where,
        local_workers=local,
        cpu=(sum(r[0] for r in runs), sum(r[1] for r in runs), sum(r[2] for r in runs)),
        wall=walls(workers, stretch if here else 1.0),
        local_wall=walls(local, local_stretch),
        longest=max((r[0] * (stretch if r[3] and here else 1.0) for r in runs), default=0.0),
        overhead=own_time(stretch),
        local_overhead=own_time(local_stretch),
        load=load,
        cores=cores,
        stretch=stretch,
        local_stretch=local_stretch,
        modelled=modelled,
        local=here,
        points=list(costs.values()),
        later=later,
        round_note=round_note,
        changes=[] if changed is None else changed.lines(),
        reused=reused,
    )
