"""``results/<name>/report.html``: one self-contained page about a campaign (``nematic
report``; ``nematic run`` writes it after the figures): its question, grid and counts, the
figures and fits, an interactive phase diagram (bokeh, its JavaScript inlined) whose points
show their runs, the failures by reason, the refinement rounds, the cost and the provenance.

:mod:`.content` gathers what the page says from the results folder, :mod:`.phase_plot`
builds the interactive phase diagram, :mod:`.page` renders and writes the HTML."""

from __future__ import annotations

from .page import REPORT, build_report, write_report

__all__ = ["REPORT", "build_report", "write_report"]
