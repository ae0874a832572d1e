"""The model's check of every grid point of a campaign: each point's parameters and numerics
built as :func:`nematic_solids.sweep.expand.make_point` builds them, each distinct
:class:`~nematic_solids.model.errors.ParameterError` reported at the key path that caused it."""

from __future__ import annotations

from nematic_solids.model.accelerated_support import check_precision, check_supported
from nematic_solids.model.errors import ParameterError

from ..campaign import AMB, Campaign
from ..expand import MAX_POINT_PROBLEMS, iter_points, make_point
from ..identity import PointIdentity
from ..models.interface import SettingError, setting_error
from ..protocols import error_path, protocol_axes
from .checker import Checker


def check_points(campaign: Campaign, checker: Checker) -> None:
    """Build the model's objects at every grid point; report each distinct
    :class:`~nematic_solids.model.errors.ParameterError` at the key path that caused it."""
    axis_names = {a.name for a in campaign.axes}
    swept = {k: v for k, v in protocol_axes(campaign.parameters).items() if k in axis_names}
    seen: set[tuple[str, str]] = set()
    _check_variant_precision(checker, campaign)
    runs: dict[tuple, dict] = {}  # one grid point's run (its identity) -> its coordinates
    identity = PointIdentity(campaign.model)
    for index, coords in iter_points(campaign):
        try:
            point = make_point(campaign, index, coords)
            plain = campaign.initial is None and campaign.chain is None  # ids of their own
            if plain and _same_run(
                checker, identity(point.parameters, point.numerics), coords, runs
            ):
                return
        except ValueError as e:
            if _report(checker, campaign, setting_error(e), coords, axis_names, swept, seen):
                return
            continue
        if getattr(point.numerics, "precision", "float64") != "float64":
            _check_float32(checker, campaign, axis_names, seen)
            try:
                check_precision(point.numerics)
            except ParameterError as e:
                if _report(checker, campaign, setting_error(e), coords, axis_names, swept, seen):
                    return
                continue
        if _needs_samples(checker, campaign, point, coords, seen, axis_names):
            return
        if campaign.execution.backend == "accelerated":
            try:
                check_supported(point.parameters, point.numerics)
            except ParameterError as e:
                key = ("execution.backend", e.name)
                if key not in seen:
                    seen.add(key)
                    checker.add(
                        ("execution", "backend"),
                        f"the accelerated backend cannot run {e.name} = {e.value!r}; allowed: "
                        f"{e.allowed} (or backend: compiled)",
                    )


#: why float32 is refused on the compiled backend
COMPILED_FLOAT64 = (
    "float32 runs on the accelerated backend only, for now (the compiled and numpy backends "
    "compute in float64); give execution: {backend: accelerated}, or precision: float64"
)


def _check_variant_precision(checker: Checker, campaign: Campaign) -> None:
    """A verification variant that asks for float32 runs where the campaign's runs do: on the
    accelerated backend (``precision: float64``, the variant that checks a float32 campaign,
    runs anywhere)."""
    if campaign.verify is None or campaign.execution.backend == "accelerated":
        return
    for i, variant in enumerate(campaign.verify.variants):
        if variant.settings.get("precision", "float64") != "float64":
            checker.add(
                ("verify", "variants", i, "precision"),
                f"got {variant.settings['precision']!r}; {COMPILED_FLOAT64}",
            )


def _check_float32(
    checker: Checker, campaign: Campaign, axis_names: set[str], seen: set[tuple[str, str]]
) -> None:
    """Refuse float32 where it does not run: on the compiled backend (float64 only, for now)
    and in a chain (whose runs go one at a time on the compiled backend); once per cause, at
    the key that sets the precision."""
    swept = "precision" in axis_names
    where = ("sweep", "axes", "precision") if swept else ("numerics", "precision")
    if campaign.execution.backend != "accelerated":
        why = COMPILED_FLOAT64
    elif campaign.chain is not None:
        why = (
            "a chain's runs go one at a time on the compiled backend, which computes in "
            "float64 only, for now; give precision: float64"
        )
    else:
        return
    key = ("precision", why)
    if key not in seen:
        seen.add(key)
        checker.add(where, f"got 'float32'; {why}")


