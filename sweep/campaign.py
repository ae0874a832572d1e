"""A validated campaign as immutable data: :class:`Campaign` and its parts, and the names
and constants they are checked against (the model's parameter and numerics fields, the
largest seed, the significant digits of swept values).

:mod:`nematic_solids.sweep.spec` builds a :class:`Campaign` from YAML; everything else reads it.
This module imports nothing of the parsers.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from .limits import DEFAULT_MAX_RUNS

AMB = "alpha_minus_B"
DEFAULT_MODEL = "nematic"  # a campaign without model: runs it (models.interface.DEFAULT_MODEL)
#: Significant digits kept when normalising swept floats (and in run identity).
SIGNIFICANT_DIGITS = 12
DEFAULT_SEEDS = 50
MAX_SEED = 2**63 - 1
#: Default of ``execution.wait_for_workers``: how long a driver on an external scheduler or a
#: batch cluster waits for its first worker before giving up (seconds).
DEFAULT_WORKER_WAIT = 600.0
#: Default of ``execution.give_up_after``: how long a running campaign goes on without any
#: usable worker (every job ended, the scheduler unreachable) before the driver gives up.
DEFAULT_GIVE_UP = 120.0
#: Default of ``store.checkpoint_every``: a run in progress writes its state every 10 minutes
#: of wall time (what a lost worker, a cancelled or timed-out batch job costs at most per
#: run; a run shorter than that writes none, so short runs pay nothing).
DEFAULT_CHECKPOINT_WALL = 600.0
#: ``execution.cluster.kind`` -> the dask-jobqueue class.
CLUSTER_KINDS = {
    "slurm": "SLURMCluster",
    "pbs": "PBSCluster",
    "sge": "SGECluster",
    "lsf": "LSFCluster",
    "oar": "OARCluster",
    "moab": "MoabCluster",
    "htcondor": "HTCondorCluster",
}


# --------------------------------------------------------------------------- the model's names
def normalise_float(x: float) -> float:
    """Round to :data:`SIGNIFICANT_DIGITS` significant digits: 0.30000000000000004 -> 0.3."""
    y = float(f"{float(x):.{SIGNIFICANT_DIGITS}g}")
    return 0.0 if y == 0 else y


def same_value(a: Any, b: Any) -> bool:
    """Whether two swept values are one: numbers equal to 1e-9 relative (a value read back
    from a netCDF file or a YAML selection against the grid's), anything else equal."""
    if isinstance(a, numbers.Real) and isinstance(b, numbers.Real):  # numpy's too
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-300)
    return bool(a == b)


# --------------------------------------------------------------------------- the parsed objects
@dataclass(frozen=True)
class Axis:
    """One swept name and its (normalised) values."""

    name: str
    values: tuple[Any, ...]


@dataclass(frozen=True)
class Dim:
    """One dimension of the grid: a single axis, or a zip group of axes of equal length.

    A zip group's dimension is named after its first axis; the others are coordinates on it.
    """

    name: str
    axes: tuple[Axis, ...]

    def __len__(self) -> int:
        return len(self.axes[0].values)


@dataclass(frozen=True)
class Product:
    """A fit or figure to produce, with its options."""

    name: str
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class StoreSpec:
    """What the run files keep: ``snapshot_fields`` (``None`` = every snapshot variable the
    model writes) in ``snapshot_dtype``; a rolling checkpoint of a run in progress every
    ``checkpoint_tau`` (simulated time) or ``checkpoint_wall`` (seconds), whichever comes
    first (both infinite: none); and, with ``end_state``, the run's end state, from which a
    longer run continues (:mod:`nematic_solids.sweep.run.continuation`)."""

    snapshot_fields: tuple[str, ...] | None = None
    snapshot_dtype: str = "float64"
    checkpoint_tau: float = math.inf
    checkpoint_wall: float = DEFAULT_CHECKPOINT_WALL
    end_state: bool = True


