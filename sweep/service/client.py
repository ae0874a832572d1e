"""The command line's side of the service (``nematic submit``, ``queue``, ``cancel``, and
``nematic run`` handing a campaign over): finds the service of a results root from its
``.service/service.json``, reads its token from the file only its owner can read, and calls
its API with ``Authorization: token ...`` (the standard library's HTTP client: nothing to
install for the command line)."""

from __future__ import annotations

import json
import ssl
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

from . import ServiceError
from .paths import ServicePaths

TIMEOUT = 30.0


class ServiceClient:
    def __init__(self, url: str, token: str | None, cafile: str | None = None):
        self.url = url.rstrip("/")
        self.token = token
        self.context = (
            ssl.create_default_context(cafile=cafile) if url.startswith("https") else None
        )

    @classmethod
    def for_root(cls, root: Path) -> ServiceClient | None:
        """The client of the service running for ``root``, or ``None`` if none runs."""
        paths = ServicePaths(root)
        info = paths.running()
        if info is None or not info.get("url"):
            return None
        token = paths.read_token() if info.get("token_file") else None
        if info.get("token_file") and token is None:
            raise ServiceError(
                f"the service of {paths.root} runs ({info['url']}) but its token file "
                f"{paths.token} cannot be read by this user"
            )
        return cls(str(info["url"]), token, info.get("certfile"))

    def call(self, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.url + path, data=data, method=method)
        if data is not None:
            request.add_header("Content-Type", "application/json")
        if self.token:
            request.add_header("Authorization", f"token {self.token}")
        try:
            with urllib.request.urlopen(request, timeout=TIMEOUT, context=self.context) as r:
                return json.loads(r.read().decode() or "null")
        except urllib.error.HTTPError as e:
            try:
                detail = json.loads(e.read().decode()).get("detail")
            except (ValueError, AttributeError):
                detail = e.reason
            raise ServiceError(f"the service refused: {e.code} {detail}") from None
        except (urllib.error.URLError, OSError) as e:
            reason = getattr(e, "reason", e)
            raise ServiceError(f"cannot reach the service at {self.url}: {reason}") from None

    def submit(
        self,
        path: Path,
        priority: int = 0,
        settings: dict[str, Any] | None = None,
        seeds: int | list[int] | None = None,
        name: str | None = None,
    ) -> dict[str, Any]:
        text = path.read_text(encoding="utf-8")
        body = {
            "text": text,
            "source": str(path.resolve()),
            "priority": priority,
            "settings": settings or {},
            "seeds": seeds,
            "name": name,
        }
        return dict(self.call("POST", "/api/queue", body))

    def queue(self) -> dict[str, Any]:
        return dict(self.call("GET", "/api/queue"))

    def cancel(self, entry_id: int) -> dict[str, Any]:
        return dict(self.call("POST", f"/api/queue/{entry_id}/cancel", {}))


def require_client(root: Path) -> ServiceClient:
    client = ServiceClient.for_root(root)
    if client is None:
        raise ServiceError(
            f"no service runs for {Path(root).resolve()}: start one with 'nematic serve {root}'"
        )
    return client
