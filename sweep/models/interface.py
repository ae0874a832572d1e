"""The model interface: what a model declares so that the campaign manager can run it.

A model is an object with the attributes and methods of :class:`Model`. The campaign
manager's core (spec, run, store, outputs, refine, precision, verify, report) reads a model's
settings, observables and capabilities from here and runs a point through
:meth:`Model.run`; it names no parameter or observable of any model.

- :class:`Setting`: one input of a run (a physical parameter or a numerical choice), with its
  type, default, long name and units, and whether a campaign may sweep it or give it a time
  protocol.
- :class:`Observable`: one scalar of a run that phase.nc keeps per point, declared once with
  its metadata and the rules that aggregate it: the seed mean (arithmetic or geometric), how a
  change between two runs is measured (absolute or relative) and whether it classifies the
  pattern.
- :class:`Capabilities`: the optional parts of the machinery a model supports (exact
  continuation, protocols, batched runs, a cost model, a resolution rule, memory per run).
- :class:`RunRequest` and :class:`RunOutcome`: one point and seed in, the run's dataset and
  its end state out.

Models are found by name through the entry point group :data:`ENTRY_POINT_GROUP`
(:mod:`nematic_solids.sweep.models.registry`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Protocol, runtime_checkable

if TYPE_CHECKING:
    import xarray as xr
    from numpy.typing import ArrayLike

#: The entry point group under which packages register models (``name = "module:object"``).
ENTRY_POINT_GROUP = "nematic_solids.models"
#: The model a campaign runs when it names none (``model:`` absent): this paper's.
DEFAULT_MODEL = "nematic"

SETTING_KINDS = ("parameter", "numerics")
SEED_MEANS = ("arithmetic", "geometric")
CHANGES = ("absolute", "relative")


@dataclass(frozen=True)
class Setting:
    """One input of a run.

    ``kind`` is ``"parameter"`` (physics: part of a point's coordinates) or ``"numerics"``
    (how the run is computed). ``type`` is the Python type a campaign value must have
    (``float`` accepts ints); ``choices`` lists the allowed words of a ``str`` setting."""

    name: str
    kind: Literal["parameter", "numerics"]
    type: type
    default: Any
    long_name: str
    units: str = "1"
    #: whether a campaign may give it several values (an axis of the phase diagram)
    sweepable: bool = True
    #: whether it may follow a time protocol within a run (a ramp, a sine, steps)
    protocol: bool = False
    #: the symbol that figures and reports print (plain text or LaTeX between $...$)
    symbol: str | None = None
    choices: tuple[str, ...] = ()
    #: whether it chooses only how a run is executed, not what it computes (a backend whose
    #: results agree to rounding): recorded in the run file, never part of a run's identity
    execution: bool = False

    def __post_init__(self) -> None:
        if self.kind not in SETTING_KINDS:
            raise ValueError(f"setting {self.name}: kind {self.kind!r} not in {SETTING_KINDS}")
        if self.choices and self.type is not str:
            raise ValueError(f"setting {self.name}: choices need type str")

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` has this setting's type (bools are not numbers; ints are
        floats), and is one of its choices if it has any."""
        if isinstance(value, bool) and self.type is not bool:
            return False
        wanted: tuple[type, ...] = (int, float) if self.type is float else (self.type,)
        ok = isinstance(value, wanted)
        return ok and (not self.choices or value in self.choices)


@dataclass(frozen=True)
class Observable:
    """One scalar of a run that phase.nc keeps per point, and how it is aggregated.

    ``scalar`` names the run file's scalar it is read from (often ``name`` itself, or its
    value at the end, ``<name>_final``). ``seed_mean`` is the mean over seeds: ``"geometric"``
    for quantities that span decades between seeds (a pattern's variance near onset),
    ``"arithmetic"`` otherwise. ``change`` is how two runs' values are compared (verification,
    convergence): ``"relative"`` (``|a - b| / |b|``) or ``"absolute"`` (``|a - b|``). ``classifies``
    marks the observable whose seed mean decides the pattern class (:meth:`Model.classify`
    reads it)."""

    name: str
    scalar: str
    long_name: str
    units: str = "1"
    seed_mean: Literal["arithmetic", "geometric"] = "arithmetic"
    change: Literal["absolute", "relative"] = "relative"
    classifies: bool = False
    #: whether it measures a pattern, so that its seed mean is taken over the patterned runs
    #: only (a relaxed run's value is the floor of the solver or its initial texture's)
    pattern: bool = False
    #: whether a verification compares it when the campaign's ``verify:`` lists none (a
    #: model that marks none: every observable)
    verify: bool = False
    symbol: str | None = None

    def __post_init__(self) -> None:
        if self.seed_mean not in SEED_MEANS:
            raise ValueError(f"observable {self.name}: seed_mean not in {SEED_MEANS}")
        if self.change not in CHANGES:
            raise ValueError(f"observable {self.name}: change not in {CHANGES}")

    def mean(self, values: ArrayLike) -> float:
        """The seed mean of ``values`` by ``seed_mean``, over the finite ones (and the
        positive ones for the geometric mean); NaN when none is left."""
        import numpy as np  # here: reading a campaign file needs the declarations only

        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v)]
        if self.seed_mean == "geometric":
            v = v[v > 0]
            return float(10 ** np.mean(np.log10(v))) if v.size else math.nan
        return float(np.mean(v)) if v.size else math.nan

    def difference(self, base: float, value: float) -> float:
        """How ``value`` differs from ``base`` by ``change``: ``value - base``, or that
        over ``|base|`` (0 where both are 0, infinite where only the base is); NaN where
        either is not finite."""
        if not (math.isfinite(base) and math.isfinite(value)):
            return math.nan
        if self.change == "absolute":
            return value - base
        if base == 0:
            return 0.0 if value == 0 else math.inf
        return (value - base) / abs(base)


