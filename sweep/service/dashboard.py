"""The dashboard's two pages (all campaigns; one campaign), served by the service: plain HTML
with the script and style of ``static/`` written into the page (no CDN, no other request than
the service's own API), the CSRF value in a ``meta`` element for the script's requests that
change something. The script (``static/dashboard.js``) draws the phase diagram as SVG and
listens to the service's event stream (``/api/events``)."""

from __future__ import annotations

import html
from functools import cache
from pathlib import Path

#: The script and style of the pages (package data).
STATIC = Path(__file__).parent / "static"
PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="nematic-csrf" content="{csrf}">
<link rel="icon" href="data:,">
<title>{title}</title>
<style>{style}</style></head>
<body data-page="{page}" data-campaign="{campaign}">
<header><a href="/">nematic service</a> <span id="live" title="updates pushed by the service">
connecting</span></header>
<main id="main"><p>loading</p></main>
<script>{script}</script>
</body></html>
"""


@cache
def _static(name: str) -> str:
    return (STATIC / name).read_text(encoding="utf-8")


def _page(page: str, title: str, campaign: str, csrf: str) -> str:
    script = _static("dashboard.js").replace("</", "<\\/")
    return PAGE.format(
        csrf=html.escape(csrf),
        title=html.escape(title),
        page=page,
        campaign=html.escape(campaign),
        style=_static("dashboard.css"),
        script=script,
    )


def index_page(csrf: str) -> str:
    """Every campaign of the root and the queue."""
    return _page("index", "nematic service: campaigns", "", csrf)


def campaign_page(name: str, csrf: str) -> str:
    """One campaign: its phase diagram filling in, failures, cost, rounds, a run on click."""
    return _page("campaign", f"nematic service: {name}", name, csrf)


__all__ = ["campaign_page", "index_page"]
