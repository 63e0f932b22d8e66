"""The testbed's guard on the lab's network: who may talk to the server, and how long and how much.

A page the subject's browser visits elsewhere must not be able to drive the experiment, read it, or frame it:

* **Host allow-list** (DNS rebinding): a request whose ``Host`` is not 127.0.0.1, localhost, ::1 or the
  ``--host`` the server was started with is refused (400) before any route runs.
* **Origin** (CSRF): a state-changing request (anything but GET/HEAD) whose ``Origin`` is not this server's own is
  refused (403); without an ``Origin`` only a request that no browser marked as cross-site passes (a script, a
  test). Its body must be declared ``application/json`` (415): a foreign page's "simple" form or text POST cannot
  be, without a preflight the server never answers.
* **Headers**: a Content-Security-Policy allowing only this server's own scripts, styles and connections, with
  ``frame-ancestors 'none'`` (and ``X-Frame-Options: DENY``), ``nosniff``, ``no-referrer`` (the URL may hold a
  token).
* **Tokens**: with ``--host`` (other machines can reach the page) every request needs the session's token, in the
  URL the experimenter hands out (``?token=…``, then a same-site cookie); the experimenter's page and its API always
  need the experimenter's key (``?key=…``), which only the terminal shows.
* **Time and size**: a connection that has not sent its request's headers within :data:`HEADER_TIMEOUT_S` is
  closed (:func:`guarded_h11`); a body must arrive within :data:`BODY_TIMEOUT_S` (408) and be at most
  :data:`MAX_BODY` bytes (413); at most :data:`MAX_CONNECTIONS` connections are served at once (503 beyond).
"""

from __future__ import annotations

import hmac
import json
import socket
from collections.abc import Iterable
from typing import Any
from urllib.parse import parse_qs, urlsplit

__all__ = ["Guard", "guarded_h11", "allowed_hosts", "HEADER_TIMEOUT_S", "BODY_TIMEOUT_S", "MAX_BODY",
           "MAX_CONNECTIONS", "CSP", "LOCAL_HOSTS"]

#: Seconds a connection may take to send a request's headers (a slow client is closed, not waited for).
HEADER_TIMEOUT_S = 10.0
#: Seconds a request's body may take to arrive.
BODY_TIMEOUT_S = 30.0
#: The largest request body read: a 30 s trial with every read and input event is well under 2 MB.
MAX_BODY = 8 << 20
#: Connections served at once; more get a 503.
MAX_CONNECTIONS = 64
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
       "object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
HEADERS = [(b"content-security-policy", CSP.encode()), (b"x-frame-options", b"DENY"),
           (b"x-content-type-options", b"nosniff"), (b"referrer-policy", b"no-referrer"),
           (b"cross-origin-opener-policy", b"same-origin"), (b"cross-origin-resource-policy", b"same-origin")]
EXPERIMENTER_PATHS = ("/experimenter", "/api/experimenter")


def allowed_hosts(host: str) -> frozenset[str]:
    """The host names the server answers to: this machine's loopback names, and ``host`` when it listens there
    (for 0.0.0.0 or ::, this machine's name and addresses)."""
    names = set(LOCAL_HOSTS)
    if host in ("0.0.0.0", "::", ""):
        name = socket.gethostname()
        names |= {name.lower(), socket.getfqdn().lower()}
        try:
            names |= {str(info[4][0]).lower() for info in socket.getaddrinfo(name, None)}
        except OSError:
            pass
    else:
        names.add(host.lower().strip("[]"))
    return frozenset(names)


def _hostname(value: str) -> str | None:
    try:
        parts = urlsplit("//" + value)
        _ = parts.port  # a malformed port raises
    except ValueError:
        return None
    return parts.hostname


def _header(scope: dict, name: bytes) -> str | None:
    for key, value in scope.get("headers", ()):
        if key == name:
            return value.decode("latin-1")
    return None


def _cookie(scope: dict, name: str) -> str | None:
    raw = _header(scope, b"cookie") or ""
    for part in raw.split(";"):
        key, eq, value = part.strip().partition("=")
        if eq and key == name:
            return value
    return None


def _same(a: str | None, b: str | None) -> bool:
    return a is not None and b is not None and hmac.compare_digest(a.encode(), b.encode())


