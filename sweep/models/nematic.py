"""The paper's model (the active nematic solid of :mod:`nematic_solids.model`) as a plugin of
the model interface (:mod:`.interface`): :data:`MODEL`, registered as ``nematic``, the model a
campaign runs when it names none.

- Its settings are the fields of :class:`~nematic_solids.model.parameters.Parameters` (kind
  ``parameter``) and :class:`~nematic_solids.model.parameters.Numerics` (kind ``numerics``),
  read from the dataclasses: type, default and choices from the code, long names and symbols
  from :data:`nematic_solids.sweep.names.NAMES` or else the class docstring. The contractility
  ``alpha_minus_B`` (``alpha = B + alpha_minus_B``) is the input the paper sweeps; it, ``chi``
  and ``eps`` may follow a time protocol
  (:data:`nematic_solids.model.protocol.PROTOCOL_PARAMETERS`).
- Its observables (:data:`OBSERVABLES`) are declared here once, with their run scalar, long
  name and aggregation rules: ``sigma2_S`` is averaged geometrically over seeds (it spans
  decades between a relaxed and a patterned seed) and classifies a point (patterned above
  :data:`PATTERNED_ABOVE`).
- :meth:`Nematic.run` is :func:`nematic_solids.model.simulate.run` with its end state;
  :meth:`Nematic.run_batch` the accelerated backend's batch of seeds
  (:func:`nematic_solids.model.accelerated.datasets.batch_datasets`).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from nematic_solids.model.parameters import (
    BACKENDS,
    CHOICES,
    DISPLACEMENT,
    ERROR_NORMS,
    MECHANICS,
    PRECISIONS,
    SCHEMES,
    Numerics,
    Parameters,
    check_compatible,
)
from nematic_solids.model.protocol import PROTOCOL_PARAMETERS

from ..limits import run_memory_bytes
from ..names import NAMES
from . import nematic_identity
from .interface import Capabilities, Observable, RunOutcome, RunRequest, Setting

if TYPE_CHECKING:
    from nematic_solids.model.checkpoint import InitialState, RunState

#: The swept input for the contractility alpha - B (``alpha = B + alpha_minus_B``).
AMB = "alpha_minus_B"
#: The seed mean of sigma2_S above which a point is patterned (:meth:`Nematic.classify`): the
#: default of ``verify.patterned_above`` and of the growth figure's runs.
PATTERNED_ABOVE = 1e-6
#: The classes :meth:`Nematic.classify` gives.
CLASSES = ("patterned", "relaxed", "unknown")

#: The choices of the numerics that are words (the parameters': ``CHOICES``).
NUMERICS_CHOICES: dict[str, tuple[str, ...]] = {
    "scheme": SCHEMES,
    "error_norm": ERROR_NORMS,
    "mechanics": MECHANICS,
    "displacement": DISPLACEMENT,
    "backend": BACKENDS,
    "precision": PRECISIONS,
}
_TYPES: dict[str, type] = {"float": float, "int": int, "str": str, "bool": bool}
#: Numerics that are execution only (the same numbers whatever their value): never swept.
_NOT_SWEPT = {"backend"}
#: Numerics that choose how a run is executed, not what it computes (the backends agree to
#: rounding): never part of a run's identity.
_EXECUTION_ONLY = ("backend",)


def _docstring_entries(cls: type) -> dict[str, str]:
    """Field -> the first sentence of its entry in ``cls``'s "Attributes:" docstring."""
    doc = (cls.__doc__ or "").split("Attributes:", 1)[-1]
    out: dict[str, str] = {}
    current = None
    for line in doc.splitlines():
        m = re.match(r"^\s{8}(\w+):\s*(.*)$", line)
        if m:
            current = m.group(1)
            out[current] = m.group(2)
        elif current is not None and line.strip():
            out[current] += " " + line.strip()
    return {k: _SENTENCE.split(v.strip(), maxsplit=1)[0].rstrip(".") for k, v in out.items()}


#: the end of a docstring's first sentence (not the abbreviations "Fig.", "Eq.", "e.g.")
_SENTENCE = re.compile(r"(?<!Fig)(?<!Eq)(?<!e\.g)\.\s+(?=[A-Z\"(])")


