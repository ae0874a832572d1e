"""A run's complete state at a save time, :class:`RunState`, from which
:func:`nematic_solids.model.simulate.run` continues exactly: a run continued from the state it had
at time t takes the same accepted steps and ends with bitwise the same arrays as the run that never
stopped.

Complete means everything the next step reads: the fields q1, q2, A; the spectra of q1, q2 as
the last step produced them (a forward transform of the fields differs from them by
rounding); the step controller's next step size; the mechanics' displacement (finite strain:
the integrated displacement or Newton's warm start), its rate and the rate's gradient; and what
the run has recorded so far (the time series, the snapshots, the counters, the smallest
well-posedness margin, the wall time). Caches that are pure functions of these (the phi
functions, the last solve's stress) are rebuilt. The FFT plans are deterministic
(:mod:`nematic_solids.model.fourier`), so a state continues bitwise in another process.

A state is taken right after a save (the observables at a save time): the run resumes with
the step that followed that save. It continues the run with the same parameters, seed and
numerics; only ``t_final`` and the snapshot times after the state may differ (a longer run
continues a finished shorter one: its save times up to the shorter end are the same, so the
steps are too). :meth:`RunState.problem`
says why a state does not continue a given run.

On disk a state is a netCDF file (:meth:`RunState.to_dataset`, :func:`load`) with a SHA-256 of
its arrays and settings: a truncated, altered or foreign file is refused with
:class:`CheckpointError` naming the cause. Writing it (atomically) is the caller's:
:mod:`nematic_solids.sweep` writes rolling checkpoints and end states with its atomic writes.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from . import __version__
from .errors import NematicError
from .parameters import Numerics, Parameters, save_times
from .solver_base import SolverState

Array = np.ndarray

#: Layout of the file; a file of another format is refused.
FORMAT = 1
#: The fields of a snapshot, in order (the Dataset's snapshot variables).
SNAPSHOT_FIELDS = ("q1", "q2", "A", "u1", "u2", "I1bar")
#: The numerics a continued run may change: its end, and its snapshots after the state.
MAY_DIFFER = ("t_final", "snapshot_times")


@dataclass(frozen=True)
class Schedule:
    """When a run hands out its state (:func:`nematic_solids.model.simulate.run`'s ``checkpoint``):
    after the first save at least ``tau`` (simulated time) or ``wall`` (seconds of wall time) after
    the last state handed out (or the run's start). Both infinite (the default): never."""

    tau: float = math.inf
    wall: float = math.inf

    def due(self, since_tau: float, since_wall: float) -> bool:
        """Whether a state is due ``since_tau`` and ``since_wall`` after the last one."""
        return since_tau >= self.tau - 1e-9 * max(self.tau, 1.0) or since_wall >= self.wall


@dataclass
class InitialState:
    """Fields a new run begins from at t = 0 instead of the seeded texture (another run's end
    or snapshot, under the new run's own parameters): ``fields`` q1, q2, A (3, N, N);
    ``displacement`` the periodic displacement u~ (2, N, N) in real space, finite strain's
    first guess for the force balance at t = 0 (the new parameters move it: Newton solves it
    again); ``origin`` says where they come from (the Dataset's ``initial_from``);
    ``displacement_hat`` the end state's own displacement spectrum (finite strain), used
    instead of ``displacement`` when given: the exact guess, whatever the run file keeps of its
    snapshots (their precision, their fields)."""

    fields: Array
    displacement: Array | None = None
    origin: str = ""
    displacement_hat: Array | None = None

    @classmethod
    def at(cls, state: RunState, time: float | None = None, origin: str = "") -> InitialState:
        """The fields of ``state`` at its time (``time`` None) or of its snapshot at ``time``,
        with the displacement of the snapshot there (if it has one)."""
        t = state.t if time is None else float(time)
        snap = next((s for s in state.snaps if abs(s[0] - t) <= 1e-9 * max(t, 1.0)), None)
        if snap is None:
            if time is not None:
                raise CheckpointError(f"the run has no snapshot at t = {t:g}")
            return cls(np.asarray(state.fields, dtype=float), None, origin)
        out = cls.of_snapshot(snap[1], origin)
        if time is None:  # the state's own fields, exact (a snapshot may be rounded)
            out.fields = np.asarray(state.fields, dtype=float)
        return out

    @classmethod
    def exact(cls, state: RunState, origin: str = "") -> InitialState:
        """The end state ``state`` itself: its fields and (finite strain) its displacement
        spectrum, bit for bit; nothing of its snapshots."""
        u_hat = state.mechanics.get("u_hat")
        return cls(
            np.array(state.fields, dtype=float),
            None,
            origin,
            None if u_hat is None else np.array(u_hat, dtype=complex),
        )

    @classmethod
    def of_snapshot(cls, snapshot: Array, origin: str = "") -> InitialState:
        """The fields of one snapshot (:data:`SNAPSHOT_FIELDS`; NaN where a field is not
        kept), its displacement if it has one; :class:`CheckpointError` without q1, q2, A."""
        fields = np.asarray(snapshot[:3], dtype=float)
        if not np.all(np.isfinite(fields)):
            raise CheckpointError("the snapshot keeps no q1, q2 and A")
        disp = np.asarray(snapshot[3:5], dtype=float)
        return cls(fields, disp if np.all(np.isfinite(disp)) else None, origin)


class CheckpointError(NematicError):
    """A saved state cannot be read or does not continue the run asked for."""


@dataclass
class RunState:
    """Everything :func:`nematic_solids.model.simulate.run` needs to continue a run from time ``t``
    (see the module docstring). ``rows`` are the saved observables (one dict per save time, with
    ``time`` and ``steps``), ``snaps`` the stored snapshots ``(time, fields)``, ``counters`` the
    work counted so far (transforms by part, spin and CG iterations), ``stopped`` the time an
    early-stopped run ended (NaN otherwise), ``wall`` the wall time spent."""

    t: float
    fields: Array
    solver: SolverState
    mechanics: dict[str, Array]
    counters: dict[str, Any]
    rows: list[dict[str, float]]
    snaps: list[tuple[float, Array]]
    parameters: dict[str, Any]
    numerics: dict[str, Any]
    seed: int
    stopped: float = math.nan
    wall: float = 0.0
    #: the history of the state, the "run_id@t" entries a campaign adds (free text here)
    lineage: list[str] = field(default_factory=list)
    #: where the run's fields at t = 0 came from (``InitialState.origin``; "" for the
    #: seeded texture)
    initial_from: str = ""
    #: the model version that computed it (``model.__version__``): a state of another
    #: version does not continue a run of this one
    code_version: str = __version__

    @property
    def complete(self) -> bool:
        """Whether the state is its run's end (``t_final`` reached or stopped early)."""
        t_final = float(self.numerics["t_final"])
        return math.isfinite(self.stopped) or self.t >= t_final - 1e-9 * max(t_final, 1.0)

    def problem(self, params: Parameters, numerics: Numerics, seed: int) -> str | None:
        """Why this state does not continue the run ``(params, numerics, seed)``, or None.
        The model version, the parameters, the seed and the numerics but ``t_final`` and
        ``snapshot_times`` must be the same; the run's save times up to the state's time must
        be the state run's (the stepper lands on each, so they shaped its steps), and the
        run's snapshots up to then must be among the state's."""
        if self.code_version != __version__:
            return f"it was computed by model version {self.code_version}, this is {__version__}"
        if int(seed) != self.seed:
            return f"it is seed {self.seed}'s state, not seed {seed}'s"
        if params.to_dict() != self.parameters:
            diff = _differences(self.parameters, params.to_dict())
            return f"its parameters differ ({diff})"
        mine = {k: v for k, v in self.numerics.items() if k not in MAY_DIFFER}
        theirs = {k: v for k, v in numerics.to_dict().items() if k not in MAY_DIFFER}
        if mine != theirs:
            return f"its numerics differ ({_differences(mine, theirs)})"
        t, eps = self.t, 1e-9 * max(self.t, 1.0)
        if numerics.t_final < t - eps:
            return f"it is at t = {t:g}, past this run's t_final = {numerics.t_final:g}"
        own = [float(x) for x in save_times(Numerics.from_dict(self.numerics)) if x <= t + eps]
        wanted = [float(x) for x in save_times(numerics) if x <= t + eps]
        if own != wanted:
            return (
                f"this run's save times up to t = {t:g} are not the state's (save_every or "
                "snapshot_times differ there), so its steps would differ"
            )
        have = {round(s[0], 9) for s in self.snaps}
        missing = [x for x in numerics.snapshot_times if x <= t + eps and round(x, 9) not in have]
        if missing:
            return f"it has no snapshot at t = {', '.join(f'{x:g}' for x in missing)}"
        return None

    # --- netCDF ---------------------------------------------------------------------------
    def to_dataset(self, *, snapshots: bool = True) -> xr.Dataset:
        """The state as a Dataset (complex spectra as (re, im) pairs), with its checksum;
        ``snapshots=False`` leaves the snapshots out (a run file holds them already: the
        reader puts them back, ``snaps`` is then empty)."""
        n = self.fields.shape[-1]
        columns = sorted({k for r in self.rows for k in r})
        table = np.array([[r.get(c, math.nan) for c in columns] for r in self.rows], dtype=float)
        snaps = (
            np.stack([s[1] for s in self.snaps])
            if self.snaps
            else np.zeros((0, len(SNAPSHOT_FIELDS), n, n), dtype=float)
        )
        data: dict[str, Any] = {
            "fields": (("field", "x", "y"), np.asarray(self.fields, dtype=float)),
            "rows": (("row", "column"), table.reshape(len(self.rows), len(columns))),
        }
        if snapshots:
            data["snap_time"] = (("snap",), np.array([s[0] for s in self.snaps], dtype=float))
            data["snaps"] = (("snap", "snap_field", "x", "y"), snaps)
        if self.solver.q_hat is not None:
            data["q_hat"] = _pair(self.solver.q_hat, "q")
        for name, value in self.mechanics.items():
            data[f"mech_{name}"] = _pair(value, name)
        attrs = {
            "title": "active nematic solid: run state (nematic_solids.model.checkpoint)",
            "checkpoint_format": FORMAT,
            "t": float(self.t),
            "h": float(self.solver.h),
            "margin_min": float(self.solver.margin_min),
            "stopped": float(self.stopped),
            "wall": float(self.wall),
            "seed": int(self.seed),
            "columns": json.dumps(columns),
            "stats_json": json.dumps(self.solver.stats, sort_keys=True),
            "counters_json": json.dumps(self.counters, sort_keys=True),
            "parameters_json": json.dumps(self.parameters, sort_keys=True),
            "numerics_json": json.dumps(self.numerics, sort_keys=True),
            "lineage_json": json.dumps(self.lineage),
            "initial_from": self.initial_from,
            "code_version": self.code_version,
            "complex_json": json.dumps(
                sorted(k for k, v in data.items() if v[0][0] == "part"), sort_keys=True
            ),
        }
        ds = xr.Dataset(data, attrs=attrs)
        ds.attrs["sha256"] = _checksum(ds)
        for var in ds.data_vars.values():  # byte shuffle + zlib: 12 % smaller, written faster
            var.encoding = {"zlib": True, "complevel": 4, "shuffle": True}
        return ds

    @classmethod
    def from_dataset(cls, ds: xr.Dataset) -> RunState:
        """The state a :meth:`to_dataset` Dataset holds; :class:`CheckpointError` if it is
        not one, of another format, or its checksum does not match."""
        fmt = ds.attrs.get("checkpoint_format")
        if fmt is None:
            raise CheckpointError("not a run state (no checkpoint_format attribute)")
        if int(fmt) != FORMAT:
            raise CheckpointError(f"run state format {fmt}, this code reads {FORMAT}")
        try:
            if ds.attrs["sha256"] != _checksum(ds):
                raise CheckpointError("its checksum does not match its content (corrupt)")
            a = ds.attrs
            columns = json.loads(a["columns"])
            complex_names = set(json.loads(a["complex_json"]))
            arrays = {
                str(k): _unpair(v.values) if k in complex_names else np.asarray(v.values)
                for k, v in ds.data_vars.items()
            }
            rows = [dict(zip(columns, map(float, r), strict=True)) for r in arrays["rows"]]
            snaps = [
                (float(t), s)
                for t, s in zip(arrays.get("snap_time", ()), arrays.get("snaps", ()), strict=True)
            ]
            solver = SolverState(
                h=float(a["h"]),
                q_hat=arrays.get("q_hat"),
                stats={k: int(v) for k, v in json.loads(a["stats_json"]).items()},
                margin_min=float(a["margin_min"]),
            )
            state = cls(
                t=float(a["t"]),
                fields=arrays["fields"],
                solver=solver,
                mechanics={k[5:]: v for k, v in arrays.items() if k.startswith("mech_")},
                counters=json.loads(a["counters_json"]),
                rows=rows,
                snaps=snaps,
                parameters=json.loads(a["parameters_json"]),
                numerics=json.loads(a["numerics_json"]),
                seed=int(a["seed"]),
                stopped=float(a["stopped"]),
                wall=float(a["wall"]),
                lineage=list(json.loads(a["lineage_json"])),
                initial_from=str(a.get("initial_from", "")),
                code_version=str(a["code_version"]),
            )
        except CheckpointError:
            raise
        except (KeyError, ValueError, TypeError, IndexError) as e:
            raise CheckpointError(f"an incomplete run state ({type(e).__name__}: {e})") from e
        if not np.all(np.isfinite(state.fields)):
            raise CheckpointError("its fields are not finite")
        return state


def read_netcdf(path: str | Path, group: str | None = None) -> xr.Dataset:
    """The netCDF file ``path`` (its ``group``) loaded into memory, or
    :class:`CheckpointError` saying that it is missing or unreadable."""
    try:
        return xr.load_dataset(path, group=group, engine="netcdf4")
    except FileNotFoundError as e:
        raise CheckpointError(f"{path} does not exist") from e
    except (OSError, ValueError, RuntimeError, KeyError) as e:
        what = "a readable netCDF file" if group is None else f"a netCDF file with a group {group}"
        raise CheckpointError(f"{path} is not {what} ({e})") from e


def load(path: str | Path) -> RunState:
    """Read and check the state in ``path`` (:class:`CheckpointError` naming the cause if it
    is missing, unreadable, truncated, altered or not a run state)."""
    path = Path(path)
    ds = read_netcdf(path)
    try:
        return RunState.from_dataset(ds)
    except CheckpointError as e:
        raise CheckpointError(f"{path}: {e}") from e


def _pair(a: Array, name: str) -> tuple[tuple[str, ...], Array]:
    """A netCDF variable of the array: a complex one as its (re, im) pair (leading dim
    "part"), a real one as it is."""
    a = np.asarray(a)
    dims = tuple(f"{name}_{i}" for i in range(a.ndim))
    if np.iscomplexobj(a):
        return ("part", *dims), np.stack([a.real, a.imag]).astype(float)
    return dims, a.astype(float)


def _unpair(a: Array) -> Array:
    return np.asarray(a[0] + 1j * a[1], dtype=complex)


def _checksum(ds: xr.Dataset) -> str:
    """SHA-256 of every array (name, shape, bytes) and every attribute but itself."""
    h = hashlib.sha256()
    for name in sorted(map(str, ds.data_vars)):
        v = np.ascontiguousarray(ds[name].values, dtype=float)
        h.update(f"{name}{v.shape}".encode())
        h.update(v.tobytes())
    attrs = {k: v for k, v in ds.attrs.items() if k != "sha256"}
    h.update(json.dumps({k: _plain(v) for k, v in sorted(attrs.items())}).encode())
    return h.hexdigest()


def _plain(v: Any) -> Any:
    """An attribute as the checksum reads it: the same in memory and read back from a file
    (numpy scalars as Python ones, NaN as text)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    return v


def _differences(a: dict[str, Any], b: dict[str, Any]) -> str:
    keys = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    return ", ".join(f"{k}: {a.get(k)!r} there, {b.get(k)!r} here" for k in keys[:4])
