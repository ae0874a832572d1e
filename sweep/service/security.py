"""The service's security, after Jupyter's server: a token on by default (generated at start,
printed with the URL, exchanged for an HttpOnly cookie when a page is opened with
``?token=...``, sent by the command line as ``Authorization: token ...``); a closed service
without it (every path but the login page answers 401); requests that change something (submit,
cancel) need the token and pass a CSRF check (:func:`csrf_problem`); the Host header must name
the address the service listens on (:func:`host_allowed`: no DNS rebinding); a non-loopback
address is refused without a token and TLS (:func:`bind_problem`); names in paths are checked
before they touch the disk (:func:`safe_name`, :func:`inside`)."""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import re
from collections.abc import Mapping
from pathlib import Path
from urllib.parse import urlsplit

#: The cookie that holds the token once a page was opened with ``?token=``.
COOKIE = "nematic_token"
#: The header a page's script sends with a request that changes something (its value is
#: :func:`csrf_token`, written into the page).
CSRF_HEADER = "x-nematic-csrf"
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
#: A campaign name or run id as it may appear in a path: no separator, no leading dot.
NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.+=-]{0,199}$")


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) is this machine's loopback."""
    if host.strip("[]").lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def bind_problem(host: str, token: str | None, tls: bool) -> str | None:
    """Why the service must not listen on ``host``, or ``None``: any address but the loopback
    needs both a token and TLS (the token would otherwise cross the network in clear text)."""
    if is_loopback(host):
        return None
    missing = [
        what for what, ok in (("a token", token), ("TLS (--certfile, --keyfile)", tls)) if not ok
    ]
    if not missing:
        return None
    return (
        f"refusing to listen on {host}: an address other than the loopback (127.0.0.1) "
        f"needs {' and '.join(missing)}; on a cluster's login node keep 127.0.0.1 and reach "
        "it through an SSH tunnel (ssh -L PORT:127.0.0.1:PORT LOGIN-NODE)"
    )


def token_matches(given: str | None, token: str) -> bool:
    return given is not None and hmac.compare_digest(given.encode(), token.encode())


def presented_token(
    headers: Mapping[str, str], cookies: Mapping[str, str]
) -> tuple[str | None, str]:
    """The token a request carries and how: ``("...", "header")`` from ``Authorization:
    token ...`` (or ``Bearer ...``), ``("...", "cookie")`` from :data:`COOKIE`, else
    ``(None, "")``. The query's ``?token=`` counts only where a page exchanges it for the
    cookie."""
    auth = headers.get("authorization", "")
    scheme, _, value = auth.partition(" ")
    if scheme.lower() in ("token", "bearer") and value.strip():
        return value.strip(), "header"
    if cookies.get(COOKIE):
        return cookies[COOKIE], "cookie"
    return None, ""


def csrf_token(token: str) -> str:
    """The CSRF value of a service's token (an HMAC: it reveals nothing of the token), written
    into its pages and sent back by their scripts in :data:`CSRF_HEADER`."""
    return hmac.new(token.encode(), b"nematic-csrf", hashlib.sha256).hexdigest()


def _origin_of(url: str) -> str | None:
    parts = urlsplit(url)
    if not parts.scheme or not parts.netloc:
        return None
    return f"{parts.scheme}://{parts.netloc}".lower()


def csrf_problem(
    method: str, headers: Mapping[str, str], how: str, token: str, scheme: str
) -> str | None:
    """Why a request that changes something is refused as a possible cross-site request, or
    ``None``. An ``Origin`` (else a ``Referer``) that the request carries must be this
    service's own (``scheme://Host``); a request authenticated by the cookie must carry one of
    them and the page's CSRF value in :data:`CSRF_HEADER` (a form on another site can send the
    cookie, not the header). The command line's header token needs no more: a browser does
    not send an ``Authorization`` header across sites without the service's CORS consent,
    which it never gives."""
    if method.upper() in SAFE_METHODS:
        return None
    own = f"{scheme}://{headers.get('host', '')}".lower()
    origin = headers.get("origin")
    referer = headers.get("referer")
    if origin is not None and origin != "null":
        if origin.lower() != own:
            return f"cross-site request refused: Origin {origin} is not {own}"
    elif origin == "null":
        return "cross-site request refused: Origin null"
    elif referer and _origin_of(referer) != own:
        return f"cross-site request refused: Referer {referer} is not from {own}"
    if how == "cookie":
        if origin is None and not referer:
            return "a request authenticated by the cookie must say its Origin or Referer"
        if not token_matches(headers.get(CSRF_HEADER), csrf_token(token)):
            return f"a request authenticated by the cookie needs the page's {CSRF_HEADER} header"
    return None


def host_allowed(host_header: str, bound: str) -> bool:
    """Whether the Host header names the address the service listens on: a service on the
    loopback answers only to loopback names (a DNS name that resolves to 127.0.0.1 in a
    browser, DNS rebinding, is refused); on another address, to that address or any name (the
    token guards it, and TLS)."""
    host = host_header.rsplit(":", 1)[0] if not host_header.endswith("]") else host_header
    if is_loopback(bound):
        return is_loopback(host)
    return True


def safe_name(name: str) -> bool:
    """Whether ``name`` (a campaign's, a run id) may be looked up on disk: one path component,
    no leading dot (so no ``..``), no separator."""
    return bool(NAME.match(name)) and "/" not in name and "\\" not in name


def inside(root: Path, path: Path) -> bool:
    """Whether ``path``, resolved (links followed), lies within ``root``."""
    try:
        return path.resolve().is_relative_to(root.resolve())
    except OSError:
        return False
