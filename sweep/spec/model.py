"""``model:``: the model a campaign's runs compute, by its registered name (the entry point
group ``nematic_solids.models``: :mod:`nematic_solids.sweep.models.registry`). Absent: this
paper's model, ``nematic``, which adds nothing to a run's identity; any other model's name
is part of every run id of the campaign.

.. code-block:: yaml

    model: nematic
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..campaign import DEFAULT_MODEL
from ..models.registry import UnknownModel, get_model, list_models
from .checker import Checker, suggest


def read_model(c: Checker, raw: Any, read: Mapping[str, Any]) -> str:
    """The model's name; a problem at the key's line, naming the registered models, when it
    is not one of them or cannot be loaded (the default model then, so that the rest of the
    file is still checked)."""
    if raw is None:
        return DEFAULT_MODEL
    known = list_models()
    if not isinstance(raw, str) or raw not in known:
        hint = suggest(raw, known) if isinstance(raw, str) else ""
        c.bad(("model",), raw, "a registered model: " + ", ".join(known) + hint)
        return DEFAULT_MODEL
    try:
        get_model(raw)
    except (UnknownModel, ImportError, AttributeError) as e:
        c.add(("model",), f"the model {raw!r} is registered but cannot be loaded: {e}")
        return DEFAULT_MODEL
    return raw
