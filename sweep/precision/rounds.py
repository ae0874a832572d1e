"""Seeds by precision: the rounds replayed from the results folder, the plan file, and the
expansion for ``phase.nc`` and ``nematic status``.

:func:`replay` rebuilds every round from the run files: round 0 runs the campaign's first
``initial`` seeds at every grid point; while every run planned so far has finished (a record
whose file is intact), each point is decided from its seeds' values
(:func:`nematic_solids.sweep.precision.decide.decide`) and the next round gives every undecided
point the next ``add`` seeds, in the campaign's order. So a killed driver resumes to the same
decisions, and the plan file ``precision.json`` (written atomically by the driver) is never read
back to decide anything. The object :func:`replay` returns is driven by
:func:`nematic_solids.sweep.refine.driver.drive_rounds` like an adaptive campaign's rounds.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..campaign import Campaign, PrecisionSpec
from ..expand import Expansion, expand
from ..files import atomic_write_text, dumps
from ..refine.runs import Outcomes, RunList
from ..store import CampaignStore, Record
from .decide import DECISIONS, Decision, counts_text, decide, next_count, rounds_bound

if TYPE_CHECKING:
    import xarray as xr

PLAN_FILE = "precision.json"
PLAN_VERSION = 1
#: Points listed per round in the driver's messages (the plan file has them all).
MAX_LINES = 12


@dataclass(frozen=True)
class SeedRound:
    """One round: ``runs`` as (point, seed position) and why each point of it got seeds."""

    number: int
    runs: tuple[tuple[int, int], ...]
    why: Mapping[int, str] = field(default_factory=dict)

    @property
    def points(self) -> list[int]:
        return list(dict.fromkeys(p for p, _ in self.runs))


@dataclass
class SeedPlan:
    """The rounds of a campaign with seeds by precision as the results folder gives them."""

    campaign: Campaign
    grid: Expansion
    rounds: list[SeedRound]
    #: run index (in :attr:`grid`) -> its outcome and class values (None: not finished)
    outcomes: dict[int, float | None]
    classes: dict[int, tuple[float, ...] | None]
    #: each point's latest decision ("pending" while its seeds run)
    decisions: list[Decision]
    finished: bool = False
    stop: str = ""

    @property
    def spec(self) -> PrecisionSpec:
        assert self.campaign.precision is not None
        return self.campaign.precision

    @property
    def current(self) -> SeedRound:
        return self.rounds[-1]

    @property
    def cap(self) -> int:
        return len(self.campaign.seeds)

    def indices(self) -> list[int]:
        return [p * self.cap + j for rnd in self.rounds for p, j in rnd.runs]

    @property
    def n_runs(self) -> int:
        return sum(len(r.runs) for r in self.rounds)

    @property
    def pending(self) -> list[int]:
        return [i for i in self.indices() if self.outcomes.get(i) is None]

    def run_list(self) -> RunList:
        return RunList(self.campaign, [self.grid.run(i) for i in self.indices()])

    def expansion(self) -> PrecisionExpansion:
        return PrecisionExpansion(self)

    def counts(self) -> Counter[str]:
        return Counter(d.state for d in self.decisions)

    def counts_text(self) -> str:
        return counts_text(d.state for d in self.decisions)

    def run_bound(self) -> int:
        return self.campaign.n_runs

    def to_dict(self) -> dict[str, Any]:
        """The plan file's content: every point with its seeds run and decision, and the
        rounds with their runs (run_id, seed, state, outcome)."""
        points = []
        for p, d in enumerate(self.decisions):
            points.append(
                {
                    "coords": self.grid.points[p].coords,
                    "seeds_run": d.n,
                    "decision": d.state,
                    "why": d.why,
                    "mean": d.mean,
                    "width": d.width,
                }
            )
        rounds = []
        for rnd in self.rounds:
            runs = []
            for p, j in rnd.runs:
                i = p * self.cap + j
                value = self.outcomes.get(i)
                runs.append(
                    {
                        "coords": self.grid.points[p].coords,
                        "seed": self.grid.seeds[j],
                        "run_id": self.grid.run_ids[i],
                        "why": rnd.why.get(p, ""),
                        "state": "pending" if value is None else "done",
                        "outcome": value,
                    }
                )
            rounds.append(
                {
                    "round": rnd.number,
                    "n_runs": len(rnd.runs),
                    "points": len(rnd.points),
                    "runs": runs,
                }
            )
        return {
            "version": PLAN_VERSION,
            "campaign": self.campaign.name,
            "precision": self.spec.to_dict(),
            "seeds": list(self.campaign.seeds),
            "finished": self.finished,
            "stop": self.stop,
            "n_runs": self.n_runs,
            "n_pending": len(self.pending),
            "run_bound": self.run_bound(),
            "decisions": dict(self.counts()),
            "points": points,
            "rounds": rounds,
        }

    def status_dict(self) -> dict[str, Any]:
        """The plan for ``nematic status --json`` (rounds without their runs)."""
        plan = self.to_dict()
        for rnd in plan["rounds"]:
            rnd["pending"] = sum(1 for r in rnd["runs"] if r["state"] == "pending")
            del rnd["runs"]
        del plan["points"]
        return {"precision": plan}

    def status_lines(self) -> list[str]:
        """What ``nematic status`` adds: the rule, one line per round, the decisions."""
        out = [spec_line(self.campaign)]
        for rnd in self.rounds:
            pending = sum(1 for p, j in rnd.runs if self.outcomes.get(p * self.cap + j) is None)
            out.append(
                f"round {rnd.number}: {len(rnd.runs)} runs at {len(rnd.points)} "
                "point(s); " + (f"{pending} pending" if pending else "done")
            )
        state = "finished" if self.finished else f"round {self.current.number} in progress"
        out.append(
            f"decisions: {self.counts_text()}; {state}; {self.n_runs} runs planned so "
            f"far, at most {self.run_bound()}"
        )
        return out

    def round_lines(self, number: int) -> list[str]:
        """A round's plan as the driver prints it."""
        rnd = self.rounds[number]
        if number == 0:
            return [
                f"round 0: {len(rnd.points)} points x {self.spec.initial} seed(s), "
                f"{len(rnd.runs)} runs"
            ]
        out = [
            f"round {number}: {len(rnd.runs)} runs: {len(rnd.points)} undecided point(s) "
            "get more seeds"
        ]
        for k, p in enumerate(rnd.points):
            if k == MAX_LINES:
                out.append(
                    f"  ... and {len(rnd.points) - MAX_LINES} more ({PLAN_FILE} lists every run)"
                )
                break
            seeds = [self.grid.seeds[j] for q, j in rnd.runs if q == p]
            where = ", ".join(
                f"{a}={v:g}" if isinstance(v, float) else f"{a}={v}"
                for a, v in self.grid.points[p].coords.items()
            )
            out.append(f"  {where}: seeds {', '.join(map(str, seeds))}: {rnd.why.get(p, '')}")
        return out


