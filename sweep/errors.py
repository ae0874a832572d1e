"""The campaign manager's exceptions. They extend the model's hierarchy
(:class:`nematic_solids.model.errors.NematicError`), so a caller can catch everything this project
raises on purpose with one class. Every message names the bad value, what is allowed and the fix.

- :class:`CampaignError` an invalid campaign file or command-line override
- :class:`CampaignLocked` another driver runs the campaign
- :class:`StoreError` an unusable results folder; :class:`StorageError` a file that cannot
  be written
- :class:`ClusterError` no usable dask cluster
- :class:`FitError`, :class:`FigureError` a fit or figure that these results cannot give
- :class:`ExportError` a results table that cannot be exported as asked
- :class:`CatalogueError` a catalogue of runs that cannot be opened where asked
"""

from __future__ import annotations

from dataclasses import dataclass

# the model's errors that the campaign manager raises too: a device (a GPU) that is not there
# on a worker host, a setting out of a bound (limits) -- one place where the core meets them
from nematic_solids.model.errors import DeviceUnavailable as DeviceUnavailable
from nematic_solids.model.errors import NematicError
from nematic_solids.model.errors import ParameterError as ParameterError


@dataclass(frozen=True)
class Problem:
    """One mistake in a campaign: where it is, what was found and what is allowed.

    ``path`` is the key path inside the YAML document (``sweep.axes.chi[2]``); ``location``
    is ``"FILE:LINE"`` or a command-line option (``"--set K=..."``).
    """

    path: str
    message: str
    location: str = ""

    def __str__(self) -> str:
        where = f"{self.location}: " if self.location else ""
        return f"{where}{self.path or '<document>'}: {self.message}"


class CampaignError(NematicError, ValueError):
    """A campaign file (or its command-line overrides) is invalid. Exit code 2."""

    def __init__(self, source: str, problems: list[Problem]):
        self.source = source
        self.problems = list(problems)
        head = f"invalid campaign {source}: {len(self.problems)} problem(s)"
        super().__init__("\n".join([head, *(f"  {p}" for p in self.problems)]))


class CampaignLocked(NematicError, RuntimeError):
    """Another driver holds the campaign's lock. Exit code 2 (refused to start)."""


class StoreError(NematicError, RuntimeError):
    """The results folder is unusable (not writable, not a campaign folder, ...)."""


class StorageError(StoreError):
    """A file of the results folder cannot be written: the disk is full, the filesystem is
    read-only, a file size limit was reached, ... The message names the path and the cause.
    Not a failure of the run: the run stays pending. Exit code 2."""


class ClusterError(NematicError, RuntimeError):
    """The dask cluster cannot be reached or its workers cannot run the model. Exit code 2."""


class FitError(NematicError, ValueError):
    """A fit cannot be done on this phase diagram (missing axis, bad option, no data)."""


class FigureError(NematicError, ValueError):
    """A figure cannot be drawn from these results (missing axis, fit or file; bad option)."""


class ExportError(NematicError, ValueError):
    """A results table cannot be exported as asked (unknown format, Parquet without pyarrow)."""


class CatalogueError(NematicError, RuntimeError):
    """The catalogue of runs (:mod:`nematic_solids.sweep.catalogue`) cannot be opened or used
    where asked: a network filesystem under SQLite, an unreachable or unknown database URL, a
    catalogue of another results root. Exit code 2. Never fails a run: the driver goes on
    without the catalogue (the run files stay the source of truth)."""
