"""Campaign YAML -> a validated, immutable :class:`Campaign`.

The schema (documented for users in ``docs/campaigns.md``)::

    name: fig2                      # results go to results/<name>/ (default: the file's stem)
    description: free text
    parameters: {B: 0.5, K: 5.0e-5}  # base model parameters (model.parameters.Parameters)
    numerics: {resolution: 128, t_final: 300}   # base numerics (model.parameters.Numerics)
    sweep:
      axes:                         # product of all axes by default, in this order
        alpha_minus_B: {linspace: [0.1, 1.0, 10]}
        K: {logspace: [-5, -3, 3]}  # exponents, base 10 (geomspace takes the end points)
        eps: [0.0, 0.1]
      zip:                          # groups of axes that vary together (equal lengths)
        - [K, eps]
    seeds: 50                       # a count (seeds 0..49), a list, or {count: 50, start: 1000}
    store: {snapshot_times: [100, 300], snapshot_fields: [q1, q2, A], snapshot_dtype: float32}
    fits: [transition]              # names (or {name: {options}}) from sweep.fits.REGISTRY
    figures: [fig2]                 # names (or {name: {options}}) from sweep.figures.REGISTRY;
                                    # [] draws none; absent: every figure that applies
    execution:
      workers: 2                    # local dask LocalCluster (default: one per core)
      scheduler: tcp://host:8786    # or an existing dask scheduler
      cluster: {kind: slurm, jobs: 10, cores: 8, memory: 16GB, walltime: "02:00:00"}

Every mistake is collected as a :class:`~sweep.errors.Problem` naming the file and line, the
key path, the value and what is allowed (with the closest valid name for unknown keys), and
raised together as one :class:`~sweep.errors.CampaignError` before anything runs.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib
import inspect
import logging
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from model.parameters import Numerics, Parameters

from .errors import CampaignError, Problem
from .limits import DEFAULT_MAX_RUNS, max_local_workers, parse_size

if TYPE_CHECKING:
    from .refine.config import RefineSpec

log = logging.getLogger(__name__)

TOP_KEYS = ("name", "description", "parameters", "numerics", "sweep", "seeds", "store", "fits",
            "figures", "execution", "limits", "refine")
LIMITS_KEYS = ("max_runs", "run_memory")
#: Largest campaign file read (bytes), and most YAML nodes after aliases are expanded: a
#: file of anchors that refer to anchors (a "billion laughs") is refused before it is built.
MAX_TEXT_BYTES = 4 * 2**20
MAX_YAML_NODES = 100_000
#: Most batch jobs of a dask-jobqueue cluster.
MAX_JOBS = 100_000
SWEEP_KEYS = ("axes", "zip")
RANGE_KINDS = ("linspace", "logspace", "geomspace")
RANGE_KEYS = ("start", "stop", "num")
STORE_KEYS = ("snapshot_times", "snapshot_fields", "snapshot_dtype")
#: Snapshot variables of a run file (model.simulate.run contract).
SNAPSHOT_FIELDS = ("q1", "q2", "A", "u1", "u2", "I1bar")
SNAPSHOT_DTYPES = ("float64", "float32")
EXECUTION_KEYS = ("workers", "threads_per_worker", "memory_limit", "scheduler", "cluster",
                  "wait_for_workers", "give_up_after", "security")
SECURITY_KEYS = ("tls", "reason")
#: Default of ``execution.wait_for_workers``: how long a driver on an external scheduler or a
#: batch cluster waits for its first worker before giving up (seconds).
DEFAULT_WORKER_WAIT = 600.0
#: Default of ``execution.give_up_after``: how long a running campaign goes on without any
#: usable worker (every job ended, the scheduler unreachable) before the driver gives up.
DEFAULT_GIVE_UP = 120.0
CLUSTER_KINDS = {
    "slurm": "SLURMCluster", "pbs": "PBSCluster", "sge": "SGECluster", "lsf": "LSFCluster",
    "oar": "OARCluster", "moab": "MoabCluster", "htcondor": "HTCondorCluster",
}
#: Arguments of the dask-jobqueue classes that the campaign manager sets itself.
_CLUSTER_RESERVED = {"self", "scheduler", "name", "config_name", "job_cls", "loop", "asynchronous",
                     "n_workers", "base_class_kwargs", "job_kwargs", "kwargs", "security"}
DEFAULT_SEEDS = 50
MAX_SEED = 2**63 - 1
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
SCHEDULER_RE = re.compile(r"^(tcp|tls|inproc|ucx|ws|wss)://\S+$")
#: Significant digits kept when normalising swept floats (and in run identity).
SIGNIFICANT_DIGITS = 12

AMB = "alpha_minus_B"


# --------------------------------------------------------------------------- the model's names
def _field_types(cls: type) -> dict[str, str]:
    return {f.name: str(f.type) for f in dataclasses.fields(cls)}


PARAMETER_TYPES: dict[str, str] = {**_field_types(Parameters), AMB: "float"}
NUMERICS_TYPES: dict[str, str] = _field_types(Numerics)
#: Numerics fields that may be swept (scalars only).
SWEEPABLE_NUMERICS = tuple(n for n, t in NUMERICS_TYPES.items()
                           if t in ("int", "float", "bool", "str"))
AXIS_TYPES: dict[str, str] = {**PARAMETER_TYPES,
                              **{n: NUMERICS_TYPES[n] for n in SWEEPABLE_NUMERICS}}


def normalise_float(x: float) -> float:
    """Round to :data:`SIGNIFICANT_DIGITS` significant digits: 0.30000000000000004 -> 0.3."""
    y = float(f"{float(x):.{SIGNIFICANT_DIGITS}g}")
    return 0.0 if y == 0 else y


def suggest(name: str, valid: Sequence[str]) -> str:
    """``" (did you mean 'x'?)"`` for the closest valid name, or ``""``."""
    lowered = {v.lower(): v for v in valid}
    close = [lowered[name.lower()]] if name.lower() in lowered else []
    close = close or difflib.get_close_matches(name, list(valid), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


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
    model writes) in ``snapshot_dtype``."""

    snapshot_fields: tuple[str, ...] | None = None
    snapshot_dtype: str = "float64"


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
    #: seconds to wait for a first worker (scheduler / cluster); 0: wait for ever
    wait_for_workers: float = DEFAULT_WORKER_WAIT
    #: seconds without any usable worker (or scheduler) after which a started campaign stops
    give_up_after: float = DEFAULT_GIVE_UP
    #: TLS with per-campaign temporary credentials for a scheduler the driver starts
    tls: bool = True
    #: why the campaign opted out of TLS (required with ``security: {tls: false}``)
    insecure_reason: str | None = None

    @property
    def mode(self) -> str:
        """"local", "scheduler" or "cluster"."""
        if self.scheduler:
            return "scheduler"
        return "cluster" if self.cluster else "local"


