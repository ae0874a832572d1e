"""A model's settings as a campaign file names them (:func:`setting_names`): which names
``parameters:``, ``numerics:`` and ``sweep.axes`` accept, and each one's type, read from the
model's declarations (:class:`~nematic_solids.sweep.models.interface.Setting`)."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass

from .campaign import DEFAULT_MODEL
from .models.interface import setting_types
from .models.registry import get_model


@dataclass(frozen=True)
class SettingNames:
    """A model's settings as the campaign file names them: each -> its type's name
    (``float``, ``int``, ``str``, ``bool``, ``list``)."""

    parameters: Mapping[str, str]
    numerics: Mapping[str, str]

    @property
    def sweepable_numerics(self) -> tuple[str, ...]:
        """The numerics that may be swept (those of a scalar type)."""
        return tuple(n for n, t in self.numerics.items() if t in SCALAR_TYPES)

    @property
    def axes(self) -> dict[str, str]:
        """What ``sweep.axes`` may name: every parameter and the sweepable numerics."""
        return {**self.parameters, **{n: self.numerics[n] for n in self.sweepable_numerics}}

    @property
    def all(self) -> dict[str, str]:
        """Every setting, parameters first."""
        return {**self.parameters, **self.numerics}


SCALAR_TYPES = ("int", "float", "bool", "str")


@functools.cache
def setting_names(model: str = DEFAULT_MODEL) -> SettingNames:
    """The settings of the registered ``model`` (:func:`~.models.registry.get_model`)."""
    m = get_model(model)
    return SettingNames(setting_types(m, "parameter"), setting_types(m, "numerics"))
