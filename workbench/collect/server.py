"""The experiment server: a Starlette application served by uvicorn on 127.0.0.1, behind the testbed's guard.

:func:`make_app` joins the routes (:mod:`.routes`) and the guard (:mod:`.guard`: the host allow-list, the origin and
content-type checks, tokens, security headers); :class:`Server` serves it with header and body timeouts and a bound
on connections. ``--host`` other than this machine's loopback needs a token in the page's URL
(:func:`new_token`), which the command prints.
"""

from __future__ import annotations

import secrets
import signal
import socket
import threading
from collections.abc import Callable, Iterable
from typing import Any

from workbench.collect.guard import (
    HEADER_TIMEOUT_S,
    LOCAL_HOSTS,
    MAX_BODY,
    MAX_CONNECTIONS,
    Guard,
    guarded_h11,
)
from workbench.collect.routes import STATIC, routes
from workbench.collect.session import Session
from workbench.errors import UsageError

__all__ = ["make_app", "Server", "STATIC", "MAX_BODY", "new_token", "LOCAL_HOSTS"]


def new_token() -> str:
    """A random token for a URL (128 bits)."""
    return secrets.token_urlsafe(16)


def make_app(session: Session, *, on_trial: Callable[[dict[str, Any], dict[str, Any]], None] | None = None,
             on_live: Callable[[dict[str, Any], dict[str, Any] | None], None] | None = None,
             hosts: Iterable[str] = LOCAL_HOSTS, token: str | None = None, key: str | None = None) -> Any:
    """The guarded Starlette application of one session.

    ``on_trial(result, payload)`` is called with each written trial's result and what the page sent;
    ``on_live(piece, item)`` with each piece of a trial in flight (the page sends them only when it is given).
    ``hosts`` are the host names answered, ``token`` the subject's page's token (None: none needed, on this
    machine only), ``key`` the experimenter's page's key (None: that page is closed).
    """
    from starlette.applications import Starlette

    app = Starlette(routes=routes(session, on_trial=on_trial, on_live=on_live))
    return Guard(app, hosts, token=token, key=key)


class Server:
    """uvicorn serving an application on ``host:port`` (``port`` 0: a free one), in this thread or another.

    The socket is bound and listening here, before the server runs, so :attr:`url` is known (and a taken port is an
    error) at once, and a client that connects before :meth:`run` waits for it instead of being refused.
    Connections that are slow to send their headers are closed (:data:`~.guard.HEADER_TIMEOUT_S`), at most
    :data:`~.guard.MAX_CONNECTIONS` are served at once, idle keep-alive connections close after 5 s.
    """

    def __init__(self, app: Any, host: str = "127.0.0.1", port: int = 8765, *,
                 header_timeout_s: float = HEADER_TIMEOUT_S) -> None:
        import uvicorn

        self.sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise UsageError(f"cannot listen on {host}:{port} ({exc.strerror}); choose another --port") from None
        # listening from here, not from when uvicorn starts: the URL is printed (and a browser opened on it) before
        # run(), and a bound socket that does not listen refuses a connection; a listening one queues it until served
        self.sock.listen()
        self.host, self.port = host, self.sock.getsockname()[1]

        class _Uvicorn(uvicorn.Server):
            def handle_exit(self, sig: int, frame: Any) -> None:
                # Ctrl-C (or SIGTERM) ends serving and the command goes on to save the experimenter's recording
                # and print its summary: the normal end of a session, not raised again as uvicorn would
                if self.should_exit and sig == signal.SIGINT:
                    self.force_exit = True
                self.should_exit = True

        config = uvicorn.Config(app, log_level="warning", lifespan="off", http=guarded_h11(header_timeout_s),
                                limit_concurrency=MAX_CONNECTIONS, timeout_keep_alive=5, access_log=False)
        self.server = _Uvicorn(config)
        self._thread: threading.Thread | None = None

    def url_for(self, host: str | None = None, query: str = "") -> str:
        """The URL of the page on ``host`` (default the address listened on), with ``query``."""
        host = host or self.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/" + (f"?{query}" if query else "")

    @property
    def url(self) -> str:
        return self.url_for()

    def run(self) -> None:
        """Serve until Ctrl-C (in the main thread) or :meth:`stop`."""
        self.server.run(sockets=[self.sock])

    def start(self) -> Server:
        """Serve in a background thread (tests, the CLI's experimenter view); returns once it accepts requests."""
        import time

        self._thread = threading.Thread(target=self.run, name="collect-server", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started and time.monotonic() < deadline:
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=5)
        self.sock.close()

