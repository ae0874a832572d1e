"""Drawing a campaign's figures: which fits and figures to produce (:func:`plan`), writing
``fits.nc`` and ``figures/<name>.png|pdf`` atomically (:func:`produce`), and the hook at the
end of ``nematic run`` (:func:`regenerate`)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import xarray as xr

from nematic_solids.model.errors import NematicError

from ..analysis.fits_file import fit_notes, load_fits, load_phase, write_fits
from ..analysis.shape import Shape
from ..campaign import Campaign
from ..errors import FigureError, FitError
from ..files import atomic_path
from .common import FIGURES, FORMATS, PNG_DPI, STYLE, Results
from .failed import record_failed
from .registry import REGISTRY

if TYPE_CHECKING:
    from matplotlib.figure import Figure

log = logging.getLogger(__name__)


@contextlib.contextmanager
def _style() -> Iterator[None]:
    import matplotlib as mpl

    with mpl.rc_context(cast(Any, STYLE)), np.errstate(all="ignore"):
        yield


def save_figure(fig: Figure, folder: Path, name: str) -> list[Path]:
    """Write ``folder/name.png`` and ``.pdf`` atomically; return the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in FORMATS:
        path = folder / f"{name}.{fmt}"
        with atomic_path(path) as tmp:
            fig.savefig(
                tmp,
                format=fmt,
                dpi=PNG_DPI if fmt == "png" else None,
                metadata={"Title": f"{name} ({folder.parent.name})"} if fmt == "pdf" else None,
            )
        paths.append(path)
    return paths


def draw(
    name: str,
    root: str | Path,
    options: Mapping[str, Any] | None = None,
    results: Results | None = None,
) -> list[Path]:
    """Draw registered figure ``name`` from ``root`` (results/<campaign>) into
    ``root/figures/``; return the written paths. Raises :class:`FigureError`."""
    if name not in REGISTRY:
        raise FigureError(f"unknown figure {name!r}; registered: {', '.join(sorted(REGISTRY))}")
    res = results or Results(root)
    with _style():
        fig = REGISTRY[name].function(res, dict(options or {}))
        try:
            return save_figure(fig, res.root / FIGURES, name)
        finally:
            fig.clear()


@dataclass
class Outcome:
    """What :func:`produce` did: the figures it set out to draw, files written, fits and
    figures that failed (name -> why), and caveats about the fits written
    (:func:`nematic_solids.sweep.analysis.fits_file.fit_notes`)."""

    paths: list[Path] = field(default_factory=list)
    failures: dict[str, str] = field(default_factory=dict)
    fits_path: Path | None = None
    figures: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def plan(
    campaign: Campaign, phase: xr.Dataset, names: Sequence[str] | None = None
) -> tuple[list[tuple[str, dict[str, Any]]], list[tuple[str, dict[str, Any]]]]:
    """(fits, figures) to produce: the figures named (``names``), else the campaign's
    ``figures:`` list (``figures: []``: none), else (no ``figures:`` key) every registered
    figure that applies to this grid; the campaign's fits first (their options win), then
    the fits those figures need."""
    shape = Shape.of_phase(phase)
    listed = (
        None if campaign.figures is None else {p.name: dict(p.options) for p in campaign.figures}
    )
    if names:
        unknown = [n for n in names if n not in REGISTRY]
        if unknown:
            raise FigureError(
                f"unknown figure(s) {', '.join(unknown)}; registered: {', '.join(sorted(REGISTRY))}"
            )
        figures = [(n, (listed or {}).get(n, {})) for n in names]
    elif listed is not None:
        figures = list(listed.items())
    else:
        figures = [(n, {}) for n, spec in REGISTRY.items() if spec.drawn_for(shape)]
    fit_requests: list[tuple[str, dict[str, Any]]] = [
        (p.name, dict(p.options)) for p in campaign.fits
    ]
    for n, _ in figures:
        fit_requests.extend(REGISTRY[n].fits(shape))
    return fit_requests, figures


def produce(
    campaign: Campaign,
    results_dir: str | Path,
    *,
    names: Sequence[str] | None = None,
    fits: bool = True,
    draw_figures: bool = True,
) -> Outcome:
    """Write ``fits.nc`` (unless ``fits`` is false) and the figures of ``campaign`` (see
    :func:`plan`; none unless ``draw_figures``) from ``results_dir/<name>/``. Failures are
    collected, not raised, except for a missing phase.nc (:class:`FigureError`), and recorded
    for the report in ``failed_products.json`` (:func:`.failed.record_failed`)."""
    root = Path(results_dir) / campaign.name
    try:
        phase = load_phase(root)
    except FitError as e:
        raise FigureError(str(e)) from None
    fit_requests, figures = plan(campaign, phase, names)
    out = Outcome(figures=[n for n, _ in figures])
    if fits and fit_requests:
        try:
            out.fits_path, failed = write_fits(root, fit_requests)
        except NematicError as e:
            failed = {"fits": str(e)}
        except Exception as e:  # nor may the fits
            failed = {"fits": one_line(e)}
            log.debug("fits not written", exc_info=True)
        out.failures.update({f"fit {k}": v for k, v in failed.items()})
    if out.fits_path is not None:
        out.notes = fit_notes(load_fits(root))
    if figures and draw_figures:  # not with figures: [] in the campaign, or the fits alone
        results = Results(root)
        for name, options in figures:
            try:
                out.paths.extend(draw(name, root, options, results))
            except NematicError as e:
                out.failures[name] = " ".join(str(e).split())
            except Exception as e:  # a figure must never sink the run it follows
                out.failures[name] = one_line(e)
                log.debug("figure %s not drawn", name, exc_info=True)  # --verbose shows it
    drawn = [] if not draw_figures else (list(names) if names else None)
    try:
        record_failed(root, out.failures, fits=bool(fits and fit_requests), figures=drawn)
    except (NematicError, OSError) as e:  # the failures are still printed, and exit 4
        log.warning("the failed products are not recorded for the report: %s", e)
    return out


def one_line(e: BaseException) -> str:
    """An unexpected exception as one line: its type and message, whitespace collapsed."""
    return f"{type(e).__name__}: {' '.join(str(e).split())}"


def regenerate(
    campaign: Campaign, results_dir: str | Path, *, fits: bool = True, draw_figures: bool = True
) -> list[Path]:
    """Fits and figures of ``campaign`` after a run (the hook of ``nematic run``): writes
    ``fits.nc`` (unless ``fits`` is false) and ``figures/*.png|pdf`` (none with
    ``figures: []`` or without ``draw_figures``); returns the figure paths. Never raises for a
    figure that cannot be drawn (it is logged, as are the fits' caveats,
    :func:`nematic_solids.sweep.analysis.fits_file.fit_notes`); returns [] when there is no
    phase.nc."""
    try:
        out = produce(campaign, results_dir, fits=fits, draw_figures=draw_figures)
    except FigureError as e:
        log.warning("no figures: %s", e)
        return []
    for note in out.notes:
        log.warning("fits: %s", note)
    for name, why in out.failures.items():
        log.warning("%s failed: %s", name, why)
    return out.paths