@dataclass(frozen=True)
class ClusterSpec:
    """A dask-jobqueue cluster: ``kind`` (slurm, pbs, ...), ``jobs`` to start (or ``adapt``
    bounds) and the options passed to the dask-jobqueue class (cores, memory, walltime, ...)."""

    kind: str
    jobs: int = 1
    adapt: tuple[int, int] | None = None
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ExecutionSpec:
    workers: int | None = None
    threads_per_worker: int = 1
    memory_limit: str | None = None
    scheduler: str | None = None
    cluster: ClusterSpec | None = None
    #: seconds to wait for a first worker (scheduler / cluster), or 0 to wait for ever
    wait_for_workers: float = DEFAULT_WORKER_WAIT
    #: seconds without any usable worker (or scheduler) after which a started campaign stops
    give_up_after: float = DEFAULT_GIVE_UP
    #: TLS with per-campaign temporary credentials for a scheduler the driver starts
    tls: bool = True
    #: why the campaign opted out of TLS (required with ``security: {tls: false}``)
    insecure_reason: str | None = None
    #: how a run is computed, "compiled" (:func:`~nematic_solids.model.simulate.run`, up to
    #: ``runs_per_task`` runs per task, None: from the cost model; sweep.run.group) or
    #: "accelerated" (JAX: up to ``batch`` seeds of a point per task, on ``device``; run.batch)
    backend: str = "compiled"
    batch: int = 1
    device: str = "auto"
    runs_per_task: int | None = None

    @property
    def mode(self) -> str:
        """ "local", "scheduler" or "cluster"."""
        if self.scheduler:
            return "scheduler"
        return "cluster" if self.cluster else "local"


#: ``execution.backend``: how runs are computed (not part of a run's identity: the accelerated
#: backend's results agree with the compiled one's to 1e-10 relative, tested)
EXECUTION_BACKENDS = ("compiled", "accelerated")
#: Most seeds in one accelerated task (``execution.batch``), runs in one compiled task.
MAX_BATCH, MAX_RUNS_PER_TASK = 1000, 10_000


