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

A campaign may also name a model that no package registers by its reference,
``model: my_module:MODEL`` (:func:`is_reference`): the module is imported from the driver's
and the workers' import path (a local cluster's workers share the driver's, so a module beside
the campaign file serves when ``nematic`` runs in that folder). The reference is the model's
name, in its runs' ids too.
"""

from __future__ import annotations

import functools
import re
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


#: ``module.sub:object.attr``: a model named by where it is defined
_REFERENCE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


def is_reference(name: str) -> bool:
    """Whether ``name`` is a ``module:object`` reference (not a registered name)."""
    return bool(_REFERENCE.match(name))


def list_models() -> list[str]:
    """The names of the registered models, sorted."""
    return sorted(_entry_points())


@functools.cache
def get_model(name: str = DEFAULT_MODEL) -> Model:
    """The model registered as ``name`` (loaded once). Raises :class:`UnknownModel` naming the
    registered ones, or where the entry point does not give a model."""
    eps = _entry_points()
    if name not in eps and is_reference(name):
        eps = {name: EntryPoint(name=name, value=name, group=ENTRY_POINT_GROUP)}
    if name not in eps:
        raise UnknownModel(
            f"no model named {name!r} is installed; the registered models are "
            f"{', '.join(list_models())} (a package registers one under the entry point group "
            f"{ENTRY_POINT_GROUP!r})"
        )
    try:  # a user's module may fail in any way: its error, named, is the message
        obj = eps[name].load()
        model = obj() if callable(obj) and not isinstance(obj, Model) else obj
    except Exception as e:
        raise UnknownModel(
            f"the model {name} = {eps[name].value!r} cannot be loaded: {type(e).__name__}: {e}"
        ) from e
    if not isinstance(model, Model):
        raise UnknownModel(
            f"the entry point {name} = {eps[name].value!r} does not give a model (an object "
            "with name, long_name, settings, observables, capabilities, point, run and "
            "classify)"
        )
    return model
