"""A refined campaign's rounds, replayed from the results folder.

:func:`replay` rebuilds every round from the files: round 0 is the grid; while every run
planned so far has finished (a record whose file is intact), the next round is planned from
their outcomes (:func:`nematic_solids.sweep.refine.plan.next_round`). It stops at the first round
with runs still to do, when a round plans nothing (converged) or when the rounds are used (with a
``precision:`` section, rounds after the last refinement round only add seeds, until every point is
decided). So a killed driver resumes to the same plan, and two machines with the same run files make
the same plan: the plan file ``refine.json`` records it (written atomically by the driver) but is
never read back to decide anything.

Runs keep the campaign's identity (:mod:`nematic_solids.sweep.identity`): a refined point is a grid
point of a campaign whose refined axes hold it, so a refined value equal to a value of another
campaign's grid is the same run (the same file).

The expansions the rest of :mod:`nematic_solids.sweep` works on: :class:`RunList` (the planned runs,
for :func:`nematic_solids.sweep.run.driver.run_campaign`) and :class:`RefinedExpansion` (the grid
whose refined axes are the sorted union of every value run, with a mask of the planned runs, for
``phase.nc`` and ``nematic status``).
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..campaign import Axis, Campaign, Dim
from ..expand import Expansion, GridPoint, make_point
from ..files import atomic_write_text, dumps
from ..identity import PointHasher
from ..precision.decide import DECISIONS, Decision, counts_text
from ..store import CampaignStore, Record
from .plan import (
    At,
    Line,
    Point,
    Round,
    first_round,
    merge_index,
    next_round,
    points_of,
    refined_dims,
    run_bound,
    values_at,
)
from .runs import Outcomes, RunList
from .seeds import decision, sources
from .stats import Outcome

if TYPE_CHECKING:
    import xarray as xr

log = logging.getLogger(__name__)

#: The plan file in the results folder.
PLAN_FILE = "refine.json"
PLAN_VERSION = 1
RunKey = tuple[Line, At, int]


class RunNamer:
    """Coordinates, model objects and run_ids of points (line, x) of a refined campaign."""

    def __init__(self, campaign: Campaign):
        self.campaign = campaign
        self.ks = refined_dims(campaign)
        self._points: dict[Point, tuple[GridPoint, PointHasher]] = {}

    def coords(self, line: Line, x: At) -> dict[str, Any]:
        out: dict[str, Any] = {}
        it, refined = iter(line), iter(values_at(x))
        for i, d in enumerate(self.campaign.dims):
            if i in self.ks:
                out[d.name] = next(refined)
            else:
                j = next(it)
                for a in d.axes:
                    out[a.name] = a.values[j]
        return out

    def point(self, line: Line, x: At) -> tuple[GridPoint, PointHasher]:
        key = (line, x)
        if key not in self._points:
            index = merge_index(self.ks, line, [-1] * len(self.ks))
            p = make_point(self.campaign, index, self.coords(line, x))
            self._points[key] = (
                p,
                PointHasher(p.parameters.to_dict(), p.numerics.to_dict(), self.campaign.model),
            )
        return self._points[key]

    def run_id(self, line: Line, x: At, seed: int) -> str:
        return self.point(line, x)[1](seed)


# --------------------------------------------------------------------------- replay
@dataclass
class Refinement:
    """The rounds of a refined campaign as the results folder gives them."""

    campaign: Campaign
    rounds: list[Round]
    #: run -> its run_id, and its outcome (None: not finished)
    run_ids: dict[RunKey, str]
    outcomes: dict[RunKey, Outcome | None]
    #: no further round will be planned (converged, or the rounds are used)
    finished: bool = False
    #: why it finished ("converged: ...", "rounds used: ...") or ""
    stop: str = ""
    namer: RunNamer | None = field(default=None, repr=False)
    #: with a precision: section, each point's latest decision ("pending" while its seeds
    #: run)
    decisions: dict[Point, Decision] = field(default_factory=dict)

    @property
    def current(self) -> Round:
        return self.rounds[-1]

    def keys(self) -> Iterator[tuple[Round, RunKey]]:
        for rnd in self.rounds:
            for r in rnd.runs:
                yield rnd, (r.line, r.x, r.seed)

    @property
    def n_runs(self) -> int:
        return sum(len(r.runs) for r in self.rounds)

    @property
    def pending(self) -> list[RunKey]:
        return [k for _, k in self.keys() if self.outcomes.get(k) is None]

    def union_campaign(self) -> Campaign:
        """The campaign whose refined axes hold the sorted union of every value run."""
        ks = refined_dims(self.campaign)
        run = [values_at(x) for _, x in points_of(self.rounds)]
        dims = list(self.campaign.dims)
        for a, k in enumerate(ks):
            values = sorted({v[a] for v in run} | set(dims[k].axes[0].values))
            dims[k] = Dim(dims[k].name, (Axis(dims[k].name, tuple(values)),))
        return dataclasses.replace(self.campaign, dims=tuple(dims))

    def expansion(self) -> RefinedExpansion:
        return RefinedExpansion(self)

    def run_list(self) -> RunList:
        """Every run planned so far, in plan order."""
        dense = self.expansion()
        ids = [self.run_ids[k] for _, k in self.keys()]
        return RunList(dense.campaign, [dense.run(dense.position[rid]) for rid in ids])

    def first_round_of(self) -> dict[Point, int]:
        """The round in which each point was first run."""
        out: dict[Point, int] = {}
        for rnd in self.rounds:
            for r in rnd.runs:
                out.setdefault(r.point, rnd.number)
        return out

    def decisions_text(self) -> str:
        """How many points have each decision (seeds by precision)."""
        return counts_text(d.state for d in self.decisions.values())

    def to_dict(self) -> dict[str, Any]:
        """The plan file's content (the why of every run, its status and outcome; with a
        precision: section every point's seeds and decision)."""
        assert self.campaign.refine is not None
        assert self.namer is not None
        rounds = []
        for rnd in self.rounds:
            runs = []
            for r in rnd.runs:
                key = (r.line, r.x, r.seed)
                value = self.outcomes.get(key)
                runs.append(
                    {
                        "coords": self.namer.coords(r.line, r.x),
                        "seed": r.seed,
                        "run_id": self.run_ids[key],
                        "why": r.why,
                        "state": "pending" if value is None else "done",
                        "outcome": value,
                    }
                )
            rounds.append(
                {
                    "round": rnd.number,
                    "n_runs": len(rnd.runs),
                    "new_points": len(rnd.new_points),
                    "seeded_points": len(rnd.seeded_points),
                    "runs": runs,
                }
            )
        out = {
            "version": PLAN_VERSION,
            "campaign": self.campaign.name,
            "refine": self.campaign.refine.to_dict(),
            "seeds": list(self.campaign.seeds),
            "finished": self.finished,
            "stop": self.stop,
            "n_runs": self.n_runs,
            "n_pending": len(self.pending),
            "run_bound": run_bound(self.campaign),
            "rounds": rounds,
        }
        if self.campaign.precision is not None:
            out["precision"] = self.campaign.precision.to_dict()
            out["points"] = [
                {
                    "coords": self.namer.coords(*point),
                    "seeds_run": d.n,
                    "decision": d.state,
                    "why": d.why,
                    "mean": d.mean,
                    "width": d.width,
                }
                for point, d in self.decisions.items()
            ]
        return out


