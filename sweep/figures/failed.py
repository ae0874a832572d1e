"""The fits and figures that failed when they were last produced, kept in the campaign folder
(``results/<name>/failed_products.json``: product -> the one-line reason) so that the report
names them as ``nematic run`` and ``nematic figures`` did. :func:`record_failed` updates it
after each products step, atomically; :func:`read_failed` reads it."""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Mapping
from pathlib import Path

from ..files import atomic_write_text, dumps

log = logging.getLogger(__name__)

FAILED_PRODUCTS = "failed_products.json"


def label(key: str) -> str:
    """A key of ``Outcome.failures`` (``fit NAME``, or a figure's name) as the product it names:
    ``fit transition``, ``figure loop``."""
    return key if key.startswith("fit ") else f"figure {key}"


def read_failed(root: Path) -> dict[str, str]:
    """The products that failed in ``root`` (product, as :func:`label` writes it -> why),
    sorted; ``{}`` when none failed or nothing was produced yet. An unreadable file (it is
    written atomically, so only a hand edit makes one) is logged and read as none."""
    path = Path(root) / FAILED_PRODUCTS
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as e:
        log.warning("%s cannot be read (%s); the products step rewrites it", path, e)
        return {}
    if not isinstance(data, dict):
        log.warning("%s is not a JSON object; the products step rewrites it", path)
        return {}
    return {str(k): str(v) for k, v in sorted(data.items())}


def record_failed(
    root: Path,
    failures: Mapping[str, str],
    *,
    fits: bool,
    figures: Iterable[str] | None,
) -> None:
    """Update ``root/failed_products.json`` after a products step: the entries of what it
    produced again are replaced by its ``failures`` (keys of ``Outcome.failures``); the others
    are kept. ``fits``: fits.nc was written again (every fit's entry goes, since the file holds
    only the fits just computed); ``figures``: the figures drawn again, ``None`` for every
    figure (the campaign's whole list), ``[]`` for none. No failure left: the file is
    removed."""
    root = Path(root)
    drawn = None if figures is None else {label(n) for n in figures}
    kept = {
        k: v
        for k, v in read_failed(root).items()
        if not (fits and k.startswith("fit "))
        and not (k.startswith("figure ") and (drawn is None or k in drawn))
    }
    kept.update({label(k): v for k, v in failures.items()})
    path = root / FAILED_PRODUCTS
    if kept:
        atomic_write_text(path, dumps(kept) + "\n")
    else:
        path.unlink(missing_ok=True)
