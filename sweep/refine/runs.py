"""What the rounds of an adaptive campaign (``refine:``) or of seeds by precision
(``precision:``) share: the outcome of each run read from the results folder
(:class:`Outcomes`) and the planned runs as an expansion for execution (:class:`RunList`)."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

from ..campaign import Campaign
from ..expand import Expansion, GridPoint, RunSpec
from ..store import RETRYABLE_REASONS, CampaignStore, Record


class Outcomes:
    """The outcome of each run from the results folder: ``None`` while it has not finished
    (no record, a file that is missing or damaged, a result that was not stored), NaN when
    it failed or has no value, else the observable (``source``; :meth:`row` reads several
    run scalars at once)."""

    def __init__(
        self, store: CampaignStore, source: str, records: Mapping[str, Record] | None = None
    ):
        self.store = store
        self.source = source
        self.records = store.scan() if records is None else records
        self._growth: dict[tuple[str, Any], float] = {}

    def __call__(self, run_id: str) -> float | None:
        row = self.row(run_id, (self.source,))
        return None if row is None else row[self.source]

    def row(self, run_id: str, sources: Sequence[str]) -> dict[str, float] | None:
        """The run's value of each of ``sources`` (``None`` while it has not finished)."""
        rec = self.records.get(run_id)
        if rec is None or not self.store.is_complete(run_id, rec):
            return None
        if rec.get("status") != "ok":
            if rec.get("reason") in RETRYABLE_REASONS:
                return None
            return dict.fromkeys(sources, math.nan)
        return {source: self._value(run_id, rec, source) for source in sources}

    def _value(self, run_id: str, rec: Record, source: str) -> float:
        if source == "growth":
            key = (run_id, rec.get("nc_sha256"))
            if key not in self._growth:
                from ..analysis.stability import run_growth  # xarray: not for status

                self._growth[key] = run_growth(self.store.nc_path(run_id))
            return self._growth[key]
        value = (rec.get("scalars") or {}).get(source)
        try:
            return math.nan if value is None else float(value)
        except (TypeError, ValueError):
            return math.nan


class RunList(Expansion):
    """The planned runs of a refined campaign as an :class:`~nematic_solids.sweep.expand.Expansion`
    (what :func:`nematic_solids.sweep.run.todo.plan_runs` and
    :func:`~nematic_solids.sweep.run.driver.run_campaign` take)."""

    def __init__(self, campaign: Campaign, runs: list[RunSpec]):
        self.campaign = campaign
        self.seeds = campaign.seeds
        self._runs = list(runs)
        points: dict[int, GridPoint] = {}
        for r in self._runs:
            points.setdefault(id(r.point), r.point)
        self.points = list(points.values())
        self.run_ids = [r.run_id for r in self._runs]
        self.position = {rid: i for i, rid in enumerate(self.run_ids)}

    def __len__(self) -> int:
        return len(self._runs)

    def run(self, i: int) -> RunSpec:
        return self._runs[i]

    def by_point(self) -> Iterator[tuple[GridPoint, list[str], list[int]]]:
        groups: dict[int, tuple[GridPoint, list[str], list[int]]] = {}
        for r in self._runs:
            group = groups.setdefault(id(r.point), (r.point, [], []))
            group[1].append(r.run_id)
            group[2].append(r.seed)
        return iter(groups.values())
