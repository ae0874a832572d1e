"""Reading a phase diagram (``phase.nc`` as an :class:`xarray.Dataset`) for the fits and
figures: its sweep dims, fixed parameters, a swept name as a dimension, a selection; and the
variables a fit writes."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..campaign import AMB
from ..errors import FitError


def sweep_dims(phase: xr.Dataset) -> list[str]:
    """The sweep dims of a phase Dataset (every dim of ``status`` but ``seed``)."""
    ref = (
        "status"
        if "status" in phase
        else next((n for n, v in phase.data_vars.items() if "seed" in v.dims), None)
    )
    if ref is None:
        raise FitError("not a phase diagram: no variable over the seed dim")
    return [str(d) for d in phase[ref].dims if d != "seed"]


def fixed_parameter(phase: xr.Dataset, name: str) -> float | None:
    """A model parameter that the campaign did not sweep (phase.nc attribute ``param_<name>``),
    ``alpha_minus_B`` derived from ``alpha`` and ``B`` when needed."""
    key = f"param_{name}"
    if key in phase.attrs:
        return float(phase.attrs[key])
    if name == AMB and "param_alpha" in phase.attrs and "param_B" in phase.attrs:
        return float(phase.attrs["param_alpha"]) - float(phase.attrs["param_B"])
    return None


def is_swept(phase: xr.Dataset, name: str) -> bool:
    """Whether ``name`` varies over the phase diagram (a sweep dim or a zipped coordinate;
    ``alpha_minus_B`` also when ``alpha`` or ``B`` is swept)."""
    if name in phase.coords and name not in ("seed",) and phase[name].ndim == 1:
        return True
    return name == AMB and (is_swept(phase, "alpha") or is_swept(phase, "B"))


def with_dim(phase: xr.Dataset, name: str) -> xr.Dataset:
    """``phase`` with ``name`` as a dimension: a zipped coordinate is swapped in,
    ``alpha_minus_B`` is derived from a swept ``alpha`` or ``B``, a fixed parameter becomes a
    length-1 dim. Raises :class:`FitError` if ``name`` is neither swept nor fixed."""
    if name in phase.dims:
        return phase
    if name in phase.coords and phase[name].ndim == 1:
        return phase.swap_dims({phase[name].dims[0]: name})
    if name == AMB:
        for swept, other in (("alpha", "B"), ("B", "alpha")):
            if is_swept(phase, swept):
                fixed = fixed_parameter(phase, other)
                if fixed is None:
                    raise FitError(
                        "alpha_minus_B: both alpha and B are swept on different "
                        "dims; sweep alpha_minus_B instead"
                    )
                sign = 1.0 if swept == "alpha" else -1.0
                amb = sign * (phase[swept] - fixed)
                ds = phase.assign_coords(
                    {
                        AMB: (
                            phase[swept].dims,
                            amb.values,
                            {"long_name": "contractility alpha - B", "units": "1"},
                        )
                    }
                )
                return with_dim(ds, AMB)
    value = fixed_parameter(phase, name)
    if value is None:
        raise FitError(
            f"{name!r} is neither swept nor a fixed parameter of this campaign "
            f"(sweep dims: {', '.join(sweep_dims(phase)) or 'none'})"
        )
    return phase.expand_dims({name: [value]})


def select(phase: xr.Dataset, choice: Mapping[str, Any] | None) -> xr.Dataset:
    """``phase`` at the sweep values ``choice`` (nearest grid value; the dim is dropped)."""
    for name, value in (choice or {}).items():
        if name not in phase.coords:
            raise FitError(
                f"select: {name!r} is not a coordinate of the phase diagram "
                f"(coordinates: {', '.join(map(str, phase.coords))})"
            )
        ds = with_dim(phase, name)
        phase = ds.sel({name: value}, method="nearest")
    return phase


def default_axis(phase: xr.Dataset, candidates: Sequence[str] = (AMB, "chi", "eps")) -> str:
    for name in candidates:
        if is_swept(phase, name):
            return name
    dims = sweep_dims(phase)
    if not dims:
        raise FitError("the campaign sweeps nothing: no axis to fit along")
    return dims[0]


def other_dims(ds: xr.Dataset, used: Iterable[str]) -> list[str]:
    u = set(used)
    return [d for d in sweep_dims(ds) if d not in u]


def coord_copy(ds: xr.Dataset, dims: Sequence[str]) -> dict[str, xr.Variable]:
    """The coordinates of ``ds`` that live on ``dims`` only (for a fit's output)."""
    out = {}
    for name, c in ds.coords.items():
        if c.ndim == 1 and c.dims[0] in dims:
            out[str(name)] = c.variable
    return out


def variable(
    dims: Sequence[str], data: Any, long_name: str, units: str = "1", **attrs: Any
) -> xr.Variable:
    return xr.Variable(
        tuple(dims), np.asarray(data), {"long_name": long_name, "units": units, **attrs}
    )