def _settings() -> tuple[Setting, ...]:
    out: list[Setting] = []
    for cls, kind in ((Parameters, "parameter"), (Numerics, "numerics")):
        docs = _docstring_entries(cls)
        choices: Mapping[str, tuple[str, ...]] = CHOICES if cls is Parameters else NUMERICS_CHOICES
        for f in dataclasses.fields(cls):
            if f.name == "protocol":  # the time protocols of the settings that allow one
                continue
            scalar = str(f.type) in _TYPES
            name = NAMES.get(f.name)
            out.append(
                Setting(
                    name=f.name,
                    kind=kind,  # type: ignore[arg-type]
                    type=_TYPES.get(str(f.type), list),
                    default=list(f.default) if isinstance(f.default, tuple) else f.default,
                    long_name=name.long_name if name else docs.get(f.name, f.name),
                    sweepable=scalar and f.name not in _NOT_SWEPT,
                    protocol=f.name in PROTOCOL_PARAMETERS,
                    symbol=name.tex if name else None,
                    choices=tuple(choices.get(f.name, ())),
                    execution=f.name in _EXECUTION_ONLY,
                )
            )
        if cls is Parameters:
            out.append(
                Setting(
                    name=AMB,
                    kind="parameter",
                    type=float,
                    default=Parameters.alpha - Parameters.B,
                    long_name=NAMES[AMB].long_name,
                    protocol=AMB in PROTOCOL_PARAMETERS,
                    symbol=NAMES[AMB].tex,
                )
            )
    return tuple(out)


#: What a verification compares unless a campaign lists its observables.
VERIFIED = ("sigma2_S", "cos2theta", "lambda", "lambda_peak", "t_peak")


def _obs(name: str, scalar: str, long_name: str, **rules: Any) -> Observable:
    known = NAMES.get(name)
    symbol = known.tex if known else None
    return Observable(name, scalar, long_name, symbol=symbol, verify=name in VERIFIED, **rules)


#: phase.nc's observables: the run scalar each is read from, its long name (units are all
#: "1": the model is dimensionless, lengths in units of the domain size L, times in units of
#: tau) and its aggregation rules.
OBSERVABLES: tuple[Observable, ...] = (
    _obs(
        "sigma2_S",
        "sigma2_S_final",
        "variance of the nematic order parameter S over the domain at t_final",
        seed_mean="geometric",
        classifies=True,
        pattern=True,
    ),
    _obs("mean_S", "mean_S_final", "domain mean of the nematic order parameter S at t_final"),
    _obs(
        "cos2theta",
        "cos2theta_final",
        "domain mean of cos(2 theta) (director anisotropy) at t_final",
        # in [-1, 1] and near 0 without applied strain: a relative change would measure noise
        change="absolute",
    ),
    _obs(
        "lambda",
        "lambda_final",
        "pattern size lambda (radial spectrum peak) at t_final (units of L)",
        pattern=True,
    ),
    _obs(
        "lambda_peak",
        "lambda_peak",
        "pattern size lambda at the first peak of sigma2_S(t), growth-peak rule (units of L)",
        pattern=True,
    ),
    _obs(
        "t_peak",
        "t_peak",
        "time of the first peak of sigma2_S(t), growth-peak rule (units of tau)",
        pattern=True,
    ),
    _obs(
        "lambda_peak_literal",
        "lambda_peak_literal",
        "pattern size lambda at the first local "
        "maximum of sigma2_S(t), the paper's literal rule (units of L)",
        pattern=True,
    ),
    _obs(
        "t_peak_literal",
        "t_peak_literal",
        "time of the first local maximum of sigma2_S(t), the paper's literal rule (units of tau)",
        pattern=True,
    ),
    _obs(
        "lambda_mean",
        "lambda_mean_final",
        "pattern size 2 pi / mean |k| at t_final (units of L)",
        pattern=True,
    ),
    _obs(
        "lambda_mean_peak",
        "lambda_mean_peak",
        "pattern size 2 pi / mean |k| at the first peak "
        "of sigma2_S(t), growth-peak rule (units of L)",
        pattern=True,
    ),
    _obs(
        "rate_margin_min",
        "rate_margin_min",
        "smallest well-posedness margin of the rate problem over the run (1 passive, 0 ill posed)",
    ),
)


