"""The cost before launch as data and as text: what
:func:`nematic_solids.sweep.cost.estimate.estimate` returns (:class:`Estimate`, the points'
:class:`Costed` runs, the :class:`LaterRounds`) and the lines ``nematic run --dry-run`` and
``validate --estimate`` print (:func:`lines`)."""

from __future__ import annotations

from dataclasses import dataclass, field

#: points listed one per line (the rest are counted)
MAX_POINTS = 20


@dataclass
class Costed:
    """The runs to do at one point with their estimated seconds each (and the range)."""

    label: str
    runs: int
    seconds: float
    low: float
    high: float
    basis: str


@dataclass
class Expected:
    """What the later rounds are expected to cost, where there are data for it
    (:mod:`nematic_solids.sweep.cost.later`): ``basis`` says what it stands on; ``unknown_points``
    points without data are left out of it (their ``unknown_runs`` are in the bound only)."""

    runs: int
    cpu: float
    wall: float
    basis: str
    unknown_points: int = 0
    unknown_runs: int = 0


@dataclass
class LaterRounds:
    """The rounds after the current one (seeds by precision, refinement): the bound (at most
    ``rounds`` more rounds, ``runs`` more runs, their ``cpu`` and ``wall`` seconds) and the
    :class:`Expected` value where there are data, else ``None`` with the reason in ``note``."""

    rounds: int
    runs: int
    cpu: float
    wall: float
    expected: Expected | None = None
    note: str = ""


@dataclass
class Estimate:
    campaign: str
    folder: str
    total: int
    done: int
    failed: int
    to_do: int
    measured: int
    basis: str
    workers: int
    where: str
    local_workers: int
    #: (estimate, low, high) in seconds: the sum of the run times to do, and the makespan of
    #: the runs (without the driver's :attr:`overhead`) on :attr:`workers` and on
    #: :attr:`local_workers`
    cpu: tuple[float, float, float]
    wall: tuple[float, float, float]
    local_wall: tuple[float, float, float]
    longest: float
    #: the driver's own wall time (:data:`DRIVER_OVERHEAD`) on :attr:`workers` and on
    #: :attr:`local_workers` at the machine's load
    overhead: float
    local_overhead: float
    #: this machine's 1-minute load average and cores when the estimate was made, and how
    #: much longer a run and the driver take here than on a free core (:func:`slowdown`), on
    #: :attr:`workers` (1 off a local cluster) and on :attr:`local_workers`
    load: float = 0.0
    cores: int = 1
    stretch: float = 1.0
    local_stretch: float = 1.0
    #: whether some runs are costed by the cost model alone (stretched by the load)
    modelled: bool = False
    #: whether the runs go on this machine (a local cluster)
    local: bool = True
    points: list[Costed] = field(default_factory=list)
    later: LaterRounds | None = None
    round_note: str = ""
    #: what changed since the results were made (:mod:`nematic_solids.sweep.outputs.changes`), as
    #: lines
    changes: list[str] = field(default_factory=list)
    #: runs to do that other campaigns of the results root finished (taken in place, not
    #: run): campaign -> how many (:mod:`nematic_solids.sweep.catalogue.reuse`)
    reused: dict[str, int] = field(default_factory=dict)


def fmt_seconds(seconds: float) -> str:
    """12.3 s, 4 min 05 s, 2 h 03 min."""
    if seconds < 60:
        return f"{seconds:.2g} s" if seconds < 10 else f"{seconds:.0f} s"
    if seconds < 3600:
        m, s = divmod(round(seconds), 60)
        return f"{m} min {s:02d} s"
    h, m = divmod(round(seconds / 60), 60)
    return f"{h} h {m:02d} min"


def fmt_hours(seconds: float) -> str:
    """CPU seconds as CPU-hours: 0.38 CPU-h."""
    return f"{seconds / 3600:.2g} CPU-h"