def local_worker_count(execution: ExecutionSpec) -> int:
    """The workers of a local cluster: the campaign's ``execution.workers``, else one per
    ``threads_per_worker`` cores of this machine."""
    if execution.workers:
        return execution.workers
    n = os.cpu_count() or 1
    return max(1, n // max(1, execution.threads_per_worker))


@dataclass(frozen=True)
class LimitsSpec:
    """Ceilings checked before the grid is built: ``max_runs`` (runs = product of the axis
    lengths x seeds) and ``run_memory`` (bytes one run may use; default: what one worker
    has, see ``sweep.spec.run_memory_limit``)."""

    max_runs: int = DEFAULT_MAX_RUNS
    run_memory: int | None = None


#: Defaults of the ``refine:`` section (an adaptive campaign, :mod:`nematic_solids.sweep.refine`).
DEFAULT_ROUNDS = 4
DEFAULT_FRACTION = (0.1, 0.9)
DEFAULT_JUMP = 10.0
DEFAULT_MAX_WIDTH = 0.6
DEFAULT_CONFIDENCE = 0.9


@dataclass(frozen=True)
class RefinedAxis:
    """One refined axis of a ``refine:`` section: a cell is split only while both halves are
    at least ``min_spacing`` wide; on a ``log`` axis the midpoint is geometric and the
    spacing is in decades."""

    name: str
    min_spacing: float
    log: bool = False


@dataclass(frozen=True)
class Threshold:
    """One part of a run's class: whether ``observable`` (read from the run scalar
    ``source``) is above ``above``."""

    observable: str
    source: str
    above: float


@dataclass(frozen=True)
class RefineSpec:
    """A validated ``refine:`` section (:mod:`nematic_solids.sweep.spec.refine`).

    ``axes`` are the refined axes in the campaign's order of dims. ``source`` is the run
    scalar ``observable`` is read from (``sigma2_S_final`` for ``sigma2_S``), or ``growth``;
    with ``classes`` (several observables) they are the first class's. ``initial`` / ``add``
    are seed counts: a point gets the campaign's first ``initial`` seeds, then ``add`` more
    per round while it is uncertain, up to all of the campaign's seeds (with a
    ``precision:`` section its rules decide the seeds instead)."""

    axes: tuple[RefinedAxis, ...]
    observable: str
    source: str
    criterion: str = "fraction"
    patterned_above: float | None = None
    #: criterion fraction over several observables (``classes:``); empty: ``observable``
    #: above ``patterned_above``
    classes: tuple[Threshold, ...] = ()
    fraction: tuple[float, float] = DEFAULT_FRACTION
    jump: float = DEFAULT_JUMP
    rounds: int = DEFAULT_ROUNDS
    initial: int = 1
    add: int = 1
    max_width: float = DEFAULT_MAX_WIDTH
    confidence: float = DEFAULT_CONFIDENCE

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @property
    def axis(self) -> str:
        """The refined axis of a section that refines one (``ValueError`` for several)."""
        return self._one().name

    @property
    def min_spacing(self) -> float:
        """The smallest spacing of a section that refines one axis."""
        return self._one().min_spacing

    def _one(self) -> RefinedAxis:
        if len(self.axes) != 1:
            raise ValueError(f"refine: {', '.join(self.names)} are refined, not one axis")
        return self.axes[0]

    @property
    def thresholds(self) -> tuple[Threshold, ...]:
        """What a run's class is made of (criterion fraction; none for jump)."""
        if self.criterion != "fraction":
            return ()
        if self.classes:
            return self.classes
        assert self.patterned_above is not None
        return (Threshold(self.observable, self.source, self.patterned_above),)

    def to_dict(self) -> dict[str, Any]:
        spacing: float | dict[str, float] = (
            self.axes[0].min_spacing
            if len(self.axes) == 1
            else {a.name: a.min_spacing for a in self.axes}
        )
        return {
            "axis": self.axes[0].name if len(self.axes) == 1 else None,
            "axes": list(self.names),
            "log": [a.name for a in self.axes if a.log],
            "observable": self.observable,
            "source": self.source,
            "criterion": self.criterion,
            "patterned_above": self.patterned_above,
            "classes": {t.observable: t.above for t in self.classes},
            "fraction": list(self.fraction),
            "jump": self.jump,
            "rounds": self.rounds,
            "min_spacing": spacing,
            "seeds": {
                "initial": self.initial,
                "add": self.add,
                "max_width": self.max_width,
                "confidence": self.confidence,
            },
        }


@dataclass(frozen=True)
class PrecisionSpec:
    """A validated ``precision:`` section (:mod:`nematic_solids.sweep.precision`): seeds by
    precision.

    Every point gets the campaign's first ``initial`` seeds, then the next ``add`` per round
    until its decision is taken: ``precise`` (the ``confidence`` Student-t interval of the
    seed mean of ``observable`` is narrower than ``width``, relative to ``|mean|`` when
    ``relative``), ``unanimous`` (at least ``unanimous`` seeds, all of one class: ``sigma2_S``
    above ``patterned_above`` or not, or the tuple of ``classes``' thresholds each run is
    above) or ``cap`` (every seed of the campaign run). ``width`` or ``unanimous`` may be
    ``None`` (that rule is off)."""

    observable: str
    source: str
    width: float | None = None
    relative: bool = True
    confidence: float = 0.95
    unanimous: int | None = None
    patterned_above: float | None = None
    initial: int = 4
    add: int = 4
    #: the class from several observables (``classes:``), instead of ``patterned_above``
    classes: tuple[Threshold, ...] = ()
    #: the observable and run scalar ``patterned_above`` applies to: the model's classifying
    #: observable (:func:`~nematic_solids.sweep.models.interface.classifier`)
    patterned: tuple[str, str] = ("", "")

    @property
    def thresholds(self) -> tuple[Threshold, ...]:
        """What a run's class is made of (none without the unanimity rule)."""
        if self.classes:
            return self.classes
        if self.patterned_above is None:
            return ()
        return (Threshold(*self.patterned, self.patterned_above),)

    def to_dict(self) -> dict[str, Any]:
        return {
            "observable": self.observable,
            "source": self.source,
            "width": self.width,
            "relative": self.relative,
            "confidence": self.confidence,
            "unanimous": self.unanimous,
            "patterned_above": self.patterned_above,
            "classes": {t.observable: t.above for t in self.classes},
            "initial": self.initial,
            "add": self.add,
        }


@dataclass(frozen=True)
class Variant:
    """One variant of a verification: the settings changed against the campaign's own, as
    written (a value, or ``"x2"`` / ``"/10"`` for a multiple of the point's own value), and
    other seeds (``None``: the sampled seeds)."""

    name: str
    settings: Mapping[str, Any]
    seeds: tuple[int, ...] | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = dict(self.settings)
        if self.seeds is not None:
            out["seeds"] = list(self.seeds)
        return out


@dataclass(frozen=True)
class VerifySpec:
    """A validated ``verify:`` section (:mod:`nematic_solids.sweep.spec.verify`). ``points`` is
    ``None`` for the default sample (both sides of each fitted transition and the grid's corners),
    else the selections given (axis -> value; an axis left out takes every value)."""

    variants: tuple[Variant, ...]
    points: tuple[Mapping[str, Any], ...] | None = None
    corners: bool = True
    seeds: int = 2
    threshold: float = 0.05
    patterned_above: float = 1e-6
    #: what it compares (phase.nc names; the model's ``verify`` observables unless listed)
    observables: tuple[str, ...] = ()
    before: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "variants": [v.to_dict() for v in self.variants],
            "points": None if self.points is None else [dict(p) for p in self.points],
            "corners": self.corners,
            "seeds": self.seeds,
            "threshold": self.threshold,
            "patterned_above": self.patterned_above,
            "observables": list(self.observables),
            "before": self.before,
        }


