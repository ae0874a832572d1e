"""Any py-pde equation as a model: :func:`pde_model` turns a py-pde ``PDEBase`` subclass (or a
factory of a ``pde.PDE`` of expressions), a frozen settings dataclass, a grid rule, a seeded
initial-state rule and a few measures into a :class:`~.interface.Model` that campaigns run.

**Settings.** A frozen dataclass that inherits :class:`SolverSettings` (the numerics every run
needs: ``t_final``, ``dt``, ``save_every``, ``scheme``, ``adaptive``, ``tolerance``, ``backend``)
and adds the equation's parameters. Each field's ``metadata`` gives its
:class:`~.interface.Setting`: ``long_name``, ``units``, ``kind`` (``"parameter"``, the default
of a user's field, or ``"numerics"``), ``sweepable``, ``protocol`` (the setting may be a function
of time), ``symbol``, ``choices`` and ``execution`` (it chooses how a run executes, not what it
computes, and stays out of the run's identity). Use :func:`parameter` and :func:`numerics` to
write them.

**Measures** are the observables, in the style of py-pde's trackers: a :class:`Measure` declares
its :class:`~.interface.Observable` once; :meth:`Measure.handle` gives its value from the state
at each save time (the run's time series) and :meth:`Measure.finalize` the run's scalar from
the series and the final state (by default the last value; the scalar is named by
``observable.scalar``). A measure holds no run state: the :class:`Recorder` of a run does.

**A run** (:meth:`PDEModel.run`) builds the settings, the grid and the PDE, the initial state
(from the seed through ``numpy.random.default_rng``, or a given state), and integrates it with
the py-pde solver ``scheme`` (explicit ``euler`` or ``runge-kutta``, classic fourth-order RK at a
fixed step) from its start time to ``t_final``, saving every ``save_every``. It returns the time
series of the measures, the final field and the scalars as an ``xarray.Dataset``, and a
:class:`PDEState` (the field's data, the time reached and the series so far).

**Chains and continuation.** ``RunRequest.initial`` begins a run at t = 0 from another run's
end state (its field only; the model's ``perturb`` rule may then add noise, seeded).
``RunRequest.start`` continues a run of the same point from its end
state (field, time and series) to a later ``t_final``. With a fixed step that divides
``save_every``, a continued run takes the same steps on the same data as a run that never
stopped, so its results are bitwise equal (tests/sweep/test_model_pypde.py); with adaptive
stepping the step size at the stop is not kept, so a continued run is close but not equal, and
its outcome says so in ``warnings`` and in the dataset's ``continuation`` attribute.

**Protocols.** A setting declared with ``protocol=True`` may be given as a function of time (any
object with ``__call__(t) -> float``); the PDE factory receives it as the setting's value and
must build a PDE that evaluates it at each time (a ``pde.PDE`` of expressions with
``user_funcs``, on the numpy backend).
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pde
import xarray as xr
from pde.fields.base import FieldBase

from .interface import (
    Capabilities,
    Observable,
    RunOutcome,
    RunRequest,
    Setting,
    SettingError,
    point_values,
)
from .pypde_record import FunctionMeasure, Measure, PDEState, Recorder

__all__ = [  # the adapter's API: what a model built on it imports from here
    "FunctionMeasure",
    "Measure",
    "PDEModel",
    "PDEState",
    "Recorder",
    "SolverSettings",
    "numerics",
    "parameter",
    "pde_model",
]

#: the explicit py-pde solvers a run may use (``SolverSettings.scheme``)
SCHEMES = ("runge-kutta", "euler")
BACKENDS = ("numpy", "numba")
#: a save time must be a whole number of steps to within this fraction of a step
STEP_ROUNDING = 1e-9


def parameter(default: Any, long_name: str, units: str = "1", **meta: Any) -> Any:
    """A physical parameter of a settings dataclass (a field with its metadata)."""
    return field(
        default=default,
        metadata={"kind": "parameter", "long_name": long_name, "units": units, **meta},
    )


def numerics(default: Any, long_name: str, units: str = "1", **meta: Any) -> Any:
    """A numerical choice of a settings dataclass (a field with its metadata)."""
    return field(
        default=default,
        metadata={"kind": "numerics", "long_name": long_name, "units": units, **meta},
    )


@dataclass(frozen=True)
class SolverSettings:
    """The numerics of every py-pde run; a model's settings dataclass inherits them."""

    t_final: float = numerics(100.0, "final time")
    dt: float = numerics(1e-3, "time step (the first one where adaptive)")
    save_every: float = numerics(1.0, "time between saves of the observables")
    scheme: str = numerics("runge-kutta", "py-pde explicit solver", choices=SCHEMES)
    adaptive: bool = numerics(False, "adaptive time stepping (continuation is then not exact)")
    tolerance: float = numerics(1e-4, "error tolerance of adaptive stepping")
    backend: str = numerics(
        "numpy",
        "py-pde backend (numba compiles once per run)",
        choices=BACKENDS,
        execution=True,
    )


