"""``fits.nc``: the requested fits computed from ``phase.nc`` and merged into one file
(written atomically), its caveats for the command line, and reading both files back."""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from nematic_solids.model.errors import NematicError

from ..errors import FitError
from ..files import atomic_to_netcdf
from ..provenance import code_version, git_commit, library_versions_text
from ..store import PHASE, now_iso
from .registry import REGISTRY, resolve

log = logging.getLogger(__name__)

FITS = "fits.nc"


def compute_fits(
    phase: xr.Dataset,
    requests: Iterable[tuple[str, Mapping[str, Any]]],
    root: Path | None = None,
    *,
    strict: bool = True,
) -> tuple[xr.Dataset, dict[str, str]]:
    """Run the requested fits on ``phase``; return the merged Dataset and the failures
    (``{name: message}``; with ``strict`` the first failure raises)."""
    parts: list[xr.Dataset] = []
    failures: dict[str, str] = {}
    done: list[str] = []
    for name, options in resolve(requests):
        try:
            part = REGISTRY[name].function(phase, options, root)
        except NematicError as e:
            if strict:
                raise
            failures[name] = " ".join(str(e).split())
            log.info("fit %s skipped: %s", name, failures[name])
            continue
        except Exception as e:
            if strict:
                raise
            # a bug, or data we did not foresee: one line (the traceback with --verbose)
            failures[name] = f"{type(e).__name__}: {' '.join(str(e).split())}"
            log.info("fit %s failed: %s", name, failures[name])
            log.debug("fit %s failed", name, exc_info=True)
            continue
        for var in part.data_vars.values():
            var.attrs.setdefault("fit", name)
        parts.append(part)
        done.append(f"{name}: {json.dumps(options, sort_keys=True, default=str)}")
    merged = (
        xr.merge(parts, compat="no_conflicts", join="outer", combine_attrs="override")
        if parts
        else xr.Dataset()
    )
    merged.attrs.update(
        {
            "Conventions": "CF-1.11",
            "title": f"fits of campaign {phase.attrs.get('campaign', '')}",
            "history": f"{now_iso()}: fitted from phase.nc by nematic_solids.sweep.analysis",
            "library_versions": library_versions_text(),
            "campaign": str(phase.attrs.get("campaign", "")),
            "source": "active-nematic-solids fits (nematic_solids.sweep.analysis) of phase.nc",
            "phase_created": str(phase.attrs.get("created", "")),
            "code_version": code_version(),
            "git_commit": git_commit(),
            "created": now_iso(),
            "fits": "; ".join(done),
            "failed_fits": "; ".join(f"{k}: {v}" for k, v in failures.items()),
        }
    )
    return merged, failures


def fit_notes(ds: xr.Dataset) -> list[str]:
    """One-line caveats about the fits in ``ds`` (a fits.nc) for the command line: the runs
    the ``alpha_cr`` / ``scaling`` fits left out because the first peak of sigma2_S was not
    reached by t_final, a peak check that could not be done, and the K whose alpha_cr is at
    its lower bound. Empty when there is nothing to say (or no such fit)."""
    if "alpha_cr" not in ds:
        return []
    notes = []
    attrs = ds["alpha_cr"].attrs
    n = int(attrs.get("fit_n_unpeaked", 0))
    check = str(attrs.get("fit_peak_check", ""))
    if n:
        notes.append(
            f"alpha_cr/scaling: {n} of {int(attrs.get('fit_n_patterned', n))} "
            "patterned run(s) left out: the first peak of sigma2_S was not reached "
            f"by t_final ({check}; per point: alpha_cr_unpeaked_count in {FITS})"
        )
    elif check.startswith("not done"):
        notes.append(f"alpha_cr/scaling: runs without a peak of sigma2_S not looked for ({check})")
    if "alpha_cr_at_bound" in ds:
        at = np.asarray(ds["alpha_cr_at_bound"].values).astype(bool)
        if at.any():
            K = ", ".join(f"{float(k):g}" for k in ds["K"].values[at])
            notes.append(
                f"alpha_cr at its bound {attrs.get('fit_alpha_cr_min', 0)} for K = "
                f"{K} (the unbounded fit would put it lower)"
            )
    return notes


def load_phase(root: Path) -> xr.Dataset:
    """``root/phase.nc`` loaded into memory (the file is closed)."""
    path = Path(root) / PHASE
    if not path.is_file():
        raise FitError(
            f"no phase diagram at {path}: run the campaign (nematic run) or "
            "aggregate it (nematic aggregate) first"
        )
    with xr.open_dataset(path) as ds:
        return ds.load()


def write_fits(
    root: Path, requests: Iterable[tuple[str, Mapping[str, Any]]], *, strict: bool = False
) -> tuple[Path, dict[str, str]]:
    """Compute the requested fits from ``root/phase.nc`` and write ``root/fits.nc``
    atomically; return its path and the failures."""
    root = Path(root)
    phase = load_phase(root)
    ds, failures = compute_fits(phase, requests, root, strict=strict)
    path = root / FITS
    atomic_to_netcdf(ds, path)
    log.info("wrote %s (%s)", path, ds.attrs.get("fits", ""))
    return path, failures


def load_fits(root: Path) -> xr.Dataset:
    """``root/fits.nc`` loaded into memory, or an empty Dataset if there is none."""
    path = Path(root) / FITS
    if not path.is_file():
        return xr.Dataset()
    with xr.open_dataset(path) as ds:
        return ds.load()
