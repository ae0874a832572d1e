"""``nematic serve``: the service's process (:func:`serve`). It takes the root's service lock
(one service per results root; the kernel releases it however the process ends), refuses an
address it must not listen on, makes its token, opens the queue, binds its socket, records
where it listens (``.service/service.json``), prints the URL with the token, then runs the
runner thread (:class:`~.runner.Runner`) beside the HTTP server (uvicorn) until SIGINT or
SIGTERM, which stops the campaign in flight (it goes back to the queue) and closes the
cluster."""

from __future__ import annotations

import contextlib
import faulthandler
import logging
import os
import signal
import socket
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CampaignLocked
from ..lock import CampaignLock
from . import ServiceError
from .api import ServiceContext, create_app
from .paths import ServicePaths, new_token
from .runner import Changes, ClusterPool, Runner
from .security import bind_problem

log = logging.getLogger(__name__)

DEFAULT_PORT = 8765


@dataclass(frozen=True)
class ServeOptions:
    host: str = "127.0.0.1"
    #: 0: a free port
    port: int = DEFAULT_PORT
    token: bool = True
    certfile: Path | None = None
    keyfile: Path | None = None


def _bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as e:
        sock.close()
        raise ServiceError(
            f"cannot listen on {host}:{port}: {e.strerror} (another program uses the port? "
            "--port 0 takes a free one)"
        ) from None
    sock.listen(128)
    sock.set_inheritable(False)
    return sock


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt, as SIGINT does: uvicorn takes either to stop, then
    raises it again once it has stopped, and the service stops its runner and cluster."""

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def serve(root: Path, options: ServeOptions, say: Callable[[str], None] = print) -> None:
    """Run the service of ``root`` until interrupted (see the module's docstring). Raises
    :class:`ServiceError` when it cannot start (another service holds the root, the
    address is refused, the port is taken)."""
    import uvicorn

    from .catalogue_link import open_service_database

    tls = options.certfile is not None and options.keyfile is not None
    if (options.certfile is None) != (options.keyfile is None):
        raise ServiceError("TLS needs both --certfile and --keyfile")
    token = new_token() if options.token else None
    problem = bind_problem(options.host, token, tls)
    if problem is not None:
        raise ServiceError(problem)
    paths = ServicePaths(root)
    paths.ensure()
    lock = CampaignLock(paths.lock)
    try:
        lock.acquire(command=" ".join(sys.argv))
    except CampaignLocked:
        info = paths.running() or {}
        raise ServiceError(
            f"a service already runs for {paths.root} (pid {info.get('pid', '?')}, "
            f"{info.get('url', '?')}); 'nematic queue --results {root}' talks to it"
        ) from None
    try:
        paths.clear_info()  # a killed service's: where this one listens is written below
        catalogue, queue = open_service_database(paths.root)
        sock = _bind(options.host, options.port)
        port = sock.getsockname()[1]
        if token is not None:
            paths.write_token(token)
        changes = Changes()
        runner = Runner(paths.root, queue, ClusterPool(paths.folder / "cluster"), changes)
        ctx = ServiceContext(
            paths.root, token, options.host, port, tls, catalogue, queue, changes, runner
        )
        paths.write_info(
            {
                "url": ctx.url,
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "started": ctx.started,
                "tls": tls,
                "certfile": str(options.certfile) if options.certfile else None,
                "token_file": str(paths.token) if token else None,
            }
        )
        say(f"nematic service of {paths.root}")
        say(f"  dashboard: {ctx.url}" + (f"?token={token}" if token else ""))
        if token:
            say(f"  token file (read by nematic submit/queue/cancel): {paths.token}")
        config = uvicorn.Config(
            create_app(ctx),
            log_level="warning",
            ssl_certfile=str(options.certfile) if tls else None,
            ssl_keyfile=str(options.keyfile) if tls else None,
            timeout_graceful_shutdown=2,
        )
        server = uvicorn.Server(config)
        faulthandler.register(signal.SIGUSR1, all_threads=True)  # kill -USR1: the stacks
        runner.start()
        try:
            with sigterm_as_interrupt():
                server.run(sockets=[sock])
        except KeyboardInterrupt:
            pass  # uvicorn stopped on the signal, then raised it again
        finally:
            say("stopping: the campaign in flight goes back to the queue")
            runner.shutdown()
    finally:
        paths.clear_info()
        lock.release()
