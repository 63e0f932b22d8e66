"""The server's routes: the subject's page and its JSON API, the experimenter's page and its API.

Routes (all JSON but the pages and their files)::

    GET  /                          the subject's page (static/index.html); ?subject=ID resumes that subject
    GET  /static/…                  its ES modules and style sheet, served from this package (no CDN, no build)
    GET  /api/config                the protocol as the page shows it, and the task (:func:`.task.task_spec`)
    GET  /api/subject/{id}          a subject's status (the next step, trials done), or {"registered": false}
    POST /api/subject               register {subject, fields, consent: {sha256}, confirm}; 409 asks to confirm
    POST /api/consent               a declined consent {subject, consent: {sha256}}: recorded
    POST /api/calibration           {subject, calibration}: complete, or refused
    POST /api/start                 {subject, slot}: the subject started a trial (its start time)
    POST /api/advance               {subject, key}: a practice, break, message, instructions or fit step is over
    POST /api/trial                 a finished trial: replayed through the plant, then written (MCAP, Parquet)
    POST /api/practice              a practice trial: checked; kept only if the protocol records practice
    POST /api/live                  states of a trial in flight, for the experimenter's view (never stored)
    GET  /experimenter              the experimenter's page (needs the key)
    GET  /api/experimenter/session  every subject's progress, trials and fits
    POST /api/experimenter/exclude  {trial, excluded, note}
    POST /api/experimenter/refit    {subject, label}: forget a failed fit, so it runs again

Bad input is a 4xx whose ``error`` is one line (the page shows it); a full disk is a 507; a client that hangs up
is not an error. JSON bodies are read bounded (:data:`~.guard.MAX_BODY`, :data:`~.guard.BODY_TIMEOUT_S`) with
numbers checked as they are parsed: no NaN or Infinity, no integer beyond 2^53.
"""

from __future__ import annotations

import errno
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from workbench.collect.guard import BODY_TIMEOUT_S, MAX_BODY
from workbench.collect.session import Session
from workbench.collect.subjects import check_subject
from workbench.errors import RequestError, WorkbenchError

__all__ = ["routes", "STATIC", "read_body"]

STATIC = Path(__file__).with_name("static")
_MAX_INT = 2**53
_FULL = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)}


class _Gone(Exception):
    """The client hung up before its request arrived whole: nobody is there to answer."""


def _int(text: str) -> int:
    if len(text) > 17 or abs(int(text)) > _MAX_INT:
        raise ValueError(f"the integer {text[:20]}… is too large")
    return int(text)


def _float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"the number {text[:20]} is not finite")
    return value


def _constant(text: str) -> Any:
    raise ValueError(f"{text} is not a number JSON allows")


async def read_body(request: Any) -> Any:
    """The request's JSON body, bounded in size and time, numbers checked as they are parsed."""
    import anyio
    from starlette.requests import ClientDisconnect

    declared = request.headers.get("content-length")
    if declared is not None and (not declared.isdigit() or int(declared) > MAX_BODY):
        raise RequestError(f"request body of {declared[:20]} bytes; at most {MAX_BODY}", 413)
    data = bytearray()
    try:
        with anyio.fail_after(BODY_TIMEOUT_S):
            async for chunk in request.stream():
                data += chunk
                if len(data) > MAX_BODY:
                    raise RequestError(f"request body over {MAX_BODY} bytes", 413)
    except TimeoutError:
        raise RequestError(f"request body not received within {BODY_TIMEOUT_S:g} s", 408) from None
    except ClientDisconnect:
        raise _Gone from None
    try:
        return json.loads(bytes(data), parse_int=_int, parse_float=_float, parse_constant=_constant)
    except RecursionError:  # a few MB of '[' nest deeper than the parser recurses
        raise RequestError("request body is JSON nested too deeply") from None
    except ValueError as exc:
        raise RequestError(f"request body is not JSON of finite numbers ({' '.join(str(exc).split())[:120]})") from None


