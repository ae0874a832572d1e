"""What a py-pde model's run records (:mod:`.pypde`): its observables as measures in the
style of py-pde's trackers (:class:`Measure`, :class:`FunctionMeasure`), the run state that
collects their series, checkpoints and progress (:class:`Recorder`, a py-pde tracker) and the
end state a chain or a longer run continues from (:class:`PDEState`, kept with its checksum)."""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from pde.fields.base import FieldBase
from pde.trackers.base import TrackerBase

from .interface import Observable, RunRequest


class Measure:
    """One observable of a py-pde run (py-pde's tracker style: ``handle``, ``finalize``).

    Subclasses set ``observable`` and implement :meth:`handle`; a measure keeps no state
    between calls, so one instance serves every run."""

    observable: Observable

    def handle(self, state: FieldBase, t: float) -> float:
        """The value at a save time ``t`` of the state."""
        raise NotImplementedError

    def finalize(self, times: np.ndarray, values: np.ndarray, state: FieldBase) -> float:
        """The run's scalar from its series and final state: the last value."""
        return float(values[-1])


@dataclass(frozen=True)
class FunctionMeasure(Measure):
    """A measure from a plain function of the state."""

    observable: Observable
    function: Callable[[FieldBase], float]

    def handle(self, state: FieldBase, t: float) -> float:
        return float(self.function(state))


@dataclass(frozen=True)
class PDEState:
    """A run's end state: the field's data at time ``t`` and the measures' series so far."""

    data: np.ndarray
    t: float
    times: tuple[float, ...] = ()
    series: Mapping[str, tuple[float, ...]] = field(default_factory=dict)

    def to_dataset(self, snapshots: bool = True) -> xr.Dataset:
        """The state as a dataset (to keep it in a file), with the SHA-256 of its data and
        time; :meth:`PDEState.from_dataset` reads it. (``snapshots``: a py-pde model's run
        file keeps no snapshots of the field, only its final value.)"""
        dims = [f"axis_{i}" for i in range(self.data.ndim)]
        ds = xr.Dataset({"data": (dims, self.data)}, coords={"time": list(self.times)})
        for name, values in self.series.items():
            ds[f"series_{name}"] = ("time", list(values))
        ds.attrs["t"] = self.t
        ds.attrs["sha256"] = self.checksum()
        return ds

    def checksum(self) -> str:
        """The SHA-256 of the field's data (float64, C order) and the time."""
        h = hashlib.sha256(np.ascontiguousarray(self.data, dtype=np.float64).tobytes())
        h.update(repr(float(self.t)).encode())
        return h.hexdigest()

    @classmethod
    def from_dataset(cls, ds: xr.Dataset) -> PDEState:
        """The state that :meth:`to_dataset` wrote; ``ValueError`` where its data do not match
        its checksum (a file altered or truncated)."""
        series = {
            str(k)[7:]: tuple(map(float, v.values))
            for k, v in ds.items()
            if str(k).startswith("series_")
        }
        if "data" not in ds or "t" not in ds.attrs:
            raise ValueError("no field data and time: not a py-pde model's state")
        state = cls(
            np.array(ds["data"].values, dtype=np.float64),
            float(ds.attrs["t"]),
            tuple(map(float, ds["time"].values)),
            series,
        )
        if ds.attrs.get("sha256") != state.checksum():
            raise ValueError("the state's data do not match its checksum (altered or truncated)")
        return state


class Recorder(TrackerBase):
    """The run state of one run: the measures' series at the save times, the checkpoints and
    the progress reports (a py-pde tracker)."""

    def __init__(
        self, measures: Sequence[Measure], request: RunRequest, every: float, start: PDEState | None
    ) -> None:
        super().__init__(interrupts=every)
        self.measures = measures
        self.request = request
        self.times: list[float] = list(start.times) if start else []
        self.values = {
            m.observable.name: list(start.series.get(m.observable.name, ())) if start else []
            for m in measures
        }
        t0 = start.t if start else 0.0
        self.next_checkpoint = t0 + request.checkpoint_every

    def handle(self, field: FieldBase, t: float) -> None:
        if self.times and t <= self.times[-1]:
            return  # the start of a continued run: already in its series
        self.times.append(t)
        for m in self.measures:
            self.values[m.observable.name].append(m.handle(field, t))
        if self.request.progress is not None:
            self.request.progress(t)
        if self.request.checkpoint is not None and t >= self.next_checkpoint:
            self.request.checkpoint(self.state(field, t))
            self.next_checkpoint = t + self.request.checkpoint_every

    def state(self, field: FieldBase, t: float) -> PDEState:
        return PDEState(
            np.array(field.data, copy=True),
            float(t),
            tuple(self.times),
            {k: tuple(v) for k, v in self.values.items()},
        )
