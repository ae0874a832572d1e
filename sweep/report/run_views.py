"""One run as the report's phase diagram shows it when its point is clicked: the run's last
snapshot (a small PNG drawn with :func:`nematic_solids.sweep.figures.common.safe_snapshot`, as a
data URI) and the time series of the diagram's observable (sigma2_S(t) for the paper's model).

Drawing a snapshot means importing matplotlib and reading the run file: most of what a
report costs beyond its imports. So each run's views are kept in ``results/<name>/
report_cache/<run_id>.json``, valid while the run file has the size and mtime it had (and
:data:`VIEWS_VERSION` is the one that drew them): ``nematic run`` writes the report at the
end of a campaign, and a later ``nematic report`` draws only the runs that changed. The cache
is only a cache: deleting it costs the drawing once; a folder it cannot be written to is
left alone."""

from __future__ import annotations

import base64
import contextlib
import io
import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..files import dumps, series_time, temporary_path

log = logging.getLogger(__name__)

#: The report's cache folder under ``results/<name>/``.
CACHE = "report_cache"
#: Drawn views of another version are drawn again (bump when the drawing changes).
VIEWS_VERSION = 1
SNAPSHOT_INCHES, SNAPSHOT_DPI = 2.6, 100

RunViews = tuple[str, list[float], list[float]]


def png_data_uri(fig: Any) -> str:
    """A matplotlib figure as a ``data:image/png;base64`` URI (the page embeds every image)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def draw_run_views(path: Path, series: str) -> RunViews:
    """One run's last snapshot as a PNG data URI ("" without a snapshot) and its time series
    ``series`` (non-positive values left out: the panel's axis is logarithmic), from its
    file."""
    import xarray as xr
    from matplotlib.figure import Figure

    from ..figures.common import safe_snapshot

    with xr.open_dataset(path) as ds:
        names = [n for n in ("q1", "q2", "I1bar", series) if n in ds]
        run = ds[names].load()
    t = series_time(run).values.astype(float) if series in run else np.array([])
    y = run[series].values.astype(float) if series in run else np.array([])
    keep = np.isfinite(t) & np.isfinite(y) & (y > 0)
    image = ""
    if run.sizes.get("snapshot_time", 0) and "q1" in run and "q2" in run:
        fig = Figure(figsize=(SNAPSHOT_INCHES, SNAPSHOT_INCHES), dpi=SNAPSHOT_DPI)
        ax = fig.add_axes((0.02, 0.02, 0.96, 0.88))
        with np.errstate(all="ignore"):
            safe_snapshot(ax, run, -1, colorbar=False, arrows=16)
        t_snap = float(run["snapshot_time"].values[-1])
        ax.set_title(f"director (colour: S) over I1bar, t/tau = {t_snap:g}", fontsize=7)
        image = png_data_uri(fig)
    return image, t[keep].tolist(), y[keep].tolist()


def _stamp(path: Path) -> list[int]:
    st = path.stat()
    return [VIEWS_VERSION, st.st_size, st.st_mtime_ns]


def run_views(path: Path, series: str) -> RunViews:
    """:func:`draw_run_views` of the run file ``path`` (``results/<name>/runs/<id>.nc``),
    from the cache where it holds the views of this very file and series, else drawn and
    cached."""
    stamp = _stamp(path)
    cached = path.parent.parent / CACHE / f"{path.stem}.json"
    try:
        data = json.loads(cached.read_text(encoding="utf-8"))
        if data.get("stamp") == stamp and data.get("series") == series:
            return str(data["image"]), list(data["t"]), list(data["y"])
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        pass  # absent, unreadable or of another file: drawn again
    image, t, y = draw_run_views(path, series)
    _store(cached, dumps({"stamp": stamp, "series": series, "image": image, "t": t, "y": y}))
    return image, t, y


def _store(path: Path, text: str) -> None:
    """Write a cache file through a temporary name (renamed: never half a file), without
    the fsync of the results' own files (a lost cache file is drawn again)."""
    tmp = temporary_path(path)
    try:
        path.parent.mkdir(exist_ok=True)
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as e:
        log.debug("report: %s not cached: %s", path.name, e)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