def _points(request: RunRequest) -> tuple[Parameters, Numerics]:
    return Parameters.from_dict(request.parameters), Numerics.from_dict(request.numerics)


class Nematic:
    """The active nematic solid (paper Eqs. 1-5) as a model of the campaign manager."""

    name = "nematic"
    long_name = "active nematic solid (nemato-elastic matrix with stress-regulated activity)"
    settings: tuple[Setting, ...] = _settings()
    observables: tuple[Observable, ...] = OBSERVABLES
    capabilities = Capabilities(
        exact_continuation=True,
        protocols=True,
        start_from_state=True,
        batched=True,
        cost_model=True,
        resolution_rule=True,
        memory_per_run=True,
        # float32 on the accelerated backend only (Numerics.precision)
        precisions=PRECISIONS,
    )

    def point(
        self, parameters: Mapping[str, Any], numerics: Mapping[str, Any]
    ) -> tuple[Parameters, Numerics]:
        """The point's :class:`~nematic_solids.model.parameters.Parameters` and
        :class:`~nematic_solids.model.parameters.Numerics`: a resolution rule (``auto``)
        resolved at the point's K and A0, the pair checked by
        :func:`~nematic_solids.model.parameters.check_compatible`; raises
        :class:`~nematic_solids.model.errors.ParameterError`."""
        from nematic_solids.model.resolution import resolve

        p = Parameters.from_dict(parameters)
        n = dict(numerics)
        if "resolution" in n:  # a rule (resolution: auto) gives the point's grid
            n["resolution"] = resolve(n["resolution"], p.K, p.A0)
        nums = Numerics.from_dict(n)
        check_compatible(p, nums)
        return p, nums

    def run(self, request: RunRequest) -> RunOutcome:
        """One run by :func:`nematic_solids.model.simulate.run` (compiled or numpy backend),
        from the seeded texture, ``request.initial`` (an
        :class:`~nematic_solids.model.checkpoint.InitialState`) or ``request.start`` (a
        :class:`~nematic_solids.model.checkpoint.RunState` of this run: exact continuation);
        the outcome holds the run's end state."""
        from nematic_solids.model.checkpoint import Schedule
        from nematic_solids.model.simulate import run as simulate

        params, numerics = _points(request)
        start: RunState | None = request.start
        initial: InitialState | None = request.initial
        ds, end = simulate(
            params,
            numerics,
            request.seed,
            progress=request.progress,
            start=start,
            initial=initial,
            checkpoint=request.checkpoint,
            schedule=Schedule(request.checkpoint_every, request.checkpoint_wall),
            keep_state=True,
        )
        return RunOutcome(ds, end)

    def run_batch(self, requests: Sequence[RunRequest], device: str) -> list[RunOutcome]:
        """The seeds of one point (``requests`` differ by seed, start and initial only) as
        one batch on the accelerated backend's ``device``: all from t = 0 (their seeded
        textures or their ``initial`` fields) or all from states (``start``) at one time.
        Each request's ``checkpoint`` gets its own seed's states."""
        import numpy as np

        from nematic_solids.model.accelerated.datasets import batch_datasets
        from nematic_solids.model.checkpoint import Schedule
        from nematic_solids.model.initial import initial_fields

        first = requests[0]
        params, numerics = _points(first)
        seeds = [r.seed for r in requests]
        states = [r.start for r in requests if r.start is not None]
        initial = None
        if not states and any(r.initial is not None for r in requests):
            n = numerics.resolution
            initial = np.stack(
                [
                    r.initial.fields
                    if r.initial is not None
                    else np.stack(initial_fields(params, n, r.seed))
                    for r in requests
                ]
            )
        calls = [r.checkpoint for r in requests]

        def checkpoint(b: int, state: RunState) -> None:
            call = calls[b]
            if call is not None:
                call(state)

        out = batch_datasets(
            params,
            numerics,
            seeds,
            device=device,
            initial=initial,
            start=states or None,
            checkpoint=checkpoint,
            schedule=Schedule(first.checkpoint_every, first.checkpoint_wall),
            keep_state=True,
        )
        return [RunOutcome(ds, end) for ds, end in out]

    def check_device(self, device: str) -> str:
        """The accelerated backend's device ``device`` here, described (``platform:kind``);
        raises :class:`nematic_solids.model.errors.DeviceUnavailable` (JAX missing, or no GPU
        where one is asked for)."""
        from nematic_solids.model.accelerated import select_device
        from nematic_solids.model.accelerated.device import describe

        return describe(select_device(device))

    def warm_up(
        self, points: Sequence[tuple[Mapping[str, Any], Mapping[str, Any]]]
    ) -> dict[str, Any]:
        """A tiny run of each ``(parameters, numerics)``, so that its kernels are compiled or
        loaded from the cache (:func:`nematic_solids.model.warmup.warm_up`)."""
        from nematic_solids.model.warmup import warm_up

        return warm_up([(Parameters.from_dict(p), Numerics.from_dict(n)) for p, n in points])

    def warm_kind(self, parameters: Parameters, numerics: Numerics) -> tuple[Any, ...]:
        """The kernels a run uses: its mechanics, scheme, incompressibility and adaptivity."""
        n = numerics
        return (n.mechanics, n.scheme, n.incompressible, n.adaptive)

    def import_kernels(self) -> None:
        """Import py-pde, numba and the kernels' modules."""
        import nematic_solids.model.simulate
        import nematic_solids.model.warmup  # noqa: F401

    def classify(self, values: Mapping[str, float]) -> str:
        """``patterned`` where the seed mean of sigma2_S is above :data:`PATTERNED_ABOVE`,
        ``relaxed`` where it is not, ``unknown`` where it is missing or not finite."""
        value = values.get("sigma2_S", math.nan)
        if not math.isfinite(value):
            return "unknown"
        return "patterned" if value > PATTERNED_ABOVE else "relaxed"

    def identity_settings(
        self, parameters: Mapping[str, Any], numerics: Mapping[str, Any]
    ) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
        """What of a point enters its runs' ids (:mod:`.nematic_identity`)."""
        return nematic_identity.identity_settings(parameters, numerics)

    def start_identity(
        self, numerics: Mapping[str, Any], start: Mapping[str, Any]
    ) -> dict[str, Any]:
        """What a run's start adds to its id: the first guess of finite strain
        (:func:`.nematic_identity.start_guess`)."""
        return nematic_identity.start_identity(numerics, start)

    def resolution(self, setting: Any, parameters: Mapping[str, Any]) -> Any:
        """The grid a resolution setting gives at a point: the number itself, or the rule's
        (``"auto"`` or ``{cells_per_frank, floor, cap}``) N at the point's K and A0
        (:func:`nematic_solids.model.resolution.resolve`)."""
        from nematic_solids.model.resolution import resolve

        p = Parameters.from_dict(parameters)
        return resolve(setting, p.K, p.A0)

    def rule(self, setting: Any) -> str | None:
        """The resolution rule ``setting`` is (``"auto"`` or a mapping), described
        (:meth:`nematic_solids.model.resolution.ResolutionRule.describe`); None for a number."""
        from nematic_solids.model.resolution import is_rule, read_rule

        return read_rule(setting).describe() if is_rule(setting) else None

    def memory_bytes(self, numerics: Mapping[str, Any]) -> int:
        """The estimated peak memory of one run
        (:func:`nematic_solids.sweep.limits.run_memory_bytes`)."""
        n = Numerics.from_dict(numerics)
        return run_memory_bytes(n.resolution, n.mechanics)

    def cost_seconds(self, parameters: Parameters | Mapping[str, Any], numerics: Any) -> float:
        """The calibrated CPU seconds of one run
        (:func:`nematic_solids.sweep.cost.model.model_seconds`)."""
        from ..cost.model import model_seconds

        p = parameters if isinstance(parameters, Parameters) else Parameters.from_dict(parameters)
        n = numerics if isinstance(numerics, Numerics) else Numerics.from_dict(numerics)
        return model_seconds(n, protocol=p.protocol)


#: The model registered as ``nematic`` (pyproject.toml, entry point group nematic_solids.models).
MODEL = Nematic()
