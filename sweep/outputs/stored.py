"""The campaign a results folder was made with: ``results/<name>/campaign.yaml``, the text
of the last ``nematic run`` with its command-line overrides and the campaign file's path as
header comments (written by
:func:`nematic_solids.sweep.campaign_copy.save_campaign_copy`), read back as a
:class:`~nematic_solids.sweep.campaign.Campaign` (:func:`stored_campaign`)."""

from __future__ import annotations

import ast
from typing import Any

from ..campaign import Campaign
from ..campaign_copy import OVERRIDE_PREFIX, SOURCE_PREFIX
from ..errors import StoreError
from ..spec import Overrides, parse_campaign
from ..store import CampaignStore


def stored_overrides(text: str) -> Overrides:
    """The overrides a campaign copy's header records (``--set``, ``--seeds``, ``--name``;
    the execution overrides do not change the runs and are left out)."""
    settings: dict[str, Any] = {}
    seeds: Any = None
    name = None
    for line in text.splitlines():
        if not line.startswith(OVERRIDE_PREFIX):
            break
        option, _, value = line[len(OVERRIDE_PREFIX) :].partition(" ")
        try:
            if option == "--set":
                key, _, literal = value.partition("=")
                settings[key] = ast.literal_eval(literal)
            elif option == "--seeds":
                seeds = ast.literal_eval(value)
            elif option == "--name":
                name = value
        except (ValueError, SyntaxError):
            continue  # not written by this code: the campaign text alone
    return Overrides(settings=settings, seeds=seeds, name=name)


def stored_text(store: CampaignStore) -> str | None:
    """The campaign copy's text, or ``None`` when the folder has none."""
    try:
        return store.campaign_copy.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as e:
        raise StoreError(f"cannot read {store.campaign_copy}: {e}") from None


def stored_campaign(
    store: CampaignStore, text: str | None = None, *, build_points: bool = True
) -> Campaign | None:
    """The campaign of the folder's copy (validated by this code), ``None`` without a copy.
    Raises :class:`~nematic_solids.sweep.errors.CampaignError` when this code does not accept it
    (``build_points``: whether its grid points are built and checked by the model, as
    :func:`~nematic_solids.sweep.spec.parse_campaign`'s)."""
    if text is None:
        text = stored_text(store)
    if text is None:
        return None
    return parse_campaign(
        text,
        stored_source(store, text),
        stored_overrides(text),
        default_name=store.root.name,
        build_points=build_points,
    )


def stored_source(store: CampaignStore, text: str) -> str:
    """The path the copy's relative paths are read against: the campaign file it was read
    from (its header's :data:`~nematic_solids.sweep.campaign_copy.SOURCE_PREFIX` line), else
    the copy."""
    for line in text.splitlines():
        if line.startswith(SOURCE_PREFIX):
            return line[len(SOURCE_PREFIX) :].strip()
        if not line.startswith("# "):
            break
    return str(store.campaign_copy)