def settings_of(cls: type) -> tuple[Setting, ...]:
    """The :class:`~.interface.Setting` of each field of the settings dataclass ``cls``."""
    if not (dataclasses.is_dataclass(cls) and issubclass(cls, SolverSettings)):
        raise TypeError(f"{cls!r}: the settings must be a dataclass that inherits SolverSettings")
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        meta = f.metadata
        if f.default is dataclasses.MISSING:
            raise TypeError(f"{cls.__name__}.{f.name}: every setting needs a default")
        out.append(
            Setting(
                name=f.name,
                kind=meta.get("kind", "parameter"),
                type=hints[f.name],
                default=f.default,
                long_name=meta.get("long_name", f.name),
                units=meta.get("units", "1"),
                sweepable=meta.get("sweepable", True),
                protocol=meta.get("protocol", False),
                symbol=meta.get("symbol"),
                choices=tuple(meta.get("choices", ())),
                execution=meta.get("execution", False),
            )
        )
    return tuple(out)


def _whole(ratio: float) -> bool:
    return abs(ratio - round(ratio)) <= STEP_ROUNDING * max(1.0, abs(ratio))


@dataclass
class PDEModel:
    """A py-pde equation as a :class:`~.interface.Model` (built by :func:`pde_model`)."""

    name: str
    long_name: str
    settings_class: type
    pde_factory: Callable[[Any], pde.PDEBase]
    grid: Callable[[Any], pde.GridBase]
    initial: Callable[[pde.GridBase, Any, np.random.Generator], FieldBase]
    measures: tuple[Measure, ...]
    classifier: Callable[[Mapping[str, float]], str] | None = None
    perturb: Callable[[FieldBase, Any, np.random.Generator], None] | None = None
    check: Callable[[Any], None] | None = None
    settings: tuple[Setting, ...] = ()
    observables: tuple[Observable, ...] = ()
    capabilities: Capabilities = Capabilities()

    def point(self, parameters: Mapping[str, Any], numerics: Mapping[str, Any]) -> tuple[Any, Any]:
        """A point's settings as :class:`~.interface.Values`, checked as a run checks them
        (types and choices, the steps landing on the save times, the grid built); raises
        :class:`~.interface.SettingError`."""
        p, n = point_values(self, parameters, numerics)
        s = self._settings({**p, **n})
        _check_steps(s)
        try:
            self.grid(s)
        except (ValueError, TypeError) as e:
            raise SettingError("grid", str(e), "settings that give a grid") from None
        if self.check is not None:
            try:
                self.check(s)
            except SettingError:
                raise
            except ValueError as e:
                raise SettingError("settings", "", str(e)) from None
        return p, n

    def make_settings(self, request: RunRequest) -> Any:
        """The settings dataclass of a request (every value checked against its setting)."""
        return self._settings({**request.parameters, **request.numerics})

    def _settings(self, given: Mapping[str, Any]) -> Any:
        known = {s.name: s for s in self.settings}
        unknown = sorted(set(given) - set(known))
        if unknown:
            raise ValueError(
                f"model {self.name}: unknown settings {unknown}; it has {sorted(known)}"
            )
        for key, value in given.items():
            s = known[key]
            if s.protocol and callable(value):
                continue
            if not s.accepts(value):
                want = f"one of {list(s.choices)}" if s.choices else s.type.__name__
                raise ValueError(f"model {self.name}: setting {key} = {value!r} is not {want}")
        values = {
            k: float(v) if known[k].type is float and not callable(v) else v
            for k, v in given.items()
        }
        return self.settings_class(**values)

    def run(self, request: RunRequest) -> RunOutcome:
        """One point and seed (the module docstring says what a run does)."""
        s = self.make_settings(request)
        _check_steps(s)
        warnings: list[str] = []
        grid = self.grid(s)
        equation = self.pde_factory(s)
        start = request.start
        if start is not None and request.initial is not None:
            raise ValueError("a run continues (start) or begins from a state (initial), not both")
        state = self.initial(grid, s, np.random.default_rng(request.seed))
        t0 = 0.0
        if start is not None or request.initial is not None:
            given = start if start is not None else request.initial
            if not isinstance(given, PDEState) or given.data.shape != state.data.shape:
                raise ValueError(
                    f"model {self.name}: a start or initial state must be a "
                    f"PDEState of shape {state.data.shape} (this model's grid)"
                )
            state.data[...] = given.data
            if request.initial is not None and self.perturb is not None:
                self.perturb(state, s, np.random.default_rng([request.seed, 1]))
        if start is not None:
            t0 = start.t
            if t0 > s.t_final + STEP_ROUNDING * s.save_every:
                raise ValueError(
                    f"cannot continue the state at t = {t0} to the shorter t_final = {s.t_final}"
                )
            if s.adaptive:
                warnings.append(CONTINUATION_ADAPTIVE)
        recorder = Recorder(
            self.measures, request, s.save_every, start if isinstance(start, PDEState) else None
        )
        solver = _solver(equation, s)
        controller = pde.Controller(solver, t_range=(t0, s.t_final), tracker=[recorder])
        final = controller.run(state, dt=s.dt)  # type: ignore[type-var]  # any field
        if final is None:  # only an MPI client returns none
            raise RuntimeError("py-pde returned no final state")
        t_end = float(controller.info.get("t_final", s.t_final))
        end = recorder.state(final, t_end)
        ds = self._dataset(recorder, final, s, request, solver, start is not None, warnings)
        return RunOutcome(dataset=ds, end_state=end, warnings=tuple(warnings))

    def _dataset(
        self,
        rec: Recorder,
        final: FieldBase,
        s: Any,
        request: RunRequest,
        solver: pde.SolverBase,
        continued: bool,
        warnings: list[str],
    ) -> xr.Dataset:
        times = np.array(rec.times)
        ds = xr.Dataset(coords={"time": ("time", times, {"units": "1"})})
        for m in self.measures:
            o = m.observable
            values = np.array(rec.values[o.name])
            ds[o.name] = ("time", values, {"long_name": o.long_name, "units": o.units})
            ds[o.scalar] = (
                (),
                m.finalize(times, values, final),
                {"long_name": f"{o.long_name} (run value)", "units": o.units},
            )
        axes = list(final.grid.axes)
        fields = final.fields if isinstance(final, pde.FieldCollection) else [final]
        for i, f in enumerate(fields):
            label = f.label or (f"field_{i}" if len(fields) > 1 else "u")
            coords = {a: c for a, c in zip(axes, final.grid.axes_coords, strict=True)}
            ds[f"{label}_final"] = xr.DataArray(
                np.array(f.data),
                dims=axes,
                coords=coords,
                attrs={"long_name": f"{label} at t_final"},
            )
        ds.attrs.update(
            model=self.name,
            seed=request.seed,
            solver=f"py-pde {s.scheme}, {'adaptive' if s.adaptive else 'fixed'} step "
            f"(dt = {s.dt:g}), backend {s.backend}",
            steps=int(solver.info.get("steps", 0)),
            continuation=("exact" if not s.adaptive else "not exact (adaptive step)")
            if continued
            else "none",
            warnings="; ".join(warnings),
        )
        for st in self.settings:
            v = getattr(s, st.name)
            ds.attrs[f"setting_{st.name}"] = repr(v) if callable(v) else v
        return ds

    def state_from_dataset(self, ds: xr.Dataset) -> PDEState:
        """The end state or checkpoint ``ds`` holds (:meth:`PDEState.from_dataset`)."""
        return PDEState.from_dataset(ds)

    def classify(self, values: Mapping[str, float]) -> str:
        if self.classifier is None:
            raise ValueError(f"model {self.name} declares no pattern classes")
        return self.classifier(values)