@dataclass(frozen=True)
class LimitsSpec:
    """Ceilings checked before the grid is built: ``max_runs`` (runs = product of the axis
    lengths x seeds) and ``run_memory`` (bytes one run may use; default: what one worker
    has, see :func:`run_memory_limit`)."""

    max_runs: int = DEFAULT_MAX_RUNS
    run_memory: int | None = None


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
class Overrides:
    """Command-line changes applied to the YAML before validation (``--set``, ``--seeds``,
    ``--name``, ``--scheduler``, ``--workers``), e.g. to run a campaign at reduced size."""

    settings: Mapping[str, Any] = field(default_factory=dict)
    seeds: int | list[int] | None = None
    name: str | None = None
    scheduler: str | None = None
    workers: int | None = None

    def describe(self) -> tuple[str, ...]:
        out = [f"--set {k}={v!r}" for k, v in self.settings.items()]
        if self.seeds is not None:
            out.append(f"--seeds {self.seeds}")
        if self.name is not None:
            out.append(f"--name {self.name}")
        if self.scheduler is not None:
            out.append(f"--scheduler {self.scheduler}")
        if self.workers is not None:
            out.append(f"--workers {self.workers}")
        return tuple(out)


# --------------------------------------------------------------------------- YAML reading
class _Loader(yaml.SafeLoader):
    """Safe loader that also reads ``1e-5`` (no dot) as a float, as YAML 1.2 does."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^(?:[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+|[-+]?\.[0-9_]+[eE][-+]?[0-9]+)$"),
    list("-+0123456789."),
)

Path_ = tuple[str | int, ...]


def format_path(path: Path_) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def parse_value(text: str) -> Any:
    """A command-line value read as YAML (``0.3`` -> float, ``[1, 2]`` -> list, ``abc`` -> str)."""
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader is a SafeLoader
    except yaml.YAMLError:
        return text


def parse_assignments(items: Sequence[str]) -> dict[str, Any]:
    """``["K=1e-4", "resolution=64"]`` -> ``{"K": 1e-4, "resolution": 64}``.

    Raises :class:`CampaignError` for an item without ``=``.
    """
    out: dict[str, Any] = {}
    problems = []
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            problems.append(Problem(f"--set {item}", "expected NAME=VALUE", "command line"))
            continue
        out[name.strip()] = parse_value(value.strip())
    if problems:
        raise CampaignError("command line", problems)
    return out


def _expanded_size(root: yaml.Node) -> int:
    """How many nodes the document has once every alias is expanded (each distinct node is
    visited once: linear in the file, whatever the expansion)."""
    sizes: dict[int, int] = {}
    open_: set[int] = set()  # being sized: meeting one again is a recursive alias
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        if id(node) in sizes:
            continue
        if isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        else:
            sizes[id(node)] = 1
            continue
        if done:
            sizes[id(node)] = min(1 + sum(sizes[id(n)] for n in children), 2**62)
            open_.discard(id(node))
            continue
        if id(node) in open_:
            return 2**62  # a value that contains itself: infinitely large
        open_.add(id(node))
        stack.append((node, True))
        for n in children:
            if id(n) in open_:
                return 2**62
            if id(n) not in sizes:
                stack.append((n, False))
    return sizes[id(root)]


def _walk(node: yaml.Node, path: Path_, lines: dict[Path_, int], dups: list[Path_]) -> None:
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        seen: set[Any] = set()
        for key_node, value_node in node.value:
            key = key_node.value
            if key in seen:
                dups.append((*path, key))
            seen.add(key)
            lines[(*path, key)] = key_node.start_mark.line + 1
            _walk(value_node, (*path, key), lines, dups)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _walk(item, (*path, i), lines, dups)


# --------------------------------------------------------------------------- validation
class _Checker:
    """Collects problems with their locations."""

    def __init__(self, source: str, lines: dict[Path_, int], origins: dict[Path_, str]):
        self.source, self.lines, self.origins = source, lines, origins
        self.problems: list[Problem] = []
        self.max_runs = DEFAULT_MAX_RUNS

    def location(self, path: Path_) -> str:
        for n in range(len(path), -1, -1):
            if path[:n] in self.origins:
                return f"{self.origins[path[:n]]}"
        for n in range(len(path), -1, -1):
            if path[:n] in self.lines:
                return f"{self.source}:{self.lines[path[:n]]}"
        return self.source

    def add(self, path: Path_, message: str) -> None:
        self.problems.append(Problem(format_path(path), message, self.location(path)))

    def bad(self, path: Path_, value: Any, allowed: str) -> None:
        self.add(path, f"got {value!r}; allowed: {allowed}")

    def unknown(self, path: Path_, key: Any, valid: Sequence[str], hint: str = "") -> None:
        extra = suggest(str(key), valid) if isinstance(key, str) else ""
        self.add(path, f"unknown key {key!r}{extra}{hint}; allowed keys: {', '.join(valid)}")

    def mapping(self, path: Path_, value: Any, valid: Sequence[str] | None) -> dict[str, Any]:
        """Check ``value`` is a mapping with string keys from ``valid``; return the known part."""
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            self.bad(path, value, "a mapping of KEY: VALUE")
            return {}
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                self.bad((*path, str(key)), key, "string keys")
            elif valid is not None and key not in valid:
                self.unknown((*path, key), key, valid)
            else:
                out[key] = item
        return out

    def raise_if_any(self) -> None:
        if self.problems:
            raise CampaignError(self.source, sorted(self.problems, key=self._line))

    def _line(self, p: Problem) -> int:
        head, _, tail = p.location.rpartition(":")
        return int(tail) if head == self.source and tail.isdigit() else 0


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def coerce(kind: str, value: Any) -> Any:
    """Normalise one value for a field of declared type ``kind``; ``ValueError`` if impossible."""
    if kind == "float":
        if not _is_number(value) or not math.isfinite(float(value)):
            raise ValueError("a finite real number")
        return normalise_float(value)
    if kind == "int":
        if _is_int(value):
            return int(value)
        if _is_number(value) and float(value).is_integer():
            return int(value)
        raise ValueError("an integer")
    if kind == "bool":
        if not isinstance(value, bool):
            raise ValueError("true or false")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise ValueError("a string")
        return value
    return value


def _check_name(c: _Checker, value: Any, path: Path_) -> str | None:
    allowed = ("letters, digits, '.', '_' or '-', starting with a letter or digit, at most 100 "
               "characters (the results go to results/<name>/)")
    if value is None:
        c.add(path, f"missing; allowed: {allowed}")
        return None
    if not isinstance(value, str) or not NAME_RE.match(value) or ".." in value:
        c.bad(path, value, allowed)
        return None
    return value


def _check_settings(c: _Checker, raw: Any, section: str, types: Mapping[str, str],
                    other: Mapping[str, str], other_section: str) -> dict[str, Any]:
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        c.bad((section,), raw, "a mapping of NAME: VALUE")
        return {}
    out: dict[str, Any] = {}
    for key, value in raw.items():
        path = (section, str(key))
        if key in types:
            out[key] = value
        elif key in other:
            c.add(path, f"{key!r} is a {other_section} setting, not a {section} one; move it "
                  f"under '{other_section}:'")
        else:
            c.unknown(path, key, sorted(types))
    return out


def _range_values(c: _Checker, kind: str, spec: Any, path: Path_) -> list[Any] | None:
    usage = ("[start, stop, num] or {start: .., stop: .., num: ..}"
             + (" (exponents of 10)" if kind == "logspace" else ""))
    if isinstance(spec, Sequence) and not isinstance(spec, str):
        if len(spec) != 3:
            c.bad(path, spec, usage)
            return None
        start, stop, num = spec
    elif isinstance(spec, Mapping):
        keys = c.mapping(path, spec, RANGE_KEYS)
        missing = [k for k in RANGE_KEYS if k not in spec]
        if missing:
            c.add(path, f"missing {', '.join(missing)}; allowed: {usage}")
            return None
        if len(keys) != len(spec):
            return None
        start, stop, num = spec["start"], spec["stop"], spec["num"]
    else:
        c.bad(path, spec, usage)
        return None
    ok = True
    for label, v in (("start", start), ("stop", stop)):
        if not _is_number(v) or not math.isfinite(float(v)):
            c.bad((*path, label), v, "a finite number")
            ok = False
    if not _is_int(num) or num < 1:
        c.bad((*path, "num"), num, "an integer >= 1 (the number of values)")
        ok = False
    elif num > c.max_runs:
        c.bad((*path, "num"), num, f"at most {c.max_runs} values (limits.max_runs)")
        ok = False
    if not ok:
        return None
    if kind == "linspace":
        return list(np.linspace(float(start), float(stop), int(num)))
    if kind == "logspace":
        return list(np.logspace(float(start), float(stop), int(num)))
    if float(start) == 0 or float(stop) == 0 or (float(start) > 0) != (float(stop) > 0):
        c.bad(path, [start, stop], "geomspace end points that are non-zero and of one sign")
        return None
    return list(np.geomspace(float(start), float(stop), int(num)))


def _check_axis(c: _Checker, name: str, raw: Any, path: Path_) -> Axis | None:
    if isinstance(raw, Mapping):
        if len(raw) != 1 or next(iter(raw)) not in RANGE_KINDS:
            keys = list(raw)
            bad = next((k for k in keys if k not in RANGE_KINDS), keys[0] if keys else None)
            if bad is not None and bad not in RANGE_KINDS:
                c.unknown((*path, str(bad)), bad, RANGE_KINDS)
            else:
                c.bad(path, raw, "exactly one of " + ", ".join(RANGE_KINDS))
            return None
        kind = next(iter(raw))
        values = _range_values(c, kind, raw[kind], (*path, kind))
        if values is None:
            return None
        vpaths = [(*path, kind)] * len(values)
    elif isinstance(raw, Sequence) and not isinstance(raw, str):
        values = list(raw)
        vpaths = [(*path, i) for i in range(len(values))]
    else:
        c.bad(path, raw, "a list of values or {linspace|logspace|geomspace: [start, stop, num]} "
              "(a single value belongs under 'parameters:' or 'numerics:')")
        return None
    if not values:
        c.bad(path, raw, "a non-empty list of values (an empty axis would give no runs)")
        return None
    kind_t = AXIS_TYPES[name]
    out: list[Any] = []
    ok = True
    for v, vpath in zip(values, vpaths, strict=True):
        try:
            out.append(coerce(kind_t, v))
        except ValueError as e:
            c.bad(vpath, v, str(e))
            ok = False
    if not ok:
        return None
    seen: set[Any] = set()
    dups = [v for v in out if v in seen or seen.add(v)]  # type: ignore[func-returns-value]
    if dups:
        c.bad(path, dups[0], "distinct values (this one appears twice)")
        return None
    return Axis(name, tuple(out))


def _check_sweep(c: _Checker, raw: Any, base: Mapping[str, Any]) -> tuple[Dim, ...]:
    sweep = c.mapping(("sweep",), raw, SWEEP_KEYS)
    axes_raw = c.mapping(("sweep", "axes"), sweep.get("axes"), None)
    axes: dict[str, Axis] = {}
    for name, spec in axes_raw.items():
        path = ("sweep", "axes", name)
        if name not in AXIS_TYPES:
            c.unknown(path, name, sorted(AXIS_TYPES),
                      "" if name not in NUMERICS_TYPES else " (snapshot_times cannot be swept)")
            continue
        if name in base:
            origin = c.origins.get((base[name], name))
            if origin is not None:  # a command-line --set
                c.problems.append(Problem(
                    name, f"{name!r} is a swept axis of this campaign (sweep.axes.{name}); "
                    "--set changes only base values: drop it from the command line, or "
                    "give the campaign a file of its own", f"command line {origin}"))
            else:
                c.add(path, f"{name!r} is both swept and set in "
                      f"'{base[name]}:'; remove it from one of them")
            continue
        axis = _check_axis(c, name, spec, path)
        if axis is not None:
            axes[name] = axis
    if AMB in axes_raw and "alpha" in axes_raw:
        c.add(("sweep", "axes", AMB), "sweep either 'alpha' or 'alpha_minus_B', not both")
    for a, b in ((AMB, "alpha"), ("alpha", AMB)):
        if a in axes_raw and base.get(b) == "parameters":
            c.add(("sweep", "axes", a), f"conflicts with parameters.{b} (alpha = B + "
                  "alpha_minus_B): set only one of them")

    groups: list[list[str]] = []
    zip_raw = sweep.get("zip")
    if zip_raw is not None:
        if not isinstance(zip_raw, Sequence) or isinstance(zip_raw, str):
            c.bad(("sweep", "zip"), zip_raw, "a list of groups, each a list of axis names")
            zip_raw = []
        grouped: dict[str, int] = {}
        for gi, group in enumerate(zip_raw):
            gpath: Path_ = ("sweep", "zip", gi)
            if (not isinstance(group, Sequence) or isinstance(group, str) or len(group) < 2
                    or not all(isinstance(n, str) for n in group)):
                c.bad(gpath, group, "a list of two or more axis names")
                continue
            names: list[str] = []
            for ni, n in enumerate(group):
                if n not in axes_raw:
                    c.bad((*gpath, ni), n, "the name of an axis under sweep.axes"
                          + suggest(n, list(axes_raw)) + f" (axes: {', '.join(axes_raw)})")
                elif n in grouped:
                    c.bad((*gpath, ni), n, "each axis in at most one zip group (it is already "
                          f"in sweep.zip[{grouped[n]}])")
                else:
                    grouped[n] = gi
                    names.append(n)
            if len(names) == len(group):
                lengths = {n: len(axes[n].values) for n in names if n in axes}
                if len(lengths) == len(names) and len(set(lengths.values())) > 1:
                    desc = ", ".join(f"{n} has {k}" for n, k in lengths.items())
                    c.bad(gpath, group, f"axes of equal length in a zip group ({desc} values)")
                groups.append(names)

    dims: list[Dim] = []
    placed: set[str] = set()
    for name in axes_raw:
        if name in placed or name not in axes:
            continue
        group = next((g for g in groups if name in g), None)
        if group is None:
            dims.append(Dim(name, (axes[name],)))
            placed.add(name)
        elif all(n in axes for n in group):
            dims.append(Dim(group[0], tuple(axes[n] for n in group)))
            placed.update(group)
    return tuple(dims)


def _check_seeds(c: _Checker, raw: Any) -> tuple[int, ...]:
    path: Path_ = ("seeds",)
    if raw is None:
        return tuple(range(DEFAULT_SEEDS))
    if _is_int(raw):
        if raw < 1:
            c.bad(path, raw, "a count >= 1, a list of seeds, or {count: N, start: S}")
            return ()
        if raw > c.max_runs:
            c.bad(path, raw, f"at most {c.max_runs} seeds (limits.max_runs)")
            return ()
        return tuple(range(int(raw)))
    if isinstance(raw, Mapping):
        m = c.mapping(path, raw, ("count", "start"))
        count, start = m.get("count", DEFAULT_SEEDS), m.get("start", 0)
        if not _is_int(count) or count < 1 or count > c.max_runs:
            c.bad((*path, "count"), count, f"an integer from 1 to {c.max_runs} "
                  "(limits.max_runs)")
            return ()
        if not _is_int(start) or start < 0 or start + count > MAX_SEED:
            c.bad((*path, "start"), start, "an integer >= 0")
            return ()
        return tuple(range(int(start), int(start) + int(count)))
    if isinstance(raw, Sequence) and not isinstance(raw, str):
        if not raw:
            c.bad(path, raw, "a non-empty list of seeds")
            return ()
        out = []
        for i, s in enumerate(raw):
            if not _is_int(s) or not 0 <= s <= MAX_SEED:
                c.bad((*path, i), s, "an integer seed >= 0")
            elif int(s) in out:
                c.bad((*path, i), s, "distinct seeds (this one appears twice)")
            else:
                out.append(int(s))
        return tuple(out)
    c.bad(path, raw, "a count >= 1, a list of seeds, or {count: N, start: S}")
    return ()


def _check_store(c: _Checker, raw: Any, numerics: dict[str, Any]) -> StoreSpec:
    store = c.mapping(("store",), raw, STORE_KEYS)
    if "snapshot_times" in store:
        if "snapshot_times" in numerics:
            c.add(("store", "snapshot_times"), "set in both 'store:' and 'numerics:'; keep one")
        else:
            numerics["snapshot_times"] = store["snapshot_times"]
    fields: tuple[str, ...] | None = None
    if "snapshot_fields" in store:
        raw_fields = store["snapshot_fields"]
        if not isinstance(raw_fields, Sequence) or isinstance(raw_fields, str):
            c.bad(("store", "snapshot_fields"), raw_fields,
                  "a list of field names from " + ", ".join(SNAPSHOT_FIELDS))
        else:
            for i, f in enumerate(raw_fields):
                if f not in SNAPSHOT_FIELDS:
                    c.bad(("store", "snapshot_fields", i), f, "one of "
                          + ", ".join(SNAPSHOT_FIELDS) + suggest(str(f), SNAPSHOT_FIELDS))
            fields = tuple(f for f in SNAPSHOT_FIELDS if f in raw_fields)
    dtype = store.get("snapshot_dtype", "float64")
    if dtype not in SNAPSHOT_DTYPES:
        c.bad(("store", "snapshot_dtype"), dtype, " or ".join(SNAPSHOT_DTYPES))
        dtype = "float64"
    return StoreSpec(snapshot_fields=fields, snapshot_dtype=dtype)


def registry_names(kind: str) -> list[str] | None:
    """Names registered in ``sweep.<kind>.REGISTRY`` (``kind`` = "fits" or "figures"), or
    ``None`` while that module does not exist (then any identifier is accepted)."""
    try:
        module = importlib.import_module(f"sweep.{kind}")
    except ModuleNotFoundError as e:
        if e.name == f"sweep.{kind}":
            return None
        raise
    registry = getattr(module, "REGISTRY", None)
    return None if registry is None else sorted(registry)


def _check_products(c: _Checker, raw: Any, kind: str) -> tuple[Product, ...]:
    path: Path_ = (kind,)
    if raw is None:
        return ()
    if not isinstance(raw, Sequence) or isinstance(raw, str):
        c.bad(path, raw, "a list of names or {name: {options}}")
        return ()
    known = registry_names(kind)
    out = []
    for i, item in enumerate(raw):
        options: dict[str, Any]
        if isinstance(item, str):
            name, options = item, {}
        elif (isinstance(item, Mapping) and len(item) == 1
              and isinstance(next(iter(item)), str)
              and isinstance(next(iter(item.values())), (Mapping, type(None)))):
            name, raw_options = next(iter(item.items()))
            options = dict(raw_options or {})
        else:
            c.bad((*path, i), item, "a name or {name: {options}}")
            continue
        if known is not None and name not in known:
            c.bad((*path, i), name, f"one of {', '.join(known)}{suggest(name, known)}")
            continue
        if known is None and not re.match(r"^[A-Za-z_][A-Za-z0-9_.-]*$", name):
            c.bad((*path, i), name, "an identifier")
            continue
        out.append(Product(name, options))
    return tuple(out)


def cluster_option_names(kind: str) -> list[str]:
    """Keyword arguments the dask-jobqueue cluster class of ``kind`` accepts."""
    import dask_jobqueue
    import dask_jobqueue.core as core

    cls = getattr(dask_jobqueue, CLUSTER_KINDS[kind])
    names: set[str] = set()
    for fn in (cls.job_cls.__init__, core.Job.__init__, core.JobQueueCluster.__init__):
        names.update(inspect.signature(fn).parameters)
    return sorted(names - _CLUSTER_RESERVED)


def _check_execution(c: _Checker, raw: Any) -> ExecutionSpec:
    ex = c.mapping(("execution",), raw, EXECUTION_KEYS)
    workers = ex.get("workers")
    most = max_local_workers()
    if workers is not None and (not _is_int(workers) or not 1 <= workers <= most):
        c.bad(("execution", "workers"), workers, f"an integer from 1 to {most} (local worker "
              f"processes; this machine has {os.cpu_count() or 1} core(s))")
        workers = None
    tpw = ex.get("threads_per_worker", 1)
    if not _is_int(tpw) or not 1 <= tpw <= most:
        c.bad(("execution", "threads_per_worker"), tpw, f"an integer from 1 to {most}")
        tpw = 1
    memory = ex.get("memory_limit")
    if memory is not None and not isinstance(memory, (str, int)):
        c.bad(("execution", "memory_limit"), memory, "a size such as '4GB', or 'auto'")
        memory = None
    scheduler = ex.get("scheduler")
    if scheduler is not None and (not isinstance(scheduler, str)
                                  or not SCHEDULER_RE.match(scheduler)):
        c.bad(("execution", "scheduler"), scheduler,
              "a dask scheduler address such as 'tcp://10.0.0.1:8786'")
        scheduler = None
    cluster = None
    if ex.get("cluster") is not None:
        cluster = _check_cluster(c, ex["cluster"])
    if scheduler and ex.get("cluster") is not None:
        c.add(("execution", "cluster"), "give either 'scheduler' or 'cluster', not both")
    if (scheduler or ex.get("cluster") is not None) and "workers" in ex:
        c.add(("execution", "workers"), "'workers' sizes the local cluster only; with "
              "'scheduler' the cluster is sized elsewhere, with 'cluster' use cluster.jobs")
    wait = ex.get("wait_for_workers", DEFAULT_WORKER_WAIT)
    if not _is_number(wait) or not 0 <= wait < math.inf:
        c.bad(("execution", "wait_for_workers"), wait, "a number of seconds >= 0 (0: wait "
              "for ever, with a line every minute)")
        wait = DEFAULT_WORKER_WAIT
    give_up = ex.get("give_up_after", DEFAULT_GIVE_UP)
    if not _is_number(give_up) or not 0 < give_up < math.inf:
        c.bad(("execution", "give_up_after"), give_up, "a number of seconds > 0 (how long a "
              "running campaign goes on without any usable worker)")
        give_up = DEFAULT_GIVE_UP
    tls, reason = _check_security(c, ex.get("security"))
    if tls and cluster is not None and cluster.options.get("protocol") not in (None, "tls://"):
        c.add(("execution", "cluster", "protocol"), f"{cluster.options['protocol']!r} is not "
              "encrypted: the scheduler uses TLS ('tls://') unless execution.security says "
              "{tls: false, reason: ...}")
    return ExecutionSpec(workers=workers, threads_per_worker=int(tpw),
                         memory_limit=None if memory is None else str(memory),
                         scheduler=scheduler, cluster=cluster, wait_for_workers=float(wait),
                         give_up_after=float(give_up), tls=tls, insecure_reason=reason)


def _check_security(c: _Checker, raw: Any) -> tuple[bool, str | None]:
    """``execution.security``: TLS on (default), or ``{tls: false, reason: ...}``."""
    if raw is None:
        return True, None
    path: Path_ = ("execution", "security")
    sec = c.mapping(path, raw, SECURITY_KEYS)
    tls = sec.get("tls", True)
    if not isinstance(tls, bool):
        c.bad((*path, "tls"), tls, "true or false")
        return True, None
    reason = sec.get("reason")
    if reason is not None and (not isinstance(reason, str) or not reason.strip()):
        c.bad((*path, "reason"), reason, "a sentence saying why the scheduler may run "
              "without TLS")
        return tls, None
    if not tls and reason is None:
        c.add((*path, "tls"), "turning TLS off needs a stated reason: add "
              "'reason: <why plain tcp is acceptable here>' (without TLS anyone who can "
              "reach the scheduler can run code as you)")
    return tls, None if reason is None else reason.strip()


def _check_cluster(c: _Checker, raw: Any) -> ClusterSpec | None:
    path: Path_ = ("execution", "cluster")
    if not isinstance(raw, Mapping):
        c.bad(path, raw, "a mapping with 'kind' (" + ", ".join(CLUSTER_KINDS) + ") and options")
        return None
    kind = raw.get("kind")
    if kind not in CLUSTER_KINDS:
        c.bad((*path, "kind"), kind, "one of " + ", ".join(CLUSTER_KINDS)
              + (suggest(kind, list(CLUSTER_KINDS)) if isinstance(kind, str) else ""))
        return None
    valid = cluster_option_names(kind)
    jobs = raw.get("jobs", 1)
    if not _is_int(jobs) or not 0 <= jobs <= MAX_JOBS:
        c.bad((*path, "jobs"), jobs, f"an integer from 0 to {MAX_JOBS} (batch jobs to submit)")
        jobs = 1
    adapt = None
    if raw.get("adapt") is not None:
        a = c.mapping((*path, "adapt"), raw["adapt"], ("minimum_jobs", "maximum_jobs"))
        lo, hi = a.get("minimum_jobs", 0), a.get("maximum_jobs")
        if not _is_int(lo) or lo < 0:
            c.bad((*path, "adapt", "minimum_jobs"), lo, "an integer >= 0")
        elif hi is None or not _is_int(hi) or not max(lo, 1) <= hi <= MAX_JOBS:
            c.bad((*path, "adapt", "maximum_jobs"), hi,
                  f"an integer from max(1, {lo}) to {MAX_JOBS}")
        else:
            adapt = (int(lo), int(hi))  # type: ignore[arg-type]  # checked by _is_int
    options = {}
    for key, value in raw.items():
        if key in ("kind", "jobs", "adapt"):
            continue
        if key not in valid:
            c.unknown((*path, str(key)), key, ["kind", "jobs", "adapt", *valid],
                      f" (options of dask_jobqueue.{CLUSTER_KINDS[kind]})")
        else:
            options[key] = value
    return ClusterSpec(kind=kind, jobs=int(jobs), adapt=adapt, options=options)


def _apply_overrides(doc: dict[str, Any], ov: Overrides, origins: dict[Path_, str],
                     c: _Checker) -> None:
    pnames, nnames = set(PARAMETER_TYPES), set(NUMERICS_TYPES)
    for key, value in ov.settings.items():
        label = f"--set {key}={value!r}"
        if key in pnames:
            section = "parameters"
        elif key in nnames:
            section = "numerics"
        else:
            c.problems.append(Problem(key, f"unknown name{suggest(key, sorted(pnames | nnames))}"
                                      f"; allowed: {', '.join(sorted(pnames | nnames))}",
                                      "command line --set"))
            continue
        if not isinstance(doc.get(section) or {}, Mapping):
            continue
        doc[section] = dict(doc.get(section) or {})
        doc[section][key] = value
        origins[(section, key)] = label
    if ov.seeds is not None:
        doc["seeds"] = ov.seeds
        origins[("seeds",)] = f"--seeds {ov.seeds}"
    if ov.name is not None:
        doc["name"] = ov.name
        origins[("name",)] = f"--name {ov.name}"
    if ov.scheduler is not None or ov.workers is not None:
        ex = dict(doc.get("execution") or {}) if isinstance(doc.get("execution"), Mapping) else {}
        if ov.scheduler is not None:
            ex.pop("cluster", None)
            ex.pop("workers", None)
            ex["scheduler"] = ov.scheduler
            origins[("execution", "scheduler")] = f"--scheduler {ov.scheduler}"
        if ov.workers is not None:
            ex.pop("cluster", None)
            ex.pop("scheduler", None)
            ex["workers"] = ov.workers
            origins[("execution", "workers")] = f"--workers {ov.workers}"
        doc["execution"] = ex


def parse_campaign(text: str, source: str = "<string>", overrides: Overrides | None = None,
                   default_name: str | None = None) -> Campaign:
    """Validate campaign YAML ``text``; raise :class:`CampaignError` listing every problem.

    Every grid point is then checked by the model's own :class:`Parameters` and
    :class:`Numerics` (see :func:`sweep.expand.check_points`), so impossible values anywhere
    in the sweep are rejected here too.
    """
    overrides = overrides or Overrides()
    if len(text) > MAX_TEXT_BYTES:
        raise CampaignError(source, [Problem("", f"the file has {len(text)} characters; "
                                             f"allowed: at most {MAX_TEXT_BYTES}", source)])
    try:
        loader = _Loader(text)
        try:
            node = loader.get_single_node()
            if node is not None:
                size = _expanded_size(node)
                if size > MAX_YAML_NODES:
                    raise CampaignError(source, [Problem(
                        "", f"the YAML expands to more than {MAX_YAML_NODES} values through "
                        "its aliases (*name); allowed: a campaign without such nesting",
                        f"{source}:{node.start_mark.line + 1}")])
            doc = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark is not None else source
        msg = " ".join(str(getattr(e, "problem", None) or e).split())
        raise CampaignError(source, [Problem("", f"not valid YAML: {msg}", where)]) from None
    except RecursionError:
        raise CampaignError(source, [Problem("", "the YAML is nested too deeply", source)]
                            ) from None
    if node is None:
        raise CampaignError(source, [Problem("", "the campaign file is empty; allowed: a "
                                             "mapping with keys " + ", ".join(TOP_KEYS),
                                             source)])
    lines: dict[Path_, int] = {}
    dups: list[Path_] = []
    try:
        _walk(node, (), lines, dups)
    except RecursionError:
        raise CampaignError(source, [Problem("", "the YAML is nested too deeply", source)]
                            ) from None
    origins: dict[Path_, str] = {}
    c = _Checker(source, lines, origins)
    for d in dups:
        c.add(d, "duplicate key (YAML keeps only the last one)")
    if doc is None:
        doc = {}
    if not isinstance(doc, Mapping):
        c.bad((), doc, "a mapping with keys " + ", ".join(TOP_KEYS))
        c.raise_if_any()
    doc = dict(doc)
    for key in doc:
        if key not in TOP_KEYS:
            c.unknown((str(key),), key, TOP_KEYS)
    _apply_overrides(doc, overrides, origins, c)
    limits = _check_limits(c, doc.get("limits"))
    c.max_runs = limits.max_runs

    name = _check_name(c, doc.get("name", default_name), ("name",)) or "invalid"
    description = doc.get("description") or ""
    if not isinstance(description, str):
        c.bad(("description",), description, "a string")
        description = ""
    params = _check_settings(c, doc.get("parameters"), "parameters", PARAMETER_TYPES,
                             NUMERICS_TYPES, "numerics")
    numerics = _check_settings(c, doc.get("numerics"), "numerics", NUMERICS_TYPES,
                               PARAMETER_TYPES, "parameters")
    if AMB in params and "alpha" in params:
        c.add(("parameters", AMB), "set either 'alpha' or 'alpha_minus_B', not both")
    store = _check_store(c, doc.get("store"), numerics)
    base = {**{k: "parameters" for k in params}, **{k: "numerics" for k in numerics}}
    dims = _check_sweep(c, doc.get("sweep"), base)
    seeds = _check_seeds(c, doc.get("seeds"))
    fits = _check_products(c, doc.get("fits"), "fits")
    # no figures key (or null): the default, every figure that applies; [] means none
    figures = (None if doc.get("figures") is None
               else _check_products(c, doc.get("figures"), "figures"))
    execution = _check_execution(c, doc.get("execution"))
    from .refine.config import check_refine  # local import: sweep.refine imports this module

    refine = check_refine(c, doc.get("refine"), dims, seeds)
    campaign = Campaign(
        name=name, description=description, parameters=params, numerics=numerics,
        dims=dims, seeds=seeds, store=store, fits=fits, figures=figures, execution=execution,
        limits=limits, source=source, text=text, overrides=overrides.describe(),
        refine=refine,
    )
    # Sizes first, by arithmetic: nothing below is built for a grid that is too large.
    before_bounds = len(c.problems)
    if campaign.n_runs > limits.max_runs:
        sizes = " x ".join(f"{len(d)} ({d.name})" for d in dims)
        c.add(("sweep",) if dims else ("seeds",),
              f"{campaign.n_runs} runs ({sizes + ' x ' if dims else ''}{len(seeds)} seeds); "
              f"allowed: at most {limits.max_runs} (limits.max_runs)")
    _check_memory(c, campaign)
    if len(c.problems) > before_bounds:  # out of bounds: stop before any point is built
        c.raise_if_any()
    _check_product_axes(c, campaign)
    from .expand import check_points  # local import: expand depends on this module

    # The values are checked by the model even when the structure has problems, so that
    # every mistake of the file is reported in one pass (on what could be read of it).
    structural = list(c.problems)
    try:
        check_points(campaign, c)
    except Exception:  # noqa: BLE001 - a structure too broken to build points
        if not structural:
            raise
        c.problems[:] = structural
    c.raise_if_any()
    return campaign


def _check_limits(c: _Checker, raw: Any) -> LimitsSpec:
    lim = c.mapping(("limits",), raw, LIMITS_KEYS)
    max_runs = lim.get("max_runs", DEFAULT_MAX_RUNS)
    if not _is_int(max_runs) or max_runs < 1:
        c.bad(("limits", "max_runs"), max_runs, "an integer >= 1 (the most runs a campaign "
              "may have)")
        max_runs = DEFAULT_MAX_RUNS
    memory = None
    if lim.get("run_memory") is not None:
        memory = parse_size(lim["run_memory"])
        if memory is None:
            c.bad(("limits", "run_memory"), lim["run_memory"], "a size such as '8GB' (the "
                  "most memory one run may need)")
    return LimitsSpec(max_runs=int(max_runs), run_memory=memory)


def run_memory_limit(campaign: Campaign) -> tuple[int | None, str]:
    """The memory one run may use, and whose limit it is: ``limits.run_memory``, else the
    worker's (``execution.memory_limit``; a dask-jobqueue job's ``memory`` over its
    ``processes``; on the local cluster the memory here over the workers). ``None`` when it
    is not known (an external scheduler without ``limits.run_memory``)."""
    from .limits import available_memory

    if campaign.limits.run_memory is not None:
        return campaign.limits.run_memory, "limits.run_memory"
    ex = campaign.execution
    if ex.memory_limit is not None and parse_size(ex.memory_limit) is not None:
        return parse_size(ex.memory_limit), "execution.memory_limit"
    if ex.cluster is not None:
        memory = parse_size(ex.cluster.options.get("memory"))
        processes = ex.cluster.options.get("processes") or 1
        if memory is not None and _is_int(processes) and processes >= 1:
            return memory // int(processes), "execution.cluster memory / processes"
        return None, ""
    if ex.scheduler is not None:
        return None, ""
    total = available_memory()
    if total is None:
        return None, ""
    workers = ex.workers or max(1, (os.cpu_count() or 1) // ex.threads_per_worker)
    workers = min(workers, max(1, (os.cpu_count() or 1)))  # at most one run per core at once
    per = total // (workers * ex.threads_per_worker)
    return per, f"one local worker's share of this machine's memory ({workers} worker(s))"


def _check_memory(c: _Checker, campaign: Campaign) -> None:
    """Refuse a grid whose largest run needs more memory than a worker has (estimated from
    the resolution and the mechanics: :func:`sweep.limits.run_memory_bytes`)."""
    from .limits import fmt_bytes, run_memory_bytes

    limit, what = run_memory_limit(campaign)
    if limit is None:
        return
    axes = {a.name: a.values for a in campaign.axes}
    resolutions = axes.get("resolution", (campaign.numerics.get("resolution",
                                                                Numerics.resolution),))
    mechanics = axes.get("mechanics", (campaign.numerics.get("mechanics",
                                                             Numerics.mechanics),))
    for n in resolutions:
        for mech in mechanics:
            if not _is_int(n) or n < 1:
                continue  # the model's own check reports it
            need = run_memory_bytes(int(n), str(mech))
            if need > limit:
                path: Path_ = (("sweep", "axes", "resolution") if "resolution" in axes
                               else ("numerics", "resolution"))
                c.add(path, f"got {n}: one run ({mech} mechanics) needs about "
                      f"{fmt_bytes(need)}, more than {what} allows ({fmt_bytes(limit)}); "
                      "allowed: a lower resolution, or more memory per run (limits.run_memory,"
                      " execution.memory_limit, fewer workers)")
                return


#: Options of fits and figures that name a sweep axis, and those that map axes to values.
AXIS_OPTIONS = ("axis", "activity", "strain")
SELECT_OPTIONS = ("select", "snapshot")


def _check_product_axes(c: _Checker, campaign: Campaign) -> None:
    """Fits' and figures' options against the registries (unknown options, bad values) and
    against the campaign's axes (an option that names an axis must name one of them)."""
    names = [a.name for a in campaign.axes]
    if AMB in names:
        names.append("alpha")
    for kind, products in (("fits", campaign.fits), ("figures", campaign.figures or ())):
        for i, product in enumerate(products):
            path: Path_ = (kind, i, product.name)
            for problem in _registry_problems(kind, product):
                c.add(path, problem)
            options = product.options
            for key in AXIS_OPTIONS:
                value = options.get(key)
                if value is not None and value not in names:
                    c.bad((*path, key), value, "a sweep axis of this campaign ("
                          + (", ".join(names) or "none") + ")"
                          + (suggest(value, names) if isinstance(value, str) else ""))
            chosen = [options.get(k) for k in SELECT_OPTIONS]
            snaps = options.get("snapshots")
            if isinstance(snaps, Sequence) and not isinstance(snaps, str):
                chosen.extend(snaps)
            for mapping in chosen:
                if not isinstance(mapping, Mapping):
                    continue
                for axis in mapping:
                    if axis not in names:
                        c.bad((*path,), axis, "sweep axes of this campaign in select / "
                              "snapshot options (" + (", ".join(names) or "none") + ")")


def _registry_problems(kind: str, product: Product) -> list[str]:
    try:
        if kind == "figures":
            from .figures import option_problems

            return option_problems(product.name, product.options)
        from .fits import REGISTRY, _problems

        spec = REGISTRY.get(product.name)
        return [] if spec is None else _problems(product.name, product.options, spec.options)
    except ModuleNotFoundError:
        return []


def load_campaign(path: str | Path, overrides: Overrides | None = None) -> Campaign:
    """Read and validate a campaign file (see :func:`parse_campaign`)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise CampaignError(str(p), [Problem("", f"cannot read the file: {e.strerror}",
                                             str(p))]) from None
    except UnicodeDecodeError:
        raise CampaignError(str(p), [Problem("", "not a UTF-8 text file", str(p))]) from None
    return parse_campaign(text, str(p), overrides, default_name=p.stem)
