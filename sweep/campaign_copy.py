"""The campaign copy that ``nematic run`` keeps in a results folder
(``results/<name>/campaign.yaml``): the campaign's text under a header of comments, its
command-line overrides and the absolute path of the campaign file it was read from (the copy's
relative paths, ``prior:``, are read from that file's folder). Read back by
:mod:`nematic_solids.sweep.outputs.stored`."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from .campaign import Campaign
from .store import CampaignStore

#: The header line of the campaign copy that records one command-line override.
OVERRIDE_PREFIX = "# override: "
#: The header line of the campaign copy that records the campaign file it was read from: the
#: copy's relative paths (``prior:``) are read against that file's folder.
SOURCE_PREFIX = "# source: "


def campaign_copy_text(text: str, overrides: Iterable[str] = (), source: str | None = None) -> str:
    """The content of ``campaign.yaml``: the overrides as comments, the campaign file's
    absolute path (``source``, where it is a file), then the campaign text."""
    head = "".join(f"{OVERRIDE_PREFIX}{o}\n" for o in overrides)
    if source is not None and Path(source).is_file():
        head += f"{SOURCE_PREFIX}{Path(source).resolve()}\n"
    return head + text


def save_campaign_copy(store: CampaignStore, campaign: Campaign) -> None:
    """Keep the campaign as ``nematic run`` ran it in its results folder (the copy:
    :func:`campaign_copy_text`), for the changes of the next run and ``open_campaign``."""
    store.save_campaign_text(campaign_copy_text(campaign.text, campaign.overrides, campaign.source))
