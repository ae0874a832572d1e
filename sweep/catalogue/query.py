"""Reading the catalogue: runs filtered by campaign, status and ranges of any parameter,
numeric, scalar or swept value (the key/value table ``run_values``), the campaigns with their
counts, and what changed since a ``seq``.

A condition is ``key=value`` (a number matches within a relative 1e-9, a word exactly) or
``key=low:high`` (either end may be left out; both ends included); ``key`` is one of the run's
own numbers (``seed``, ``t_final``, ``end_state``, ``wall_time``), a bare name
(``K``, ``resolution``, ``alpha_minus_B``: any space) or ``space.key``
(``parameters.K``, ``numerics.resolution``, ``scalars.sigma2_S``, ``coords.alpha_minus_B``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa

from .schema import tables as t

if TYPE_CHECKING:
    import pandas as pd

#: relative tolerance of ``key=number``
REL_TOL = 1e-9
#: the columns of the runs table every query returns first
RUN_COLUMNS = (
    "run_id",
    "status",
    "reason",
    "seed",
    "t_final",
    "end_state",
    "wall_time",
    "started",
    "finished",
    "trajectory_id",
    "path",
    "source",
    "code_version",
    "seq",
)


@dataclass(frozen=True)
class Condition:
    """One condition on a key: ``equal`` (a number or a word) or a range ``low``-``high``."""

    key: str
    equal: float | str | None = None
    low: float | None = None
    high: float | None = None

    def __post_init__(self) -> None:
        space, dot, _ = self.key.rpartition(".")
        if dot and space not in t.SPACES:
            raise ValueError(f"{self.key!r}: the space is one of {', '.join(t.SPACES)}")

    @classmethod
    def of(cls, key: str, value: Any) -> Condition:
        """From a Python value: a number or word (equal), a ``(low, high)`` pair (either
        None), or a text ``"low:high"`` / ``"value"`` as the command line gives it."""
        if isinstance(value, (tuple, list)) and len(value) == 2:
            lo, hi = value
            return cls(
                key, low=None if lo is None else float(lo), high=None if hi is None else float(hi)
            )
        if isinstance(value, str):
            return parse_condition(f"{key}={value}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{key}: a number, a word or a (low, high) pair, not {value!r}")
        return cls(key, equal=float(value))


def _float(text: str, what: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise ValueError(f"{what}: {text!r} is not a number") from None
    if math.isnan(x):
        raise ValueError(f"{what}: NaN matches nothing")
    return x


def parse_condition(text: str) -> Condition:
    """``KEY=VALUE`` or ``KEY=LOW:HIGH`` (see the module docstring); ValueError if not."""
    key, sep, value = text.partition("=")
    key, value = key.strip(), value.strip()
    if not sep or not key or not value:
        raise ValueError(
            f"{text!r}: expected KEY=VALUE or KEY=LOW:HIGH (e.g. K=1e-5, alpha_minus_B=0.5:0.7)"
        )
    if ":" in value:
        lo, _, hi = value.partition(":")
        low = _float(lo, text) if lo.strip() else None
        high = _float(hi, text) if hi.strip() else None
        if low is not None and high is not None and low > high:
            raise ValueError(f"{text!r}: the range's low end is above its high end")
        return Condition(key, low=low, high=high)
    try:
        number = float(value)
    except ValueError:
        return Condition(key, equal=value)  # a word
    return Condition(key, equal=_float(str(number), text))


#: the runs table's own numeric columns a condition may name (``seed=0:4``, ``t_final=300``)
RUN_NUMBERS = ("seed", "t_final", "end_state", "wall_time")


def _number_clause(column: sa.ColumnElement[Any], cond: Condition) -> sa.ColumnElement[bool]:
    if isinstance(cond.equal, str):
        return sa.false()
    if cond.equal is not None:
        tol = abs(cond.equal) * REL_TOL
        return column.between(cond.equal - tol, cond.equal + tol)
    parts: list[sa.ColumnElement[bool]] = [column.is_not(None)]
    if cond.low is not None:
        parts.append(column >= cond.low)
    if cond.high is not None:
        parts.append(column <= cond.high)
    return sa.and_(*parts)


def _clause(cond: Condition) -> sa.ColumnElement[bool]:
    """The run's own column (:data:`RUN_NUMBERS`), else the run is among those with a value
    row that meets ``cond``."""
    if cond.key in RUN_NUMBERS:
        return _number_clause(t.runs.c[cond.key], cond)
    v = t.run_values
    space, _, key = cond.key.rpartition(".")
    parts = [v.c.key == key]
    if space:
        parts.append(v.c.space == space)
    if isinstance(cond.equal, str):
        parts.append(v.c.text_value == cond.equal)
    else:
        parts.append(_number_clause(v.c.num_value, cond))
    # the run ids that meet it, through the (key, value) index: one range scan per condition
    return t.runs.c.run_id.in_(sa.select(v.c.run_id).where(*parts))


def conditions(where: Mapping[str, Any] | Sequence[Condition] | None) -> list[Condition]:
    if where is None:
        return []
    if isinstance(where, Mapping):
        return [Condition.of(k, v) for k, v in where.items()]
    return list(where)


def select_runs(
    campaign: str | None = None,
    where: Mapping[str, Any] | Sequence[Condition] | None = None,
    status: str | None = None,
    since_seq: int | None = None,
) -> sa.Select[Any]:
    """The SELECT of the runs meeting every filter (ordered by ``seq``)."""
    cols = [t.runs.c[c] for c in RUN_COLUMNS]
    cols += [t.runs.c.parameters, t.runs.c.numerics, t.runs.c.scalars]
    stmt = sa.select(*cols)
    if campaign is not None:
        member = t.campaign_runs
        stmt = (
            stmt.add_columns(member.c.campaign, member.c.origin, member.c.coords)
            .join(member, member.c.run_id == t.runs.c.run_id)
            .where(member.c.campaign == campaign)
        )
    if status is not None:
        stmt = stmt.where(t.runs.c.status == status)
    if since_seq is not None:
        stmt = stmt.where(t.runs.c.seq > since_seq)
    for cond in conditions(where):
        stmt = stmt.where(_clause(cond))
    return stmt.order_by(t.runs.c.seq)


def memberships(conn: sa.Connection, run_ids: Sequence[str]) -> dict[str, list[dict[str, Any]]]:
    """run_id -> its campaigns (``campaign``, ``origin``, ``coords``)."""
    out: dict[str, list[dict[str, Any]]] = {}
    m = t.campaign_runs
    for start in range(0, len(run_ids), 500):
        chunk = list(run_ids[start : start + 500])
        rows = conn.execute(
            sa.select(m.c.run_id, m.c.campaign, m.c.origin, m.c.coords)
            .where(m.c.run_id.in_(chunk))
            .order_by(m.c.campaign)
        )
        for rid, name, origin, coords in rows:
            out.setdefault(rid, []).append({"campaign": name, "origin": origin, "coords": coords})
    return out


def frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """The runs as a table: the run columns, ``campaign(s)``, then every swept value,
    parameter, numeric and scalar as a column of its bare name (a name already taken by an
    earlier column gets its space as a prefix: ``numerics.seed``)."""
    import pandas as pd

    flat = []
    for row in rows:
        out = {
            k: v for k, v in row.items() if k not in ("parameters", "numerics", "scalars", "coords")
        }
        for space in ("coords", "parameters", "numerics", "scalars"):
            for key, value in (row.get(space) or {}).items():
                name = key if key not in out else f"{space}.{key}"
                if isinstance(value, list):
                    value = tuple(value)
                out[name] = value
        flat.append(out)
    df = pd.DataFrame(flat)
    if df.empty:
        df = pd.DataFrame(columns=[*RUN_COLUMNS, "campaigns"])
    return df


def campaign_counts() -> sa.Select[Any]:
    """Each campaign with its counts of runs (all, ok, failed, made, reused), read from
    ``campaign_summary``: one row per campaign, whatever the number of runs."""
    c, s = t.campaigns, t.campaign_summary
    return (
        sa.select(
            c.c.name,
            c.c.folder,
            c.c.campaign_sha256,
            c.c.first_seen,
            c.c.last_seen,
            *(
                sa.func.coalesce(s.c[k], 0).label(k)
                for k in ("runs", "ok", "failed", "made", "reused")
            ),
        )
        .select_from(c.outerjoin(s, s.c.campaign == c.c.name))
        .order_by(c.c.name)
    )


def recount_campaigns() -> sa.Select[Any]:
    """:func:`campaign_counts` counted from every run (what ``campaign_summary`` must hold)."""
    c, m, r = t.campaigns, t.campaign_runs, t.runs
    ok = sa.func.sum(sa.case((r.c.status == "ok", 1), else_=0))
    failed = sa.func.sum(sa.case((r.c.status != "ok", 1), else_=0))
    made = sa.func.sum(sa.case((m.c.origin == "made", 1), else_=0))
    reused = sa.func.sum(sa.case((m.c.origin == "reused", 1), else_=0))
    return (
        sa.select(
            c.c.name,
            c.c.folder,
            c.c.campaign_sha256,
            c.c.first_seen,
            c.c.last_seen,
            sa.func.count(m.c.run_id).label("runs"),
            sa.func.coalesce(ok, 0).label("ok"),
            sa.func.coalesce(failed, 0).label("failed"),
            sa.func.coalesce(made, 0).label("made"),
            sa.func.coalesce(reused, 0).label("reused"),
        )
        .select_from(
            c.outerjoin(m, m.c.campaign == c.c.name).outerjoin(r, r.c.run_id == m.c.run_id)
        )
        .group_by(c.c.name, c.c.folder, c.c.campaign_sha256, c.c.first_seen, c.c.last_seen)
        .order_by(c.c.name)
    )