def spec_line(campaign: Campaign) -> str:
    """The section in one line."""
    s = campaign.precision
    assert s is not None
    rules = []
    if s.width is not None:
        rules.append(
            f"the {s.confidence:g} interval of the seed mean of {s.observable} "
            f"narrower than {s.width:g}" + (" x |mean|" if s.relative else "")
        )
    if s.unanimous is not None:
        rules.append(
            f"{s.unanimous}+ seeds of one pattern class (sigma2_S above "
            f"{s.patterned_above:g} or not)"
            if not s.classes
            else f"{s.unanimous}+ seeds of one class (which of "
            + ", ".join(f"{t.observable} > {t.above:g}" for t in s.classes)
            + " hold)"
        )
    return (
        "seeds by precision: a point stops at "
        + " or ".join(rules)
        + f"; {s.initial} seed(s) first, +{s.add} per round, up to {len(campaign.seeds)}"
    )


def validation_lines(campaign: Campaign) -> list[str]:
    """What ``nematic validate`` prints: the rule, round 0 and the bound on the runs."""
    s = campaign.precision
    assert s is not None
    cap = len(campaign.seeds)
    first = campaign.n_points * min(s.initial, cap)
    return [
        spec_line(campaign),
        f"round 0: {campaign.n_points} points x {min(s.initial, cap)} seed(s) = {first} "
        "runs; later rounds add seeds to the undecided points",
        f"runs: at least {first}, at most {campaign.n_runs} (every point to the cap), in "
        f"at most {rounds_bound(s, cap)} round(s)",
    ]


