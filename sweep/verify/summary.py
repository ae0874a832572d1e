"""What ``verify.nc`` says, read back: the file loaded (:func:`read_verify`), the one-line
summary of ``run``, ``verify`` and ``status`` (:func:`summary_line`) and the rows of the
report's and ``status -v``'s tables (:func:`verdict_rows`, :func:`transition_rows`). The file
is written by :mod:`nematic_solids.sweep.verify.measure`."""

from __future__ import annotations

import math
from pathlib import Path

import xarray as xr

from . import CHANGED, CONVERGED, MISSING, NOT_COMPARED, REQUIRED, VERIFY, stale


def _pct(x: float, absolute: bool) -> str:
    if not math.isfinite(x):
        return "inf"
    if absolute:
        return f"by {abs(x):.2g}"
    return f"{100 * abs(x):.0f} %" if abs(x) < 10 else f"by a factor {1 + x:.3g}"


def summary_line(ds: xr.Dataset, worst: int = 2) -> str:
    """One line: "12 of 14 sampled points converged; K = 1e-06: lambda changes 38 % with
    resolution x2". A point converged when it converged under every variant."""
    conv = ds["converged"].values
    n = conv.shape[0]
    ok = int((conv == CONVERGED).all(axis=1).sum())
    missing = int((conv == MISSING).any(axis=1).sum())
    text = f"{ok} of {n} sampled points converged"
    if missing:
        text += f" ({missing} with runs missing)"
    notes: list[tuple[float, str]] = []
    variants = [str(v) for v in ds["variant_name"].values]
    labels = [str(x) for x in ds["label"].values]
    for p in range(n):
        for v in range(len(variants)):
            if conv[p, v] != CHANGED:
                continue
            b, f = float(ds["patterned_base"].values[p]), float(ds["patterned"].values[p, v])
            if b != f:
                notes.append(
                    (
                        math.inf,
                        f"{labels[p]}: the patterned fraction changes from "
                        f"{b:.2g} to {f:.2g} with {variants[v]}",
                    )
                )
                continue
            best = (-1.0, "")
            for name in [
                str(k)[: -len("_verdict")] for k in ds.data_vars if str(k).endswith("_verdict")
            ]:
                if ds[f"{name}_verdict"].values[p, v] == CHANGED:
                    c = float(ds[f"{name}_change"].values[p, v])
                    # the file says how the change is measured (the observable's rule)
                    absolute = str(ds[f"{name}_change"].attrs.get("long_name", "")).startswith(
                        "absolute"
                    )
                    size = abs(c) if math.isfinite(c) else math.inf
                    if size > best[0]:
                        best = (
                            size,
                            f"{labels[p]}: {name} changes {_pct(c, absolute)} with {variants[v]}",
                        )
            if best[1]:
                notes.append(best)
    notes.sort(key=lambda t: -t[0])
    if notes:
        text += "; " + "; ".join(t for _, t in notes[:worst])
        if len(notes) > worst:
            text += f"; {len(notes) - worst} more"
    if "transition_within" in ds:
        w = ds["transition_within"].values
        text += f"; transitions: {int(w.sum())} of {w.size} stay in their interval"
    return text


#: How a verdict reads in tables.
VERDICT_TEXT = {
    CONVERGED: "converged",
    CHANGED: "CHANGED",
    NOT_COMPARED: "not compared",
    MISSING: "missing",
}


def read_verify(root: Path) -> xr.Dataset | None:
    """``root/verify.nc`` loaded, or ``None`` when there is none. Raises ``OSError`` /
    ``ValueError`` when it cannot be read."""
    path = root / VERIFY
    if not path.exists():
        return None
    with xr.open_dataset(path) as ds:
        ds = ds.load()
    missing = [n for n in REQUIRED if n not in ds.variables]
    if missing:
        raise ValueError(stale(missing))
    return ds


def verdict_rows(ds: xr.Dataset) -> list[dict[str, str]]:
    """One row per sampled point and variant: the point, why it is sampled, the variant,
    the verdict (with a class change) and the compared observables' changes."""
    rows = []
    names = [str(k)[: -len("_verdict")] for k in ds.data_vars if str(k).endswith("_verdict")]
    for p in range(ds.sizes["point"]):
        for v, variant in enumerate(ds["variant_name"].values):
            changes = []
            for n in names:
                if int(ds[f"{n}_verdict"].values[p, v]) not in (CONVERGED, CHANGED):
                    continue
                c = float(ds[f"{n}_change"].values[p, v])
                absolute = "absolute" in str(ds[f"{n}_change"].attrs.get("long_name"))
                if absolute:
                    changes.append(f"{n} {c:+.3f}")
                elif abs(c) < 10:
                    changes.append(f"{n} {100 * c:+.1f} %")
                else:  # orders of magnitude: the factor reads better
                    changes.append(f"{n} x{1 + c:.3g}")
            verdict = VERDICT_TEXT.get(int(ds["converged"].values[p, v]), "?")
            b, f = float(ds["patterned_base"].values[p]), float(ds["patterned"].values[p, v])
            if b != f and math.isfinite(b) and math.isfinite(f):
                verdict += f" (patterned fraction {b:.2g} -> {f:.2g})"
            rows.append(
                {
                    "point": str(ds["label"].values[p]),
                    "why": str(ds["why"].values[p]),
                    "variant": str(variant),
                    "verdict": verdict,
                    "changes": ", ".join(changes),
                }
            )
    return rows


def transition_rows(ds: xr.Dataset) -> list[dict[str, str]]:
    """One row per fitted transition and variant: where the variant puts it."""
    if "transition_within" not in ds:
        return []
    rows = []
    for t in range(ds.sizes["transition"]):
        lo, hi = float(ds["transition_lower"].values[t]), float(ds["transition_upper"].values[t])
        for v, variant in enumerate(ds["variant_name"].values):
            loc = float(ds["transition_location_variant"].values[t, v])
            where = (
                "no jump in the bracket"
                if not math.isfinite(loc)
                else f"at {loc:g}, "
                + ("in" if ds["transition_within"].values[t, v] else "outside")
                + f" the fit's interval [{lo:g}, {hi:g}]"
            )
            rows.append(
                {
                    "transition": str(ds["transition_fit"].values[t]),
                    "variant": str(variant),
                    "where": where,
                }
            )
    return rows
