"""``model:``: the model a campaign's runs compute, by its registered name (the entry point
group ``nematic_solids.models``: :mod:`nematic_solids.sweep.models.registry`). Absent: this
paper's model, ``nematic``, which adds nothing to a run's identity; any other model's name
is part of every run id of the campaign. A model that no package registers may be named by
its reference, ``module:object`` (imported where the campaign runs).

.. code-block:: yaml

    model: nematic
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..campaign import DEFAULT_MODEL
from ..models.registry import UnknownModel, get_model, is_reference, list_models
from .checker import Checker, suggest


def read_model(c: Checker, raw: Any, read: Mapping[str, Any]) -> str:
    """The model's name. A ``module:object`` reference is imported with the campaign file's
    folder on the import path (appended, once: the workers of a local cluster inherit it). A
    name that is not a registered model's, or a model that cannot be loaded, is a problem at
    the key's line, and the file is refused there: the rest of it names the model's settings."""
    if raw is None:
        return DEFAULT_MODEL
    known = list_models()
    if not isinstance(raw, str) or (raw not in known and not is_reference(raw)):
        hint = suggest(raw, known) if isinstance(raw, str) else ""
        c.bad(
            ("model",),
            raw,
            "a registered model (" + ", ".join(known) + ") or a module:object reference" + hint,
        )
        c.raise_if_any()
    if raw not in known and not c.source.startswith("<"):
        folder = str(Path(c.source).resolve().parent)
        if folder not in sys.path:
            sys.path.append(folder)
    try:
        get_model(raw)
    except UnknownModel as e:
        c.add(("model",), str(e))
        c.raise_if_any()
    return raw
