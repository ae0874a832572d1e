"""Indexing results folders into the catalogue from what is on disk, recomputing nothing.

A results folder (``<root>/<name>/`` with ``runs/``, ``manifest.json`` or ``phase.nc``) is
indexed from its run records (``runs/<run_id>.json``: everything the catalogue holds of a run),
or, where it has no run records (a shipped folder with its ``phase.nc`` alone), from the cells of
its ``phase.nc`` (each run's id, status, reason and scalars; the fixed parameters and numerics
from its attributes, the swept values from its coordinates; no file).

A run file that is a link to another campaign's (a run that campaign reused,
:mod:`nematic_solids.sweep.catalogue.reuse`) is recorded with the path of the file it links to
and the origin "reused".
"""

from __future__ import annotations

import hashlib
import logging
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..files import netcdf_lock
from ..store import CAMPAIGN_COPY, MANIFEST, PHASE, RUNS, CampaignStore
from .catalogue import Catalogue
from .rows import RunRow, row_from_record

log = logging.getLogger(__name__)

#: the rows written per transaction while indexing
BATCH = 2000


@dataclass
class Indexed:
    """What indexing found: runs per campaign, and the folders it could not read."""

    runs: dict[str, int] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    @property
    def total(self) -> int:
        return sum(self.runs.values())


def is_results_folder(path: Path) -> bool:
    return path.is_dir() and any((path / name).exists() for name in (RUNS, MANIFEST, PHASE))


def results_folders(root: Path) -> list[Path]:
    """The results folders directly under ``root``, by name."""
    try:
        entries = sorted(p for p in root.iterdir() if not p.name.startswith("."))
    except OSError:
        return []
    return [p for p in entries if is_results_folder(p)]


def campaign_hash(folder: Path) -> str | None:
    """The SHA-256 of the folder's campaign copy (``campaign.yaml``), else of the campaign
    text its ``phase.nc`` keeps (attribute ``campaign_yaml``), if any."""
    try:
        return hashlib.sha256((folder / CAMPAIGN_COPY).read_bytes()).hexdigest()
    except OSError:
        pass
    try:
        import netCDF4

        with netcdf_lock(), netCDF4.Dataset(folder / PHASE, "r") as nc:
            text = str(nc.getncattr("campaign_yaml"))
    except (OSError, AttributeError, KeyError):
        return None
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def file_path(store: CampaignStore, run_id: str) -> tuple[str, bool]:
    """The run's file relative to the results root (a link resolved: the file it names),
    and whether it is a link (a reused run)."""
    nc = store.nc_path(run_id)
    root = store.results_root.resolve()
    linked = nc.is_symlink()
    target = nc.resolve() if linked else nc.absolute()
    try:
        rel = target.relative_to(root)
    except ValueError:
        rel = Path(os.path.relpath(target, root))
    return rel.as_posix(), linked


def record_rows(store: CampaignStore, run_ids: list[str] | None = None) -> Iterator[RunRow]:
    """The rows of a folder's run records (all, or those of ``run_ids``)."""
    name = store.root.name
    if run_ids is None:
        try:
            run_ids = sorted(p.stem for p in store.runs_dir.glob("*.json"))
        except OSError:
            return
    for rid in run_ids:
        record = store.read_record(rid)
        if record is None or "run_id" not in record:
            continue
        path, linked = file_path(store, rid)
        origin = "reused" if linked or record.get("reused_from") else "made"
        yield row_from_record(record, name, path, origin)


def _cell_value(value: Any) -> Any:
    if hasattr(value, "tolist") and getattr(value, "size", 1) != 1:
        return value.tolist()  # an attribute that is a list (a protocol's times, ...)
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    return value


