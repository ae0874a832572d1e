"""Where the service keeps its queue: the root's catalogue database
(``<root>/catalogue.sqlite``) unless another database URL is given."""

from __future__ import annotations

from pathlib import Path

from .queue import QueueStore, queue_engine

DATABASE = "catalogue.sqlite"


def queue_store_for(root: Path, url: str | None = None) -> QueueStore:
    return QueueStore(queue_engine(url or f"sqlite:///{root / DATABASE}"))