def _wall_line(
    e: Estimate, workers: int, where: str, runs: tuple[float, float, float], overhead: float
) -> str:
    total = [r + overhead for r in runs]
    return (
        f"wall time: {fmt_seconds(total[0])} on {workers} worker(s) ({where}; 10-90 %: "
        f"{fmt_seconds(total[1])} to {fmt_seconds(total[2])}): "
        f"{fmt_seconds(runs[0])} of runs (the longest {fmt_seconds(e.longest)}) + about "
        f"{fmt_seconds(overhead)} of the driver's own (cluster start, warm-up, "
        "phase.nc, figures, report)"
    )


def lines(e: Estimate, *, brief: bool = False) -> list[str]:
    """The estimate as plain lines (``nematic run --dry-run``, ``validate --estimate``);
    ``brief``: without the runs to do point by point."""
    out = [
        f"runs: {e.total} planned, {e.done} done, {e.failed} failed (not redone), "
        f"{e.to_do} to do" + (f"; {e.round_note}" if e.round_note else "")
    ]
    for c in [] if brief else e.points[:MAX_POINTS]:
        out.append(
            f"  {c.label or '(the one point)'}: {c.runs} to do, "
            f"{fmt_seconds(c.seconds)} each ({fmt_seconds(c.low)} to "
            f"{fmt_seconds(c.high)}; {c.basis})"
        )
    if len(e.points) > MAX_POINTS and not brief:
        rest = e.points[MAX_POINTS:]
        out.append(
            f"  ... and {len(rest)} more point(s) with {sum(c.runs for c in rest)} run(s) to do"
        )
    if e.reused:
        from ..catalogue.reuse import reuse_line

        out.append(reuse_line(e.reused))
    out.append(f"basis: {e.basis}")
    if e.to_do == 0:
        out.append(
            "nothing to do" + ("; --retry-failed redoes the failed runs" if e.failed else "")
        )
    else:
        out.append(
            f"CPU time: {fmt_seconds(e.cpu[0])} = {fmt_hours(e.cpu[0])} (10-90 %: "
            f"{fmt_seconds(e.cpu[1])} to {fmt_seconds(e.cpu[2])}), one core per run"
        )
        out.append(_wall_line(e, e.workers, e.where, e.wall, e.overhead))
        if e.stretch > 1.0 and not e.local:
            out.append(
                f"  this machine: load average {e.load:.1f} on {e.cores} core(s): "
                f"part of the driver's time is stretched {e.stretch:.2g}x"
            )
        elif e.stretch > 1.0:
            what = (
                "the cost model's run times (and part of the driver's time) are stretched "
                f"{e.stretch:.2g}x; "
                if e.modelled
                else "part of the driver's time is stretched as much; "
            )
            out.append(
                f"  this machine: load average {e.load:.1f} on {e.cores} core(s), so "
                f"each worker gets about {100 / e.stretch:.0f} % of a core: {what}"
                "measured run times are taken as they are"
            )
        if e.local_workers != e.workers:
            out.append(
                "  "
                + _wall_line(
                    e,
                    e.local_workers,
                    "this machine's local cluster",
                    e.local_wall,
                    e.local_overhead,
                )
            )
    if e.later is not None:
        out.extend(later_lines(e.later, e.workers))
    return out


def later_lines(later: LaterRounds, workers: int) -> list[str]:
    """The later rounds as lines: the bound, then the expected value and its basis (or why
    there is none)."""
    out = [
        f"later rounds: at most {later.runs} more runs in at most {later.rounds} more "
        f"round(s) (the bound: every run the rules allow), at most {fmt_hours(later.cpu)} "
        f"({fmt_seconds(later.cpu)}) and {fmt_seconds(later.wall)} wall on {workers} "
        "worker(s)"
    ]
    e = later.expected
    if e is not None:
        unknown = (
            f"; {e.unknown_points} point(s) without data are in the bound only (up to "
            f"{e.unknown_runs} runs)"
            if e.unknown_points
            else ""
        )
        out.append(
            f"  expected: about {e.runs} more runs, {fmt_hours(e.cpu)} ({fmt_seconds(e.cpu)}) "
            f"and {fmt_seconds(e.wall)} wall ({e.basis}{unknown})"
        )
    if later.note:
        out.append(f"  {later.note}")
    return out
