"""Where a run starts from: its own rolling checkpoint (it was interrupted in progress), the
end state of a shorter finished run of its trajectory (a campaign whose ``t_final`` grew), or
t = 0. Either way the result equals the run that never stopped
(:mod:`nematic_solids.model.checkpoint`).

Files:

- ``results/<campaign>/checkpoints/<run_id>.nc``: the rolling checkpoint of a run in
  progress (:meth:`nematic_solids.model.checkpoint.RunState.to_dataset`), written atomically at
  ``store.checkpoint_every``, each one replacing the last, removed once the run's record is
  written. One per run in progress, so the folder stays bounded.
- the group ``state`` of a finished run's file: its end state (``store.end_state``, on by
  default), without the snapshots (the file holds them).

A checkpoint or end state of its own trajectory that cannot be read, is corrupt (its checksum) or
is another run's is never loaded: the run starts from the next option and its record says why
(``start_warning``). The state a run of ``initial.from`` or of a chain begins from is another
matter: it is what the run's identity names (:func:`parent_fields`), so one that cannot be used
fails the run (reason ``parent_state``). A longer run continues a shorter one's end state only
if that run file holds every snapshot field the new run keeps, at its precision (else the
earlier snapshots could not be written as a straight run would write them).
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from nematic_solids.model.parameters import Numerics, Parameters

from ..errors import StorageError
from ..files import atomic_to_netcdf, netcdf_lock
from ..models.interface import StateCodec
from ..models.registry import get_model
from ..store import CampaignStore
from . import model_states
from .start import (
    STATE_GROUP,
    ParentFailed,
    ParentUnusable,
    Run,
    Start,
    checkpoint_path,
)

if TYPE_CHECKING:
    from nematic_solids.model.checkpoint import InitialState, RunState


log = logging.getLogger(__name__)


def remove_checkpoint(store: CampaignStore, run_id: str) -> None:
    """Remove the rolling checkpoint of a run whose record is written."""
    with contextlib.suppress(FileNotFoundError):
        checkpoint_path(store, run_id).unlink()


def _model_of(task: Run) -> tuple[Parameters, Numerics]:
    return Parameters.from_dict(task.parameters), Numerics.from_dict(task.numerics)


def starting_state(task: Run, store: CampaignStore) -> Start:
    """The run's own checkpoint if it holds a state of this run, else the end state of the
    run ``task.parent`` if it continues to this one, else t = 0 (see the module docstring).
    A model that keeps its own states (:class:`~nematic_solids.sweep.models.interface.StateCodec`)
    reads them itself (:mod:`.model_states`); one that keeps none starts at t = 0."""
    model = get_model(task.model)
    if isinstance(model, StateCodec):
        return model_states.starting_state(task, store, model)
    if not (model.capabilities.exact_continuation or model.capabilities.start_from_state):
        return Start()
    from nematic_solids.model.checkpoint import CheckpointError, load

    params, numerics = _model_of(task)
    warnings: list[str] = []
    path = checkpoint_path(store, task.run_id)
    if path.exists():
        try:
            state = load(path)
            why = state.problem(params, numerics, task.seed)
            if why is not None:
                raise CheckpointError(f"{path}: not this run's state: {why}")
        except CheckpointError as e:
            warnings.append(f"checkpoint ignored: {e}")
            log.warning("run %s: checkpoint ignored: %s", task.run_id, e)
        else:
            state.lineage = [*state.lineage, f"checkpoint@{state.t:.12g}"]
            return Start(state, "checkpoint", "; ".join(warnings))
    if task.parent:
        try:
            parent_file = Path(task.parent_path) if task.parent_path else None
            state = read_end_state(parent_file or store.nc_path(task.parent), task)
            why = state.problem(params, numerics, task.seed)
            if why is not None:
                raise CheckpointError(f"it does not continue to this run: {why}")
        except CheckpointError as e:
            warnings.append(f"end state of run {task.parent} not used: {e}")
            log.warning("run %s: end state of run %s not used: %s", task.run_id, task.parent, e)
        else:
            state.lineage = [*state.lineage, f"{task.parent}@{state.t:.12g}"]
            return Start(state, task.parent, "; ".join(warnings))
    initial = None
    if task.initial_from:
        initial = parent_fields(task.initial_from)
        if task.initial_from.get("state"):
            warnings.append(
                f"begins from the {task.initial_from['state']} of {initial.origin}, not its "
                "exact end state (its campaign keeps none): another run id than a start from "
                "the end state"
            )
    return Start(None, "", "; ".join(warnings), initial)


def parent_fields(source: Mapping[str, str]) -> InitialState:
    """The fields a run of ``initial.from`` (or of a chain) begins with: the parent run's
    exact end state (``time: end``: the run file's group ``state``, fields and displacement bit
    for bit) or its snapshot at the time, with the displacement of that snapshot. Where the
    identity says the run begins from a snapshot (``source["state"]``: the parent keeps no end
    state), its last snapshot. :class:`ParentFailed` if the parent is not done or did not end
    well; :class:`ParentUnusable` naming the file if the state it names cannot be used (an end
    state that fails its checksum or is missing: never a fallback to a snapshot)."""
    from nematic_solids.model.checkpoint import CheckpointError, InitialState, RunState, read_netcdf

    path = Path(source["runs_dir"]) / f"{source['run']}.nc"
    origin = f"{source['campaign']}/{source['run']}@{source['time']}"
    if not path.exists():
        raise ParentFailed(f"the run it begins from, {origin}, is not done (no {path})")
    main = read_netcdf(path)
    snaps = file_snapshots(main)
    try:
        if source["time"] != "end":
            _check_precision(main, source.get("state") or "float64")
            t = float(source["time"])
            snap = next((s for s in snaps if math.isclose(s[0], t)), None)
            if snap is None:
                raise CheckpointError(f"it has no snapshot at t = {source['time']}")
            return InitialState.of_snapshot(snap[1], origin)
        if main.attrs.get("status") != "ok" or not snaps:
            raise ParentFailed(
                f"the run it begins from, {origin}, did not end "
                f"(status {main.attrs.get('status')}: {main.attrs.get('reason')})"
            )
        if source.get("state"):  # its identity: the last snapshot (no end state kept)
            _check_precision(main, source["state"])
            return InitialState.of_snapshot(snaps[-1][1], origin)
        if not has_group(path, STATE_GROUP):
            raise CheckpointError(
                "it keeps no end state (its campaign's store had end_state: false when it "
                "ran); run it again with end_state: true"
            )
        state = RunState.from_dataset(read_netcdf(path, STATE_GROUP))
        return InitialState.exact(state, origin=origin)
    except CheckpointError as e:
        raise ParentUnusable(f"the parent run's file {path}: {e}") from e


def _check_precision(main: Any, state: str) -> None:
    """The parent's snapshots are kept at the precision the run's identity names (its campaign's
    store may have changed since the parent ran)."""
    from nematic_solids.model.checkpoint import CheckpointError

    want = "float32" if "float32" in state else "float64"
    have = str(main["q1"].dtype) if "q1" in main.data_vars else want
    if have != want:
        raise CheckpointError(
            f"it keeps its snapshots as {have}, the run's identity names {want} (its campaign's "
            "store changed since it ran)"
        )


def has_group(path: Path, group: str) -> bool:
    """Whether the netCDF file ``path`` has the group ``group`` (False if it cannot be read)."""
    import netCDF4

    try:
        with netcdf_lock(), netCDF4.Dataset(path) as ds:
            return group in ds.groups
    except OSError:
        return False


def file_snapshots(main: Any) -> list[tuple[float, Any]]:
    """The snapshots of a run file's Dataset as a run state holds them: ``(time, fields)``,
    every field of :data:`nematic_solids.model.checkpoint.SNAPSHOT_FIELDS` in float64, NaN where the
    file does not keep it."""
    import numpy as np

    from nematic_solids.model.checkpoint import SNAPSHOT_FIELDS

    times = main["snapshot_time"].values if "snapshot_time" in main else ()
    n = main.sizes.get("x", 0)
    out = []
    for i, t in enumerate(times):
        stack = np.full((len(SNAPSHOT_FIELDS), n, n), math.nan)
        for j, name in enumerate(SNAPSHOT_FIELDS):
            if name in main.data_vars:
                stack[j] = np.asarray(main[name].values[i], dtype=float)
        out.append((float(t), stack))
    return out


def read_end_state(path: Path, task: Run) -> RunState:
    """The end state in the run file ``path``, its snapshots taken from the file; raises
    :class:`CheckpointError` if there is none, it is unreadable, or the file lacks a
    snapshot field ``task`` keeps (or keeps it at a lower precision)."""
    import numpy as np

    from nematic_solids.model.checkpoint import (
        SNAPSHOT_FIELDS,
        CheckpointError,
        RunState,
        read_netcdf,
    )

    group, main = read_netcdf(path, STATE_GROUP), read_netcdf(path)
    try:
        state = RunState.from_dataset(group)
    except CheckpointError as e:
        raise CheckpointError(f"{path}: {e}") from e
    keep = task.snapshot_fields if task.snapshot_fields is not None else SNAPSHOT_FIELDS
    for name in keep:
        if name not in main.data_vars:
            raise CheckpointError(f"{path} has no snapshots of {name}, which this run keeps")
        if task.snapshot_dtype == "float64" and main[name].dtype != np.float64:
            raise CheckpointError(f"{path} keeps {name} as {main[name].dtype}, this run as float64")
    state.snaps = file_snapshots(main)
    return state


class Checkpointer:
    """The callback :func:`nematic_solids.model.simulate.run` hands each due state to: writes it as
    the run's rolling checkpoint, atomically. A checkpoint that cannot be written (a full disk) does
    not stop the run: it is logged, and the run goes on."""

    def __init__(self, store: CampaignStore, run_id: str):
        self.path = checkpoint_path(store, run_id)
        self.run_id = run_id

    def __call__(self, state: RunState) -> None:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            atomic_to_netcdf(state.to_dataset(), self.path)
        except (OSError, StorageError) as e:
            log.warning("run %s: checkpoint at t = %g not written: %s", self.run_id, state.t, e)


def run_attrs(start: Start) -> dict[str, Any]:
    """The run file's attributes that say where the run started: ``started_at`` (0 or the
    state's time), ``continued_from`` (the run id whose end state it continued, or "") and
    ``lineage`` (every state it went through: "checkpoint@t", "<run_id>@t")."""
    state = start.state
    parent = start.origin if start.origin not in ("", "checkpoint") else ""
    if state is not None and not parent:  # a checkpoint of a run that continued another
        lineage = getattr(state, "lineage", start.lineage)
        parent = next((e.split("@")[0] for e in lineage if not e.startswith("checkpoint")), "")
    origin = start.initial_origin or getattr(start.initial, "origin", "")
    if state is not None:
        origin = getattr(state, "initial_from", origin)
    return {
        "initial_from": origin,
        "started_at": 0.0 if state is None else float(state.t),
        "continued_from": parent,
        "lineage": [] if state is None else list(getattr(state, "lineage", start.lineage)),
    }