@dataclass(frozen=True)
class Capabilities:
    """The optional parts of the machinery a model supports. A campaign section that needs a
    capability the model lacks is refused at validation, naming the model and the section."""

    #: a longer run continues a shorter one's end state, with results equal to a run that
    #: never stopped (otherwise a longer run starts again from t = 0)
    exact_continuation: bool = False
    #: a campaign's ``protocol:`` section gives its settings functions of time (those whose
    #: :attr:`Setting.protocol` is true; the forms of :mod:`nematic_solids.model.protocol`)
    protocols: bool = False
    #: a run may start from another run's end state (chains, ``initial.from``)
    start_from_state: bool = False
    #: several seeds of one point run as one batch (:meth:`BatchedModel.run_batch`)
    batched: bool = False
    #: the model's ``cost_seconds`` predicts a run's wall time
    cost_model: bool = False
    #: a resolution setting may be a rule that gives each point its grid
    #: (:class:`ResolutionRule`: :meth:`~ResolutionRule.resolution`, :meth:`~ResolutionRule.rule`)
    resolution_rule: bool = False
    #: the model's ``memory_bytes`` bounds a run's memory
    memory_per_run: bool = False
    #: the precisions its runs can compute in (the first is the default)
    precisions: tuple[str, ...] = ("float64",)


@dataclass(frozen=True)
class RunRequest:
    """One run: a point (its parameter and numerics values, every setting given) and a seed.

    ``start`` is the model's own end state of an earlier run to continue (exact
    continuation: the same point, a shorter ``t_final``) and ``initial`` a state to begin from
    at t = 0 instead of the seeded initial condition (chains, ``initial.from``); both are
    objects the same model returned. ``checkpoint`` is called with the run's state after the
    first save at least ``checkpoint_every`` (simulated time) or ``checkpoint_wall`` (seconds
    of wall time) after the last one; ``progress`` with the simulated time reached."""

    parameters: Mapping[str, Any]
    numerics: Mapping[str, Any]
    seed: int
    start: Any | None = None
    initial: Any | None = None
    checkpoint: Callable[[Any], None] | None = None
    checkpoint_every: float = float("inf")
    checkpoint_wall: float = float("inf")
    progress: Callable[[float], None] | None = None


@dataclass
class RunOutcome:
    """A run's result: its dataset (time series, snapshots, the observables' scalars as
    attributes or 0-d variables) and its end state (None where the run failed or the model
    keeps none)."""

    dataset: xr.Dataset
    end_state: Any | None = None
    #: messages a user should see in the run's record (e.g. a continuation that is not exact)
    warnings: tuple[str, ...] = field(default_factory=tuple)


@runtime_checkable
class Model(Protocol):
    """What the campaign manager needs of a model (see the module docstring)."""

    #: the name a campaign gives (``model: NAME``) and the entry point's name
    name: str
    long_name: str
    settings: tuple[Setting, ...]
    observables: tuple[Observable, ...]
    capabilities: Capabilities

    def point(self, parameters: Mapping[str, Any], numerics: Mapping[str, Any]) -> tuple[Any, Any]:
        """A point's settings as the model's own objects, every setting filled in from its
        default and checked: ``(parameters, numerics)``, each hashable, read by attribute,
        with ``to_dict()`` (:func:`point_values` builds them for a model that has no objects
        of its own). Raises :class:`SettingError` (or a ``ValueError`` with the same
        ``name``, ``value`` and ``allowed``) for a value the model cannot run."""
        ...

    def run(self, request: RunRequest) -> RunOutcome:
        """Run one point and seed; raise an exception whose message says why a run fails."""
        ...

    def classify(self, values: Mapping[str, float]) -> str:
        """The pattern class of a point from its observables' seed means (``values``)."""
        ...


