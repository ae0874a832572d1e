"""``prior:``: a stated prior for the cost of a campaign's later rounds, the ``phase.nc`` of a
finished run of the same campaign (e.g. the one shipped in ``docs/results/<name>/``). With it,
``nematic run --dry-run`` gives an expected value for the rounds of seeds by precision or
refinement before the campaign has data of its own (:mod:`nematic_solids.sweep.cost.later`),
labelled as resting on the prior; without it, only the bound.

```yaml
prior: ../docs/results/fig2_precision/phase.nc   # relative to this file
```
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .checker import Checker


def read_prior(c: Checker, raw: Any, read: Mapping[str, Any]) -> str | None:
    """The prior's path, absolute (relative paths are taken from the campaign file's
    folder); a problem at the key's line when it is not a string naming an existing file.
    Its content is read by :func:`nematic_solids.sweep.cost.later.load_prior`, when an estimate is
    made."""
    if raw is None:
        return None
    if not isinstance(raw, str) or not raw.strip():
        c.bad(("prior",), raw, "the path of a phase.nc of this campaign (relative to this file)")
        return None
    here = Path(c.source).parent if c.source and not c.source.startswith("<") else Path.cwd()
    path = (here / raw.strip()).resolve()
    if not path.is_file():
        c.add(("prior",), f"no file {path} (the phase.nc of a finished run of this campaign)")
        return None
    return str(path)
