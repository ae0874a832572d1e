"""Where a run starts from, for a model that keeps its own states
(:class:`~nematic_solids.sweep.models.interface.StateCodec`: any py-pde model): its own rolling
checkpoint, the end state of a shorter finished run of its trajectory, or t = 0, and, for a run
of a chain or of ``initial.from``, the end state of the run it begins from. The rules are
:mod:`.continuation`'s: a checkpoint or end state of its own trajectory that cannot be read or
fails its checksum is not loaded (the record says why, ``start_warning``); the state a chain's
run begins from is what its identity names, so one that cannot be used fails the run (reason
``parent_state``), never a fallback."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..files import netcdf_lock
from ..models.interface import StateCodec
from .start import STATE_GROUP, ParentFailed, ParentUnusable, Run, Start, checkpoint_path

if TYPE_CHECKING:
    from ..store import CampaignStore

log = logging.getLogger(__name__)


class StateUnreadable(Exception):
    """A state file or group that is missing, unreadable or fails its checksum."""


def read_state(codec: StateCodec, path: Path, group: str | None = None) -> Any:
    """The model's state in the netCDF file ``path`` (its ``group``); :class:`StateUnreadable`
    naming the file and the cause."""
    import xarray as xr

    try:  # xarray takes the netCDF lock itself (netcdf_lock is not re-entrant)
        ds = xr.load_dataset(path, group=group, engine="netcdf4")
    except FileNotFoundError as e:
        raise StateUnreadable(f"{path} does not exist") from e
    except (OSError, ValueError, RuntimeError, KeyError) as e:
        what = "a readable netCDF file" if group is None else f"a netCDF file with a group {group}"
        raise StateUnreadable(f"{path} is not {what} ({e})") from e
    try:
        return codec.state_from_dataset(ds)
    except (ValueError, KeyError) as e:
        raise StateUnreadable(f"{path}: not a state of this model ({e})") from e


def starting_state(task: Run, store: CampaignStore, codec: StateCodec) -> Start:
    """The run's own checkpoint, else the end state of ``task.parent``, else t = 0 with the
    state of the run it begins from (``task.initial_from``)."""
    warnings: list[str] = []
    path = checkpoint_path(store, task.run_id)
    if path.exists():
        try:
            state = read_state(codec, path)
        except StateUnreadable as e:
            warnings.append(f"checkpoint ignored: {e}")
            log.warning("run %s: checkpoint ignored: %s", task.run_id, e)
        else:
            return Start(
                state, "checkpoint", "; ".join(warnings), lineage=[f"checkpoint@{state.t:.12g}"]
            )
    if task.parent:
        parent = Path(task.parent_path) if task.parent_path else store.nc_path(task.parent)
        try:
            state = read_state(codec, parent, STATE_GROUP)
        except StateUnreadable as e:
            warnings.append(f"end state of run {task.parent} not used: {e}")
            log.warning("run %s: end state of run %s not used: %s", task.run_id, task.parent, e)
        else:
            return Start(
                state, task.parent, "; ".join(warnings), lineage=[f"{task.parent}@{state.t:.12g}"]
            )
    if not task.initial_from:
        return Start(None, "", "; ".join(warnings))
    source: Mapping[str, str] = task.initial_from
    origin = f"{source['campaign']}/{source['run']}@{source['time']}"
    file = Path(source["runs_dir"]) / f"{source['run']}.nc"
    if not file.exists():
        raise ParentFailed(f"the run it begins from, {origin}, is not done (no {file})")
    if source["time"] != "end" or source.get("state"):
        raise ParentUnusable(
            f"the run it begins from, {origin}: a model's runs begin from an end state only"
        )
    try:
        status = read_state_attrs(file).get("status", "ok")
        if status != "ok":
            raise ParentFailed(f"the run it begins from, {origin}, did not end (status {status})")
        initial = read_state(codec, file, STATE_GROUP)
    except StateUnreadable as e:
        raise ParentUnusable(f"the parent run's file {file}: {e}") from e
    return Start(None, "", "; ".join(warnings), initial, initial_origin=origin)


def read_state_attrs(path: Path) -> dict[str, Any]:
    """The global attributes of the run file ``path``."""
    import netCDF4

    try:
        with netcdf_lock(), netCDF4.Dataset(path) as ds:
            return {k: ds.getncattr(k) for k in ds.ncattrs()}
    except OSError as e:
        raise StateUnreadable(f"{path} is not a readable netCDF file ({e})") from e