class SettingError(ValueError):
    """A setting's value that the model cannot run: the setting's ``name``, the ``value``
    given and what is ``allowed`` (the campaign's validation reports it at the key that set
    it)."""

    def __init__(self, name: str, value: Any, allowed: str):
        super().__init__(f"{name} = {value!r}: allowed: {allowed}")
        self.name, self.value, self.allowed = name, value, allowed


def setting_error(e: ValueError) -> SettingError:
    """``e`` as a :class:`SettingError`: itself, or one with its ``name``, ``value`` and
    ``allowed`` where it has them (a model's own error class), else its message as what is
    allowed."""
    if isinstance(e, SettingError):
        return e
    if all(hasattr(e, a) for a in ("name", "value", "allowed")):
        return SettingError(str(e.name), e.value, str(e.allowed))  # type: ignore[attr-defined]
    return SettingError("settings", "", str(e))


class Values(Mapping[str, Any]):
    """A point's settings of one kind as a model without objects of its own keeps them
    (:func:`point_values`): immutable and hashable, read as a mapping or by attribute
    (``values.t_final``), ``to_dict()`` for the plain dict."""

    __slots__ = ("_values", "_hash")

    def __init__(self, values: Mapping[str, Any]):
        object.__setattr__(self, "_values", dict(values))
        object.__setattr__(self, "_hash", None)

    def __getitem__(self, key: str) -> Any:
        return self._values[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f"no setting {name!r}") from None

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("a point's settings are immutable")

    def __hash__(self) -> int:
        if self._hash is None:
            object.__setattr__(self, "_hash", hash(repr(sorted(self._values.items()))))
        return self._hash  # type: ignore[return-value]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Values) and self._values == other._values

    def __reduce__(self) -> tuple[Any, ...]:
        return (Values, (self._values,))

    def __repr__(self) -> str:
        return f"Values({self._values!r})"

    def to_dict(self) -> dict[str, Any]:
        return dict(self._values)


def point_values(
    model: Model, parameters: Mapping[str, Any], numerics: Mapping[str, Any]
) -> tuple[Values, Values]:
    """A point's parameters and numerics as :class:`Values`, every setting of ``model``
    filled in from its default: an unknown name, a value of the wrong type or not among its
    setting's choices raises :class:`SettingError`; an int given for a float setting becomes
    a float."""
    out: dict[str, dict[str, Any]] = {"parameter": {}, "numerics": {}}
    known = {s.name: s for s in model.settings}
    for section, given in (("parameter", parameters), ("numerics", numerics)):
        for name, value in given.items():
            s = known.get(name)
            if s is None or s.kind != section:
                names = [k for k, v in known.items() if v.kind == section]
                raise SettingError(name, value, f"a {section} of model {model.name}: {names}")
            if s.protocol and isinstance(value, Mapping):  # a function of time, as written
                out[section][name] = value
                continue
            if not s.accepts(value):
                want = f"one of {list(s.choices)}" if s.choices else f"a {s.type.__name__}"
                raise SettingError(name, value, want)
            out[section][name] = float(value) if s.type is float else value
    for s in model.settings:
        out[s.kind].setdefault(s.name, s.default)
    return Values(out["parameter"]), Values(out["numerics"])


@runtime_checkable
class State(Protocol):
    """What the campaign manager reads of a model's end state or checkpoint: its time and
    its dataset (written as the run file's group ``state`` or as a rolling checkpoint)."""

    t: float

    def to_dataset(self, snapshots: bool = True) -> xr.Dataset: ...


@runtime_checkable
class StateCodec(Protocol):
    """A model whose end states and checkpoints the campaign manager keeps in files as
    ``State.to_dataset`` writes them, and reads back with :meth:`state_from_dataset` (a
    run file's group ``state``, a rolling checkpoint). A model that keeps states and is not a
    StateCodec is the paper's, whose states the campaign manager reads with
    :mod:`nematic_solids.model.checkpoint`."""

    def state_from_dataset(self, ds: xr.Dataset) -> State:
        """The state ``ds`` holds; ``ValueError`` where it is not one of this model's or it
        fails its checksum."""
        ...


@runtime_checkable
class Compiled(Protocol):
    """A model whose runs use compiled kernels: :meth:`warm_up` compiles them (or loads them
    from a disk cache) with tiny runs, once per host before a campaign's runs start."""

    def warm_up(
        self, points: Sequence[tuple[Mapping[str, Any], Mapping[str, Any]]]
    ) -> dict[str, Any]:
        """Tiny runs of each ``(parameters, numerics)``; what it did (times, counts) as a
        JSON-ready mapping. Never raises for a failed tiny run."""
        ...

    def warm_kind(self, parameters: Any, numerics: Any) -> Hashable:
        """The kind of run whose kernels a point's runs use (points of one kind share one
        warm-up run)."""
        ...

    def import_kernels(self) -> None:
        """Import the modules its runs need (a worker does it once, under a lock, before its
        first run: two threads importing them at once can deadlock)."""
        ...