def replay(
    campaign: Campaign, store: CampaignStore, records: Mapping[str, Record] | None = None
) -> SeedPlan:
    """The rounds of ``campaign`` from the run records and files in ``store`` (see the
    module docstring): a pure function of the folder's run files."""
    spec = campaign.precision
    if spec is None:
        raise ValueError(f"campaign {campaign.name} has no precision: section")
    grid = expand(campaign)
    cap = len(campaign.seeds)
    value = Outcomes(store, spec.source, records)
    sources = [t.source for t in spec.thresholds] if spec.unanimous is not None else []
    n_points = len(grid.points)
    count = [min(spec.initial, cap)] * n_points
    first = SeedRound(
        0,
        tuple((p, j) for p in range(n_points) for j in range(count[0])),
        {p: "first seeds" for p in range(n_points)},
    )
    plan = SeedPlan(campaign, grid, [first], {}, {}, [Decision("pending", 0, "not run")] * n_points)
    while True:
        rnd = plan.current
        missing = False
        for p, j in rnd.runs:
            i = p * cap + j
            rid = grid.run_ids[i]
            plan.outcomes[i] = value(rid)
            row = value.row(rid, sources)
            plan.classes[i] = None if row is None else tuple(row[k] for k in sources)
            missing = missing or plan.outcomes[i] is None or plan.classes[i] is None
        for p in rnd.points:
            if missing:
                plan.decisions[p] = Decision("pending", count[p], "seeds running")
                continue
            idx = range(p * cap, p * cap + count[p])
            plan.decisions[p] = decide(
                spec, [_f(plan.outcomes[i]) for i in idx], [plan.classes[i] or () for i in idx], cap
            )
        if missing:
            return plan
        runs: list[tuple[int, int]] = []
        why: dict[int, str] = {}
        for p in rnd.points:
            n = next_count(spec, plan.decisions[p], cap)
            if n > count[p]:
                runs.extend((p, j) for j in range(count[p], n))
                why[p] = f"undecided after {count[p]} seeds: {plan.decisions[p].why}"
                count[p] = n
        if not runs:
            plan.finished = True
            plan.stop = f"every point decided ({plan.counts_text()})"
            return plan
        plan.rounds.append(SeedRound(rnd.number + 1, tuple(runs), why))


def _f(v: float | None) -> float:
    return np.nan if v is None else float(v)


def write_plan(store: CampaignStore, plan: SeedPlan) -> None:
    """Write ``precision.json`` atomically."""
    atomic_write_text(store.root / PLAN_FILE, dumps(plan.to_dict()) + "\n")


def read_plan(store: CampaignStore) -> dict[str, Any] | None:
    """The plan file as recorded (``None`` if absent or unreadable): for people and tests."""
    try:
        data = json.loads((store.root / PLAN_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


class PrecisionExpansion(Expansion):
    """The campaign's grid with every seed; :attr:`planned` marks the runs of the rounds.
    ``phase.nc`` holds only the planned runs (NaN elsewhere) and ``nematic status`` counts
    only them; :attr:`refinement` is the plan (``status`` prints its lines)."""

    def __init__(self, plan: SeedPlan):  # the grid is built once, by replay
        grid = plan.grid
        self.campaign, self.seeds, self.points = grid.campaign, grid.seeds, grid.points
        self.run_ids, self.position = grid.run_ids, grid.position
        self.refinement = plan
        self.planned = np.zeros(len(grid.run_ids), dtype=bool)
        self.planned[plan.indices()] = True

    def build_phase(
        self, records: Mapping[str, Record], store: CampaignStore | None = None
    ) -> xr.Dataset:
        return precision_phase(self, records, store)


def precision_phase(
    expansion: PrecisionExpansion, records: Mapping[str, Record], store: CampaignStore | None = None
) -> xr.Dataset:
    """phase.nc with seeds by precision: :func:`nematic_solids.sweep.outputs.aggregate.build_phase`
    from the planned runs' records (NaN for the seeds not run), with ``seed_count`` (seeds run at
    each point, ok or failed) and ``seed_decision`` (a CF flag variable: pending, precise,
    unanimous, cap) over the sweep dims, and the rule and the state as ``precision_*``
    attributes."""
    import xarray as xr

    from ..outputs.aggregate import STATUS_MISSING, build_phase

    plan = expansion.refinement
    planned = {rid for rid, keep in zip(expansion.run_ids, expansion.planned, strict=True) if keep}
    ds = build_phase(expansion, {k: v for k, v in records.items() if k in planned}, store)
    dims = [d.name for d in expansion.campaign.dims]
    ds["seed_count"] = xr.Variable(
        dims,
        (ds["status"] != STATUS_MISSING).sum("seed").values.astype(np.int32),
        {"long_name": "number of seeds run at the point (ok or failed)", "units": "1"},
    )
    flags = np.zeros(expansion.campaign.shape, dtype=np.int8)
    for point, d in zip(expansion.points, plan.decisions, strict=True):
        flags[point.index] = DECISIONS.index(d.state)
    ds["seed_decision"] = xr.Variable(
        dims,
        flags,
        {
            "long_name": "why the point's seeds stopped (seeds by precision)",
            "flag_values": np.arange(len(DECISIONS), dtype=np.int8),
            "flag_meanings": " ".join(DECISIONS),
        },
    )
    ds.attrs.update(
        {
            "precision_spec": json.dumps(plan.spec.to_dict()),
            "precision_observable": plan.spec.observable,
            "precision_rounds": len(plan.rounds),
            "precision_finished": int(plan.finished),
            "precision_stop": plan.stop,
            "precision_runs_planned": plan.n_runs,
        }
    )
    return ds