async def _refuse(send: Any, status: int, message: str) -> None:
    body = json.dumps({"error": message}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                            *HEADERS]})
    await send({"type": "http.response.body", "body": body})


class Guard:
    """ASGI middleware: the host allow-list, tokens, the origin and content-type checks, the security headers.

    Parameters
    ----------
    hosts : iterable of str
        Host names answered (:func:`allowed_hosts`).
    token : str, optional
        Needed on every request (``?token=`` once, then a cookie) when the page is served beyond this machine.
    key : str, optional
        Needed on the experimenter's page and API (``?key=`` once, then a cookie); without one they are closed.
    """

    def __init__(self, app: Any, hosts: Iterable[str], token: str | None = None, key: str | None = None) -> None:
        self.app = app
        self.hosts = frozenset(h.lower() for h in hosts)
        self.token = token
        self.key = key

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        host = _hostname(_header(scope, b"host") or "")
        if host not in self.hosts:
            await _refuse(send, 400, "this server answers only to " + ", ".join(sorted(self.hosts)) + " (Host header "
                          "refused)")
            return
        port = (scope.get("server") or (None, None))[1]
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        cookies: list[bytes] = []
        if scope["path"].startswith(EXPERIMENTER_PATHS):
            if self.key is None:
                await _refuse(send, 403, "the experimenter's page is closed (no key)")
                return
            needed = ("key", self.key, "the experimenter's key")
        else:
            needed = None if self.token is None else ("token", self.token, "the session's token")
        if needed is not None:
            param, wanted, what = needed
            name = f"wb_{param}_{port}"
            if _same((query.get(param) or [None])[0], wanted):
                cookies.append(f"{name}={wanted}; Path=/; HttpOnly; SameSite=Strict".encode())
            elif not _same(_cookie(scope, name), wanted):
                await _refuse(send, 403, f"this page needs {what}: open the link the experimenter gave")
                return
        if scope["method"] not in ("GET", "HEAD"):
            origin = _header(scope, b"origin")
            if origin is not None:
                o = urlsplit(origin)
                try:
                    o_port = o.port or 80
                except ValueError:
                    o_port = None
                if o.scheme != "http" or (o.hostname or "") not in self.hosts or o_port != port:
                    await _refuse(send, 403, f"a request from another site ({origin[:80]}) is refused")
                    return
            elif (_header(scope, b"sec-fetch-site") or "same-origin") not in ("same-origin", "none"):
                await _refuse(send, 403, "a cross-site request is refused")
                return
            kind = (_header(scope, b"content-type") or "").split(";")[0].strip().lower()
            if kind != "application/json":
                await _refuse(send, 415, "a request body must be declared application/json")
                return

        async def send_with_headers(message: dict) -> None:
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []), *HEADERS,
                                                  *((b"set-cookie", c) for c in cookies)]}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def guarded_h11(header_timeout_s: float = HEADER_TIMEOUT_S) -> type:
    """uvicorn's h11 protocol that closes a connection whose request headers have not arrived within
    ``header_timeout_s`` of its opening or of its previous response (uvicorn's own keep-alive timeout stops as
    soon as any byte arrives, so a client sending one header line a minute would be kept forever)."""
    from uvicorn.protocols.http.h11_impl import H11Protocol

    class GuardedH11(H11Protocol):
        _header_timer: Any = None

        def connection_made(self, transport: Any) -> None:  # type: ignore[override]
            super().connection_made(transport)
            self._arm()

        def _arm(self) -> None:
            self._disarm()
            self._header_timer = self.loop.call_later(header_timeout_s, self._too_slow)

        def _disarm(self) -> None:
            if self._header_timer is not None:
                self._header_timer.cancel()
                self._header_timer = None

        def handle_events(self) -> None:
            before = self.cycle
            super().handle_events()
            if self.cycle is not before:  # a request's headers are complete
                self._disarm()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            if not self.transport.is_closing():
                self._arm()

        def connection_lost(self, exc: Exception | None) -> None:
            self._disarm()
            super().connection_lost(exc)

        def _too_slow(self) -> None:
            self._header_timer = None
            if not self.transport.is_closing():
                self.transport.close()

    return GuardedH11