@runtime_checkable
class IdentityRules(Protocol):
    """A model with rules of its own for what of a point enters its runs' ids (e.g. settings
    left out at the default they had before they existed, so that older runs keep their ids).
    Without them every setting enters but those marked :attr:`Setting.execution`."""

    def identity_settings(
        self, parameters: Mapping[str, Any], numerics: Mapping[str, Any]
    ) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
        """The parameters and numerics (complete dicts) as they enter the canonical text,
        and other entries of the point's own for it."""
        ...

    def start_identity(
        self, numerics: Mapping[str, Any], start: Mapping[str, Any]
    ) -> dict[str, Any]:
        """What a run that begins from another run's state (``start``) adds to its canonical
        text besides the start itself."""
        ...


@runtime_checkable
class ResolutionRule(Protocol):
    """A model whose resolution setting may be a rule (a grid chosen at each point from its
    parameters) instead of a number."""

    def resolution(self, setting: Any, parameters: Mapping[str, Any]) -> Any:
        """The grid the resolution ``setting`` gives at the point ``parameters``."""
        ...

    def rule(self, setting: Any) -> str | None:
        """The rule a resolution ``setting`` is, described; None where it is a number."""
        ...


def resolution_rule(model: Model, setting: Any) -> str | None:
    """The rule the resolution ``setting`` of ``model`` is, described; None where it is a
    number or the model has no rules."""
    if model.capabilities.resolution_rule and isinstance(model, ResolutionRule):
        return model.rule(setting)
    return None


@runtime_checkable
class BatchedModel(Model, Protocol):
    """A model whose capabilities say ``batched``: several seeds of one point in one call,
    on a device."""

    def check_device(self, device: str) -> str:
        """The device ``device`` names on this host, described; raises an error saying why
        where there is none."""
        ...

    def run_batch(self, requests: Sequence[RunRequest], device: str) -> list[RunOutcome]:
        """The runs ``requests`` (one point: they differ by seed, start and initial only) as
        one batch on ``device``, their outcomes in the same order; raise where the batch
        fails as a whole."""
        ...


def batched(model: Model) -> BatchedModel:
    """``model`` as a :class:`BatchedModel`; ValueError where its capabilities do not say
    ``batched``."""
    if not model.capabilities.batched or not isinstance(model, BatchedModel):
        raise ValueError(f"model {model.name} does not run batches of seeds")
    return model


def setting(model: Model, name: str) -> Setting:
    """``model``'s setting ``name`` (KeyError with the known names otherwise)."""
    for s in model.settings:
        if s.name == name:
            return s
    raise KeyError(f"model {model.name} has no setting {name!r}; it has {setting_names(model)}")


def setting_names(model: Model, kind: str | None = None) -> list[str]:
    """The names of ``model``'s settings (of one ``kind`` if given), in declaration order."""
    return [s.name for s in model.settings if kind is None or s.kind == kind]


def observable(model: Model, name: str) -> Observable:
    """``model``'s observable ``name`` (KeyError with the known names otherwise)."""
    for o in model.observables:
        if o.name == name:
            return o
    known = [o.name for o in model.observables]
    raise KeyError(f"model {model.name} has no observable {name!r}; it has {known}")


def classifier(model: Model) -> Observable:
    """The observable whose seed mean classifies ``model``'s points (``classifies``; the
    first if several do); ValueError where none does."""
    for o in model.observables:
        if o.classifies:
            return o
    raise ValueError(f"model {model.name} declares no observable that classifies a pattern")


def cost_seconds(model: Model, parameters: Any, numerics: Any) -> float:
    """The predicted CPU seconds of one run of ``model`` at a point (its objects,
    :meth:`Model.point`); NaN for a model without a cost model."""
    if not model.capabilities.cost_model:
        return math.nan
    return float(model.cost_seconds(parameters, numerics))  # type: ignore[attr-defined]


def setting_types(model: Model, kind: str) -> dict[str, str]:
    """Each setting of ``kind`` -> its type's name (``float``, ``int``, ``str``, ``bool``,
    ``list``), in declaration order."""
    return {s.name: s.type.__name__ for s in model.settings if s.kind == kind}


def verified(model: Model) -> tuple[str, ...]:
    """What a verification compares unless the campaign lists observables: those marked
    ``verify``, else every observable of ``model``."""
    marked = tuple(o.name for o in model.observables if o.verify)
    return marked or tuple(o.name for o in model.observables)


def defaults(model: Model, kind: str) -> dict[str, Any]:
    """The default value of each of ``model``'s settings of ``kind``."""
    return {s.name: s.default for s in model.settings if s.kind == kind}
