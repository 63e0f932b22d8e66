"""The experiment server: a Starlette application served by uvicorn on 127.0.0.1, the page and its JSON API.

Routes (all JSON but the page and its files)::

    GET  /                      the page (static/index.html); ?subject=ID preselects the subject
    GET  /static/…              its ES modules and style sheet, served from this package (no CDN, no build step)
    GET  /api/config            the protocol as the page shows it, and the task (:func:`.task.task_spec`)
    GET  /api/subject/{id}      a subject's status (the next step, trials done), or {"registered": false}
    POST /api/subject           register {subject, fields}; a known subject resumes
    POST /api/calibration       {subject, calibration}
    POST /api/advance           {subject, key}: a practice, break or instructions step is over
    POST /api/trial             a finished trial: replayed through the plant, then written (MCAP, Parquet)
    POST /api/practice          a practice trial: checked; kept only if the protocol records practice
    POST /api/live              states of a trial in flight, for the experimenter's view (never stored)

A request body larger than :data:`MAX_BODY` is refused before it is read whole; bad input is a 400 whose
``error`` is one line (the page shows it).
"""

from __future__ import annotations

import json
import signal
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from workbench.collect.session import Session
from workbench.errors import WorkbenchError

__all__ = ["make_app", "Server", "STATIC", "MAX_BODY"]

STATIC = Path(__file__).with_name("static")
#: The largest request body read: a 30 s trial with every input event is well under 1 MB.
MAX_BODY = 8 << 20


def make_app(session: Session, *, on_trial: Callable[[dict[str, Any], dict[str, Any]], None] | None = None,
             on_live: Callable[[dict[str, Any], dict[str, Any] | None], None] | None = None) -> Any:
    """The Starlette application of one session.

    ``on_trial(result, payload)`` is called with each written trial's result and what the page sent;
    ``on_live(piece, item)`` with each piece of a trial in flight (the page sends them only when it is given).
    """
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import FileResponse, JSONResponse, Response
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    def error(message: str, status: int = 400) -> JSONResponse:
        return JSONResponse({"error": message}, status_code=status)

    async def body(request: Request) -> Any:
        declared = request.headers.get("content-length")
        if declared is not None and (not declared.isdigit() or int(declared) > MAX_BODY):
            raise WorkbenchError(f"request body of {declared} bytes; at most {MAX_BODY}")
        data = bytearray()
        async for chunk in request.stream():
            data += chunk
            if len(data) > MAX_BODY:
                raise WorkbenchError(f"request body over {MAX_BODY} bytes")
        try:
            return json.loads(data)
        except ValueError as exc:
            raise WorkbenchError(f"request body is not JSON ({exc})") from None
        except RecursionError:  # a few MB of '[' nest deeper than the parser recurses
            raise WorkbenchError("request body is JSON nested too deeply") from None

    def handler(work: Callable[[Any], Any]) -> Callable:
        async def endpoint(request: Request) -> JSONResponse:
            from starlette.concurrency import run_in_threadpool

            try:
                payload = await body(request) if request.method == "POST" else request
                return JSONResponse(await run_in_threadpool(work, payload))
            except WorkbenchError as exc:
                return error(" ".join(str(exc).split()))

        return endpoint

    async def index(request: Request) -> FileResponse:
        # no-store: a reloaded page always runs the modules this server ships
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def no_icon(request: Request) -> Response:
        return Response(status_code=204)

    def config(_: Any) -> dict[str, Any]:
        return {"protocol": session.protocol.to_json(), "task": session.spec, "live": on_live is not None}

    def subject_status(request: Any) -> dict[str, Any]:
        subject = request.path_params["subject"]
        if session.subject_doc(subject) is None:
            return {"registered": False, "subject": subject}
        return {"registered": True, **session.status(subject)}

    def register(p: Any) -> dict[str, Any]:
        _need(p, "subject")
        return {"registered": True, **session.register(p["subject"], p.get("fields", {}))}

    def calibrate(p: Any) -> dict[str, Any]:
        _need(p, "subject")
        session.calibrate(p["subject"], p.get("calibration"))
        return session.status(p["subject"])

    def advance(p: Any) -> dict[str, Any]:
        _need(p, "subject", "key")
        return session.advance(p["subject"], str(p["key"]))

    def trial(p: Any) -> dict[str, Any]:
        out = session.write_trial(p)
        if on_trial is not None:
            on_trial(out, p)
        return out

    def live(p: Any) -> dict[str, Any]:
        if on_live is None:
            return {}
        _need(p, "subject", "slot", "k0", "x")
        x = p["x"]
        n = len(session.spec["state_names"])
        if not (isinstance(x, list) and len(x) <= 200 and all(
                isinstance(r, list) and len(r) == n and all(isinstance(v, int | float) for v in r) for r in x)
                and isinstance(p["k0"], int) and isinstance(p["slot"], int)):
            raise WorkbenchError("live: expected {subject, slot, k0, x: [[state], …]} with at most 200 states")
        items = {i.slot: i for i in session.plan(str(p["subject"])) if i.kind == "trial"}
        item = items.get(p["slot"])
        on_live(p, None if item is None else item.to_json())
        return {}

    routes = [
        Route("/", index),
        Route("/favicon.ico", no_icon),
        Route("/api/config", handler(config)),
        Route("/api/subject/{subject}", handler(subject_status)),
        Route("/api/subject", handler(register), methods=["POST"]),
        Route("/api/calibration", handler(calibrate), methods=["POST"]),
        Route("/api/advance", handler(advance), methods=["POST"]),
        Route("/api/trial", handler(trial), methods=["POST"]),
        Route("/api/practice", handler(session.write_practice), methods=["POST"]),
        Route("/api/live", handler(live), methods=["POST"]),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    return Starlette(routes=routes)


def _need(p: Any, *keys: str) -> None:
    if not isinstance(p, dict) or any(k not in p for k in keys):
        raise WorkbenchError(f"expected a JSON object with {', '.join(keys)}")


class Server:
    """uvicorn serving an application on ``host:port`` (``port`` 0: a free one), in this thread or another.

    The socket is bound here, before the server runs, so :attr:`url` is known (and a taken port is an error)
    at once.
    """

    def __init__(self, app: Any, host: str = "127.0.0.1", port: int = 8765) -> None:
        import uvicorn

        self.sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise WorkbenchError(f"cannot listen on {host}:{port} ({exc.strerror}); choose another --port") from None
        self.host, self.port = host, self.sock.getsockname()[1]

        class _Uvicorn(uvicorn.Server):
            def handle_exit(self, sig: int, frame: Any) -> None:
                # Ctrl-C (or SIGTERM) ends serving and the command goes on to save the experimenter's recording
                # and print its summary: the normal end of a session, not raised again as uvicorn would
                if self.should_exit and sig == signal.SIGINT:
                    self.force_exit = True
                self.should_exit = True

        self.server = _Uvicorn(uvicorn.Config(app, log_level="warning", lifespan="off"))
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

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