def phase_rows(folder: Path) -> Iterator[RunRow]:
    """The rows of a ``phase.nc`` (a folder without run records): one per cell that names a
    run that ran (status ok or failed)."""
    import numpy as np
    import xarray as xr

    with xr.open_dataset(folder / PHASE, engine="netcdf4") as ds:
        ds.load()
    if "run_id" not in ds or "status" not in ds:
        return
    dims = tuple(str(d) for d in ds["run_id"].dims)
    per_run = [
        n
        for n, v in ds.data_vars.items()
        if v.dims == dims and n not in ("run_id", "status", "reason")
    ]
    params = {
        k[len("param_") :]: _cell_value(v) for k, v in ds.attrs.items() if k.startswith("param_")
    }
    numerics = {
        k[len("num_") :]: _cell_value(v) for k, v in ds.attrs.items() if k.startswith("num_")
    }
    code = str(ds.attrs.get("code_version", "")) or None
    status = ds["status"].values
    run_ids = ds["run_id"].values
    reasons = ds["reason"].values if "reason" in ds else None
    columns = {str(n): ds[n].values for n in per_run}
    coords = {d: ds[d].values if d in ds.coords else np.arange(ds.sizes[d]) for d in dims}
    for index in np.ndindex(*status.shape):
        code_ = int(status[index])
        rid = str(_cell_value(run_ids[index]))
        if code_ == 0 or not rid:  # missing
            continue
        where = zip(dims, index, strict=True)
        cell: dict[str, Any] = {d: _cell_value(coords[d][i]) for d, i in where}
        seed = cell.pop("seed", None)
        scalars: dict[str, Any] = {}
        for n, values in columns.items():
            v = _cell_value(values[index])
            if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                scalars[n] = v
        reason = str(_cell_value(reasons[index])) if reasons is not None else ""
        yield RunRow(
            run_id=rid,
            campaign=folder.name,
            status="ok" if code_ == 1 else "failed",
            source="phase",
            reason=reason or None,
            t_final=numerics.get("t_final"),
            seed=int(seed) if isinstance(seed, (int, float)) else None,
            code_version=code,
            parameters=params,
            numerics=numerics,
            scalars=scalars,
            coords=cell,
            wall_time=scalars.get("run_time"),
        )


def _batches(rows: Iterator[RunRow], size: int = BATCH) -> Iterator[list[RunRow]]:
    batch: list[RunRow] = []
    for row in rows:
        batch.append(row)
        if len(batch) >= size:
            yield batch
            batch = []
    if batch:
        yield batch


def index_folder(catalogue: Catalogue, folder: Path, root: Path) -> tuple[int, str]:
    """Index one results folder; returns how many runs and from what ("records", "phase.nc"
    or "nothing")."""
    store = CampaignStore(root, folder.name)
    rel = os.path.relpath(folder, root)
    catalogue.set_campaign(folder.name, rel, campaign_hash(folder))
    has_records = store.runs_dir.is_dir() and any(store.runs_dir.glob("*.json"))
    if has_records:
        rows: Iterator[RunRow] = record_rows(store)
        source = "records"
    elif (folder / PHASE).exists():
        rows, source = phase_rows(folder), "phase.nc"
    else:
        return 0, "nothing"
    n = 0
    for batch in _batches(rows):
        n += catalogue.record(batch, {folder.name: rel})
    return n, source


def index_root(catalogue: Catalogue, root: Path | None = None) -> Indexed:
    """Index every results folder under ``root`` (default: the catalogue's). A folder that
    cannot be read is reported and skipped; the others are indexed."""
    root = Path(root if root is not None else catalogue.root or ".")
    out = Indexed()
    for folder in results_folders(root):
        try:
            n, source = index_folder(catalogue, folder, root)
        except (OSError, ValueError, KeyError) as e:
            out.problems.append(f"{folder}: {e}")
            log.warning("catalogue: %s not indexed: %s", folder, e)
            continue
        out.runs[folder.name] = n
        out.sources[folder.name] = source
    catalogue.db.set_meta("indexed", str(root.resolve()))
    return out