def _finite(value: Any) -> Any:
    """JSON-ready values with every non-finite float as null (a prediction that diverged stays answerable)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:600]


def _need(p: Any, *keys: str) -> dict[str, Any]:
    if not isinstance(p, dict) or any(k not in p for k in keys):
        raise RequestError(f"expected a JSON object with {', '.join(keys)}")
    return p


def routes(session: Session, *, on_trial: Callable[[dict[str, Any], dict[str, Any]], None] | None = None,
           on_live: Callable[[dict[str, Any], dict[str, Any] | None], None] | None = None) -> list:
    """The Starlette routes of one session (see the module docstring)."""
    from starlette.concurrency import run_in_threadpool
    from starlette.requests import Request
    from starlette.responses import FileResponse, JSONResponse, Response
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    def handler(work: Callable[[Any], Any]) -> Callable:
        async def endpoint(request: Request) -> Response:
            try:
                payload = await read_body(request) if request.method == "POST" else request
                return JSONResponse(_finite(await run_in_threadpool(work, payload)))
            except _Gone:
                return Response(status_code=400)  # nobody reads it: not logged, not an error of the server's
            except RequestError as exc:
                return JSONResponse({"error": _one_line(exc), **exc.extra}, status_code=exc.status)
            except WorkbenchError as exc:
                return JSONResponse({"error": _one_line(exc)}, status_code=400)
            except OSError as exc:
                full = exc.errno in _FULL
                where = f" ({exc.filename})" if exc.filename else ""
                print(f"error: cannot write{where}: {exc.strerror or exc}", file=sys.stderr, flush=True)
                return JSONResponse({"error": ("the disk is full: nothing was written; tell the experimenter" if full
                                               else f"the server cannot write: {exc.strerror or exc}")},
                                    status_code=507 if full else 503)

        return endpoint

    def page(name: str) -> Callable:
        async def serve(request: Request) -> FileResponse:
            # no-store: a reloaded page always runs the modules this server ships
            return FileResponse(STATIC / name, headers={"Cache-Control": "no-store"})

        return serve

    async def no_icon(request: Request) -> Response:
        return Response(status_code=204)

    def config(_: Any) -> dict[str, Any]:
        return {"protocol": session.protocol.to_json(), "task": session.spec, "live": on_live is not None}

    def subject_status(request: Any) -> dict[str, Any]:
        subject = check_subject(request.path_params["subject"])
        if session.subject_doc(subject) is None:
            return {"registered": False, "subject": subject}
        return {"registered": True, **session.status(subject)}

    def register(p: Any) -> dict[str, Any]:
        p = _need(p, "subject", "consent")
        confirm = p.get("confirm", False)
        if not isinstance(confirm, bool):
            raise RequestError("confirm: expected true or false")
        return {"registered": True, **session.register(p["subject"], p.get("fields", {}), p["consent"], confirm)}

    def decline(p: Any) -> dict[str, Any]:
        p = _need(p, "consent")
        return session.decline(p.get("subject"), p["consent"])

    def calibrate(p: Any) -> dict[str, Any]:
        p = _need(p, "subject", "calibration")
        return session.calibrate(check_subject(p["subject"]), p["calibration"])

    def start(p: Any) -> dict[str, Any]:
        p = _need(p, "subject", "slot")
        return session.start_trial(check_subject(p["subject"]), p["slot"])

    def advance(p: Any) -> dict[str, Any]:
        p = _need(p, "subject", "key")
        if not isinstance(p["key"], str):
            raise RequestError("key: expected the step's key")
        return session.advance(check_subject(p["subject"]), p["key"])

    def trial(p: Any) -> dict[str, Any]:
        out = session.write_trial(p)
        if on_trial is not None:
            on_trial(out, p)
        return out

    def live(p: Any) -> dict[str, Any]:
        p = _need(p, "subject", "slot", "k0", "x")
        subject = check_subject(p["subject"])
        x, k0, slot = p["x"], p["k0"], p["slot"]
        n, steps = len(session.spec["state_names"]), session.spec["max_steps"]
        if not (isinstance(x, list) and len(x) <= 200 and all(
                isinstance(r, list) and len(r) == n and all(
                    isinstance(v, int | float) and not isinstance(v, bool) and abs(v) < 1e6 for v in r) for r in x)
                and isinstance(k0, int) and not isinstance(k0, bool) and 0 <= k0 <= steps
                and isinstance(slot, int) and not isinstance(slot, bool) and -1 <= slot <= 100_000):
            raise RequestError("live: expected {subject, slot, k0 (a step of the trial), x: [[state], …]} with at "
                               "most 200 states")
        if on_live is None:
            return {}
        items = {i.slot: i for i in session.plan(subject) if i.kind == "trial"}
        item = items.get(slot)
        on_live({**p, "subject": subject}, None if item is None else item.to_json())
        return {}

    def overview(_: Any) -> dict[str, Any]:
        return session.overview()

    def exclude(p: Any) -> dict[str, Any]:
        p = _need(p, "trial", "excluded")
        return session.exclude(p["trial"], p["excluded"], p.get("note", ""))

    def refit(p: Any) -> dict[str, Any]:
        p = _need(p, "subject", "label")
        subject = check_subject(p["subject"])
        if p["label"] not in {f.label for f in session.protocol.fits}:
            raise RequestError("refit: not a label of this protocol's fit steps")
        session.fits.retry(subject, p["label"])
        return {"retried": True}

    return [
        Route("/", page("index.html")),
        Route("/experimenter", page("experimenter.html")),
        Route("/favicon.ico", no_icon),
        Route("/api/config", handler(config)),
        Route("/api/subject/{subject}", handler(subject_status)),
        Route("/api/subject", handler(register), methods=["POST"]),
        Route("/api/consent", handler(decline), methods=["POST"]),
        Route("/api/calibration", handler(calibrate), methods=["POST"]),
        Route("/api/start", handler(start), methods=["POST"]),
        Route("/api/advance", handler(advance), methods=["POST"]),
        Route("/api/trial", handler(trial), methods=["POST"]),
        Route("/api/practice", handler(session.write_practice), methods=["POST"]),
        Route("/api/live", handler(live), methods=["POST"]),
        Route("/api/experimenter/session", handler(overview)),
        Route("/api/experimenter/exclude", handler(exclude), methods=["POST"]),
        Route("/api/experimenter/refit", handler(refit), methods=["POST"]),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