CONTINUATION_ADAPTIVE = (
    "continued with adaptive steps: the step size at the stop is not kept, "
    "so the result is close to, not equal to, a run that never stopped"
)


def _check_steps(s: Any) -> None:
    """Refuses save and final times that the step cannot land on (:class:`SettingError`)."""
    for name in ("t_final", "dt", "save_every"):
        v = getattr(s, name)
        if not (math.isfinite(v) and v > 0):
            raise SettingError(name, v, "a positive finite number")
    if not _whole(s.t_final / s.save_every):
        raise SettingError("t_final", s.t_final, f"a whole number of save_every = {s.save_every:g}")
    if not s.adaptive and not _whole(s.save_every / s.dt):
        raise SettingError(
            "save_every",
            s.save_every,
            f"a whole number of steps dt = {s.dt:g} (a fixed step lands on every save time)",
        )


def _solver(equation: pde.PDEBase, s: Any) -> pde.SolverBase:
    if s.scheme not in SCHEMES:
        raise ValueError(f"scheme {s.scheme!r} is not one of {SCHEMES}")
    return pde.SolverBase.from_name(
        s.scheme, equation, backend=s.backend, adaptive=s.adaptive, tolerance=s.tolerance
    )


def pde_model(
    name: str,
    pde_factory: type[pde.PDEBase] | Callable[[Any], pde.PDEBase],
    settings: type,
    grid: Callable[[Any], pde.GridBase],
    initial: Callable[[pde.GridBase, Any, np.random.Generator], FieldBase],
    measures: Sequence[Measure],
    *,
    long_name: str = "",
    classify: Callable[[Mapping[str, float]], str] | None = None,
    perturb: Callable[[FieldBase, Any, np.random.Generator], None] | None = None,
    check: Callable[[Any], None] | None = None,
) -> PDEModel:
    """A model of the py-pde equation ``pde_factory``.

    ``pde_factory`` is a ``PDEBase`` subclass (built with the parameter settings as its
    keyword arguments) or a function of the settings that returns a PDE; ``settings`` a frozen
    dataclass that inherits :class:`SolverSettings`; ``grid`` a function of the settings that
    returns the grid; ``initial(grid, settings, rng)`` the seeded initial state (draw every
    random number from ``rng``); ``measures`` the observables; ``classify`` the pattern class
    of a point from its observables' seed means; ``perturb(state, settings, rng)`` changes a
    state given as ``initial`` in place before the run (e.g. adds the noise of an experiment
    to a chain's start; its random numbers come from the seed too); ``check(settings)``
    refuses settings the equation cannot run (a ``ValueError``, best a
    :class:`~.interface.SettingError` naming the setting), called for every point of a
    campaign when it is validated, before anything runs."""
    declared = settings_of(settings)
    if isinstance(pde_factory, type):
        if not issubclass(pde_factory, pde.PDEBase):
            raise TypeError(f"{pde_factory!r} is not a py-pde PDEBase subclass")
        factory: Callable[[Any], pde.PDEBase] = ClassFactory(pde_factory, declared)
    else:
        factory = pde_factory
    observables = tuple(m.observable for m in measures)
    names = [o.name for o in observables]
    if len(set(names)) != len(names):
        raise ValueError(f"model {name}: observables named twice in {names}")
    caps = Capabilities(
        exact_continuation=True,
        # a setting declared protocol=True takes a function of time in a RunRequest; the
        # campaign's protocol: section (the nematic model's forms) is not wired to it
        protocols=False,
        start_from_state=True,
    )
    return PDEModel(
        name,
        long_name or name,
        settings,
        factory,
        grid,
        initial,
        tuple(measures),
        classify,
        perturb,
        check,
        declared,
        observables,
        caps,
    )


@dataclass(frozen=True)
class ClassFactory:
    """Builds a ``PDEBase`` subclass from the parameter settings as keyword arguments."""

    cls: type[pde.PDEBase]
    declared: tuple[Setting, ...]

    def __call__(self, s: Any) -> pde.PDEBase:
        return self.cls(
            **{d.name: getattr(s, d.name) for d in self.declared if d.kind == "parameter"}
        )