def replay(
    campaign: Campaign, store: CampaignStore, records: Mapping[str, Record] | None = None
) -> Refinement:
    """The rounds of ``campaign`` from the run records and files in ``store`` (see the
    module docstring). A pure function of the folder's run files."""
    spec = campaign.refine
    if spec is None:
        raise ValueError(f"campaign {campaign.name} has no refine: section")
    namer = RunNamer(campaign)
    needs = sources(campaign)
    outcome = Outcomes(store, spec.source, records)
    ref = Refinement(campaign, [first_round(campaign)], {}, {}, namer=namer)
    values: dict[Point, dict[int, Outcome]] = {}
    while True:
        rnd = ref.current
        missing = False
        for r in rnd.runs:
            key = (r.line, r.x, r.seed)
            rid = ref.run_ids[key] = namer.run_id(r.line, r.x, r.seed)
            value = ref.outcomes[key] = outcome(rid) if needs is None else outcome.row(rid, needs)
            if value is None:
                missing = True
            else:
                values.setdefault(r.point, {})[r.seed] = value
        _decide(ref, values)
        if missing:
            return ref
        refining = rnd.number < spec.rounds
        if not refining and campaign.precision is None:
            ref.finished, ref.stop = True, f"rounds used ({spec.rounds} after the grid)"
            return ref
        nxt = next_round(campaign, rnd.number + 1, values, split=refining)
        if not nxt.runs:
            ref.finished = True
            if campaign.precision is None:
                ref.stop = (
                    "converged: no boundary cell wider than twice the smallest "
                    "spacing, no uncertain point with seeds left"
                )
            else:
                ref.stop = (
                    "converged: no boundary cell wider than twice the smallest spacing"
                    if refining
                    else f"rounds used ({spec.rounds} after the grid)"
                ) + f"; every point's seeds decided ({ref.decisions_text()})"
            return ref
        ref.rounds.append(nxt)