def _report(
    checker: Checker,
    campaign: Campaign,
    e: SettingError,
    coords: dict,
    axis_names: set[str],
    swept: dict,
    seen: set[tuple[str, str]],
) -> bool:
    """Report the model's error at the key path that caused it (once per path and cause);
    ``True`` when enough problems are reported."""
    name = e.name
    if name == "alpha" and AMB in axis_names:
        name = AMB
    timed = error_path(name, swept)
    if timed is not None and timed[0] == "sweep":
        path: tuple[str | int, ...] = timed
        at = ", ".join(f"{k}={v!r}" for k, v in coords.items())
        msg = f"got {e.value!r}; allowed: {e.allowed} (at the grid point {at})"
    elif timed is not None:
        path, msg = timed, f"got {e.value!r}; allowed: {e.allowed}"
    elif name in axis_names:
        path = ("sweep", "axes", name)
        at = ", ".join(f"{k}={v!r}" for k, v in coords.items())
        msg = f"got {e.value!r}; allowed: {e.allowed} (at the grid point {at})"
    elif name in campaign.numerics:
        path, msg = ("numerics", name), f"got {e.value!r}; allowed: {e.allowed}"
    elif name in campaign.parameters:
        path, msg = ("parameters", name), f"got {e.value!r}; allowed: {e.allowed}"
    else:
        path, msg = (name,), f"got {e.value!r}; allowed: {e.allowed}"
    key = (repr(path), e.allowed)
    if key in seen:
        return False
    seen.add(key)
    checker.add(path, msg)
    if len(seen) >= MAX_POINT_PROBLEMS:
        checker.add((), "further grid problems not shown")
        return True
    return False


#: samples per period of the eps sine that the ``moduli`` fit needs (its docs: save_every <= T/8)
MODULI_SAMPLES = 8


def _needs_samples(
    checker: Checker, campaign: Campaign, point, coords: dict, seen: set, axis_names: set[str]
) -> bool:
    """The ``moduli`` fit reads the stress series at the save times: ``save_every`` at most
    1/:data:`MODULI_SAMPLES` of the eps sine's period, reported at save_every (or its axis)
    once; ``True`` when enough problems are reported."""
    if not any(f.name == "moduli" for f in campaign.fits):
        return False
    protocol = getattr(point.parameters, "protocol", None)
    sine = dict(protocol.profiles).get("eps") if protocol is not None else None
    period = getattr(sine, "period", None)
    save_every = point.numerics.save_every
    if period is None or save_every <= period / MODULI_SAMPLES * (1 + 1e-9):
        return False
    if "save_every" in axis_names:
        path: tuple[str | int, ...] = ("sweep", "axes", "save_every")
    elif "eps_period" in axis_names:
        path = ("sweep", "axes", "eps_period")
    elif "save_every" in campaign.numerics:
        path = ("numerics", "save_every")
    else:
        path = ("fits",)
    key = (repr(path), "moduli samples")
    if key in seen:
        return False
    seen.add(key)
    at = ", ".join(f"{k}={v!r}" for k, v in coords.items())
    checker.add(
        path,
        f"the moduli fit needs save_every <= T/{MODULI_SAMPLES} of the eps sine; got save_every = "
        f"{save_every:g} with T = {period:g}{f' (at the grid point {at})' if at else ''}",
    )
    return len(seen) >= MAX_POINT_PROBLEMS


def _same_run(checker: Checker, key: tuple, coords: dict, runs: dict[tuple, dict]) -> bool:
    """Whether the grid point at ``coords`` (its run's identity: ``key``) was already seen
    under other coordinates (the same run: e.g. a pulse whose level is its base, which is the
    constant parameter): reported once."""
    first = runs.setdefault(key, coords)
    if first is coords:
        return False
    fmt = ", ".join
    checker.add(
        ("sweep",),
        f"the grid points ({fmt(f'{k}={v!r}' for k, v in first.items())}) and "
        f"({fmt(f'{k}={v!r}' for k, v in coords.items())}) are the same run (the same "
        "parameters and numerics; a protocol that is constant is the plain parameter); drop "
        "one of their values",
    )
    return True
