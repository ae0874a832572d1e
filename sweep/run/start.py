"""What a run starts from (:class:`Start`), where its rolling checkpoint is, and why a run
that begins from another run's state cannot (:class:`ParentFailed`, :class:`ParentUnusable`):
shared by the nematic model's continuation (:mod:`.continuation`) and that of a model that keeps
its own states (:mod:`.model_states`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from ..store import CampaignStore


class Run(Protocol):
    """What this module reads of a run to do (a :class:`nematic_solids.sweep.run.task.RunTask`)."""

    @property
    def run_id(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def parameters(self) -> dict[str, Any]: ...
    @property
    def numerics(self) -> dict[str, Any]: ...
    @property
    def parent(self) -> str | None: ...
    @property
    def parent_path(self) -> str | None: ...
    @property
    def snapshot_fields(self) -> tuple[str, ...] | None: ...
    @property
    def snapshot_dtype(self) -> str: ...
    @property
    def initial_from(self) -> dict[str, str] | None: ...
    @property
    def model(self) -> str: ...


#: the run file's group holding the run's end state
STATE_GROUP = "state"


def checkpoint_path(store: CampaignStore, run_id: str) -> Path:
    """Where the rolling checkpoint of ``run_id`` is."""
    return store.checkpoint_path(run_id)


@dataclass
class Start:
    """What a run starts from: ``state``, the model's state to continue (the nematic model's
    :class:`~nematic_solids.model.checkpoint.RunState`, another model's own; None: t = 0),
    ``origin`` ("checkpoint", the run id of the run it continues, or ""), and why a
    checkpoint or end state found was not used."""

    state: Any | None = None
    origin: str = ""
    warning: str = ""
    #: the fields of another campaign's run it begins from (``initial.from``), at t = 0
    initial: Any | None = None
    #: the states it went through, for a model's state that keeps none itself
    lineage: list[str] = field(default_factory=list)
    #: the run it begins from, for a model's state that does not name it itself
    initial_origin: str = ""


class ParentFailed(Exception):
    """The run a run begins from (``initial.from``, or its predecessor in a chain) did not
    end well or is not done: the run fails with the reason ``parent_failed`` (redone when the
    campaign runs again)."""


class ParentUnusable(Exception):
    """The run a run begins from ended, but the state it should begin from cannot be used:
    its end state fails its checksum or is not in the file, or its snapshot is not the one the
    run's identity names. The run fails with the reason ``parent_state`` (never a silent
    fallback to another state), and is redone when the campaign runs again."""