def _decide(ref: Refinement, values: Mapping[Point, Mapping[int, Outcome]]) -> None:
    """Each point's decision by the precision: section (nothing without one): pending while
    a planned seed has not finished."""
    campaign = ref.campaign
    if campaign.precision is None:
        return
    ref.decisions = {}
    for point, seeds in points_of(ref.rounds).items():
        done = values.get(point, {})
        if all(s in done for s in seeds):
            ref.decisions[point] = decision(campaign, [done[s] for s in seeds])
        else:
            ref.decisions[point] = Decision("pending", len(seeds), "seeds running")


def write_plan(store: CampaignStore, ref: Refinement) -> None:
    """Write ``refine.json`` atomically."""
    atomic_write_text(store.root / PLAN_FILE, dumps(ref.to_dict()) + "\n")


def read_plan(store: CampaignStore) -> dict[str, Any] | None:
    """The plan file as recorded (``None`` if absent or unreadable): for people and tests;
    the driver replays the rounds from the run files instead."""
    try:
        data = json.loads((store.root / PLAN_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


# --------------------------------------------------------------------------- expansions
#: seed_decision where a point of the union grid was not run
NOT_RUN = -1


class RefinedExpansion(Expansion):
    """The grid of a refined campaign (its refined axes the sorted union of the values run)
    with every seed; :attr:`planned` marks the runs of the plan. ``phase.nc`` holds only
    the planned runs (NaN elsewhere) and ``nematic status`` counts only them."""

    def __init__(self, refinement: Refinement):
        super().__init__(refinement.union_campaign())
        self.refinement = refinement
        planned = set(refinement.run_ids.values())
        self.planned = np.fromiter(
            (rid in planned for rid in self.run_ids), dtype=bool, count=len(self.run_ids)
        )

    def build_phase(
        self, records: Mapping[str, Record], store: CampaignStore | None = None
    ) -> xr.Dataset:
        """phase.nc's dataset (:func:`refined_phase`), which
        :func:`nematic_solids.sweep.outputs.aggregate.write_phase` asks the expansion for."""
        return refined_phase(self, records, store)


def refined_phase(
    expansion: RefinedExpansion, records: Mapping[str, Record], store: CampaignStore | None = None
) -> xr.Dataset:
    """phase.nc of a refined campaign: :func:`nematic_solids.sweep.outputs.aggregate.build_phase` on
    the union grid from the planned runs' records, with ``seed_count`` (seeds run at each point, ok
    or failed; 0 where the point was not run) and ``refine_round`` (the round that first ran the
    point; -1 where it was not run) over the sweep dims, and the plan's summary as attributes
    (``refine_*``). With a ``precision:`` section also ``seed_decision`` (a CF flag variable:
    not_run, pending, precise, unanimous, cap) and ``precision_*`` attributes."""
    import xarray as xr

    from ..outputs.aggregate import STATUS_MISSING, build_phase

    ref = expansion.refinement
    planned = {rid for rid, keep in zip(expansion.run_ids, expansion.planned, strict=True) if keep}
    ds = build_phase(expansion, {k: v for k, v in records.items() if k in planned}, store)
    sweep_dims = [d.name for d in expansion.campaign.dims]
    ran = ds["status"] != STATUS_MISSING
    count = ran.sum("seed").astype(np.int32)
    ds["seed_count"] = xr.Variable(
        sweep_dims,
        count.values,
        {
            "long_name": "number of seeds run at the point (ok or failed); 0: the point was not "
            "run",
            "units": "1",
        },
    )
    ks = refined_dims(ref.campaign)
    cols = [{x: i for i, x in enumerate(expansion.campaign.dims[k].axes[0].values)} for k in ks]

    def index(line: tuple[int, ...], x: float | tuple[float, ...]) -> tuple[int, ...]:
        return merge_index(ks, line, [col[v] for col, v in zip(cols, values_at(x), strict=True)])

    rounds = np.full(expansion.campaign.shape, -1, dtype=np.int32)
    for (line, x), number in ref.first_round_of().items():
        rounds[index(line, x)] = number
    ds["refine_round"] = xr.Variable(
        sweep_dims,
        rounds,
        {
            "long_name": "refinement round that first ran the point (0: the grid); -1: not run",
            "units": "1",
        },
    )
    spec = ref.campaign.refine
    assert spec is not None
    ds.attrs.update(
        {
            "refine_axis": ", ".join(spec.names),
            "refine_observable": ", ".join(t.observable for t in spec.thresholds)
            or spec.observable,
            "refine_criterion": spec.criterion,
            "refine_rounds": len(ref.rounds),
            "refine_finished": int(ref.finished),
            "refine_stop": ref.stop,
            "refine_runs_planned": ref.n_runs,
            "refine_spec": json.dumps(spec.to_dict()),
        }
    )
    precision = ref.campaign.precision
    if precision is not None:
        flags = np.full(expansion.campaign.shape, NOT_RUN, dtype=np.int8)
        for (line, x), d in ref.decisions.items():
            flags[index(line, x)] = DECISIONS.index(d.state)
        ds["seed_decision"] = xr.Variable(
            sweep_dims,
            flags,
            {
                "long_name": "why the point's seeds stopped (seeds by precision)",
                "flag_values": np.arange(NOT_RUN, len(DECISIONS), dtype=np.int8),
                "flag_meanings": " ".join(("not_run", *DECISIONS)),
            },
        )
        ds.attrs.update(
            {
                "precision_spec": json.dumps(precision.to_dict()),
                "precision_observable": precision.observable,
            }
        )
    return ds


def expansion_for(campaign: Campaign, store: CampaignStore) -> Expansion:
    """What ``status``, ``aggregate`` and the figures work on: the grid (``expand``), or
    for a refined campaign the union grid of its rounds replayed from ``store``."""
    from ..expand import expand

    if campaign.refine is not None:  # with seeds by precision or not
        return replay(campaign, store).expansion()
    if campaign.precision is not None:  # seeds by precision on the grid (sweep/precision)
        from ..precision.rounds import replay as replay_precision

        return replay_precision(campaign, store).expansion()
    return expand(campaign)


def status_dict(refinement: Any) -> dict[str, Any]:
    """The rounds for ``nematic status --json`` (empty for a grid campaign; a campaign with
    seeds by precision gives its own)."""
    if refinement is None:
        return {}
    if hasattr(refinement, "status_dict"):  # seeds by precision (sweep/precision)
        return dict(refinement.status_dict())
    plan = refinement.to_dict()
    for rnd in plan["rounds"]:
        rnd["pending"] = sum(1 for r in rnd["runs"] if r["state"] == "pending")
        del rnd["runs"]
    return {"refine": plan}
