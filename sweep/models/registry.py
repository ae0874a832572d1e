"""The registry of models: every model is found by name through the entry point group
``nematic_solids.models`` (:data:`~nematic_solids.sweep.models.interface.ENTRY_POINT_GROUP`),
the shipped ones registered the same way as a user's (as xarray finds its backends: a cached
:func:`list_models`, loaded on first use).

A package adds a model with, in its ``pyproject.toml``::

    [project.entry-points."nematic_solids.models"]
    my-model = "my_package.my_module:MODEL"

where ``MODEL`` is an object with the attributes and methods of
:class:`~nematic_solids.sweep.models.interface.Model` (or a function of no argument that
returns one).
"""

from __future__ import annotations

import functools
from importlib.metadata import EntryPoint, entry_points

from .interface import DEFAULT_MODEL, ENTRY_POINT_GROUP, Model

#: The models this package ships: name -> entry point value. They are registered in
#: pyproject.toml too; this table serves a checkout whose installed metadata is older.
BUILTIN = {
    "nematic": "nematic_solids.sweep.models.nematic:MODEL",
    "swift-hohenberg": "nematic_solids.sweep.models.swift_hohenberg:MODEL",
}


class UnknownModel(LookupError):
    """A campaign names a model that no installed package registers."""


@functools.cache
def _entry_points() -> dict[str, EntryPoint]:
    found = {
        name: EntryPoint(name=name, value=value, group=ENTRY_POINT_GROUP)
        for name, value in BUILTIN.items()
    }
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(ep.name, ep)
    return found


def list_models() -> list[str]:
    """The names of the registered models, sorted."""
    return sorted(_entry_points())


@functools.cache
def get_model(name: str = DEFAULT_MODEL) -> Model:
    """The model registered as ``name`` (loaded once). Raises :class:`UnknownModel` naming the
    registered ones, or where the entry point does not give a model."""
    eps = _entry_points()
    if name not in eps:
        raise UnknownModel(
            f"no model named {name!r} is installed; the registered models are "
            f"{', '.join(list_models())} (a package registers one under the entry point group "
            f"{ENTRY_POINT_GROUP!r})"
        )
    obj = eps[name].load()
    model = obj() if callable(obj) and not isinstance(obj, Model) else obj
    if not isinstance(model, Model):
        raise UnknownModel(
            f"the entry point {name} = {eps[name].value!r} does not give a model (an object "
            "with name, long_name, settings, observables, capabilities, run and classify)"
        )
    return model