#: the name of the grid dimension of a chain's branches (``chain:``,
#: :mod:`nematic_solids.sweep.chains`)
BRANCH = "branch"
#: the branches a chain may have, along its axis in increasing or decreasing order
BRANCHES = ("up", "down")
CHAIN_STARTS = ("predecessor", "fresh")  #: ``chain: {up: ...}``: where the up branch starts


@dataclass(frozen=True)
class ChainSpec:
    """``chain:`` (:mod:`nematic_solids.sweep.chains`): the sweep axis that is walked in order, each
    point's runs starting from the previous point's end state (same seed, same other values), on
    each of ``branches`` ("up": increasing values, "down": decreasing); the grid gains the dimension
    :data:`BRANCH`."""

    axis: str
    branches: tuple[str, ...] = BRANCHES
    #: where each run of the up branch starts, ``"predecessor"`` (quasi-static) or ``"fresh"``
    #: (each from the seeded texture, as Fig. 2's runs: the plain runs of its points)
    up: str = "predecessor"

    @property
    def dim(self) -> Dim:
        return Dim(BRANCH, (Axis(BRANCH, self.branches),))


@dataclass(frozen=True)
class Campaign:
    """A validated campaign. ``parameters`` / ``numerics`` are the base values as written
    (validated by the model's own objects at every grid point). ``figures`` is ``None`` when
    the file has no ``figures:`` (or ``figures: null``): draw every registered figure that
    applies to the grid; an empty tuple (``figures: []``) draws none."""

    name: str
    description: str
    parameters: Mapping[str, Any]
    numerics: Mapping[str, Any]
    dims: tuple[Dim, ...]
    seeds: tuple[int, ...]
    store: StoreSpec
    fits: tuple[Product, ...]
    figures: tuple[Product, ...] | None
    execution: ExecutionSpec
    limits: LimitsSpec = field(default_factory=lambda: LimitsSpec())
    source: str = "<string>"
    text: str = ""
    overrides: tuple[str, ...] = ()
    #: the ``refine:`` section (an adaptive campaign: sweep/refine), or ``None``
    refine: RefineSpec | None = None
    #: the ``precision:`` section (seeds by precision: sweep/precision), or ``None``
    precision: PrecisionSpec | None = None
    #: the ``verify:`` section (convergence and sensitivity checks: sweep/verify), or ``None``
    verify: VerifySpec | None = None
    #: the ``initial:`` section (runs begin from another campaign's: sweep/expand), or None
    initial: InitialSpec | None = None
    #: the ``chain:`` section (points walked in order along an axis: sweep/chains), or None
    chain: ChainSpec | None = None
    #: ``prior:`` the phase.nc whose seeds per point price the later rounds (sweep/cost/later)
    prior: str | None = None
    model: str = DEFAULT_MODEL  # ``model:`` by name (the default adds nothing to run ids)

    @property
    def axes(self) -> tuple[Axis, ...]:
        return tuple(a for d in self.dims for a in d.axes)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(d) for d in self.dims)

    @property
    def n_points(self) -> int:
        return math.prod(self.shape)

    @property
    def n_runs(self) -> int:
        return self.n_points * len(self.seeds)


@dataclass(frozen=True)
class InitialSpec:
    """``initial.from`` (sweep/expand): the parent campaign, the axis values it pins, the
    seed (None: the same), the time (None: the end), the parent's file, the file:line."""

    parent: Campaign
    path: str
    point: Mapping[str, Any] = field(default_factory=dict)
    seed: int | None = None
    time: float | None = None
    location: str = ""

    @property
    def time_text(self) -> str:
        """The time as it enters the identity and the lineage, ``end`` or the number."""
        return "end" if self.time is None else f"{self.time:.12g}"
