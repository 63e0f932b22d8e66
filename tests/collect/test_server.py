"""The server over HTTP: bad input is a 400 whose ``error`` is one line, never a 500 with a traceback; it listens
on 127.0.0.1 unless told otherwise."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import pytest

from workbench.cli.parser import build_parser
from workbench.collect.server import Server, make_app
from workbench.collect.session import Session

from .conftest import join
from .test_session import _protocol


@pytest.fixture
def url(tmp_path):
    session = Session(tmp_path / "out", _protocol(tmp_path))
    join(session, "s01", {})
    server = Server(make_app(session), port=0).start()
    yield server.url.rstrip("/")
    server.stop()


def test_a_client_that_connects_before_the_server_runs_waits_and_is_served(tmp_path):
    """`workbench collect` prints the URL (and opens a browser on it) before it runs the server: a connection made
    then is queued and answered once it runs, not refused (it was refused: bound, not listening)."""
    import socket
    import threading

    server = Server(make_app(Session(tmp_path / "out", _protocol(tmp_path))), port=0)
    runner = threading.Thread(target=server.run, daemon=True)
    try:
        early = socket.create_connection((server.host, server.port), timeout=10)  # refused before the fix
        early.sendall(f"GET /api/config HTTP/1.1\r\nHost: {server.host}:{server.port}\r\n"
                      "Connection: close\r\n\r\n".encode())
        runner.start()
        with early.makefile("rb") as reply:
            assert reply.readline().split()[1] == b"200"
        early.close()
    finally:
        server.server.should_exit = True  # uvicorn's own end, then the socket closed
        if runner.is_alive():
            runner.join(timeout=10)
        server.stop()


def _post(url: str, body: bytes) -> tuple[int, dict]:
    request = urllib.request.Request(url, data=body, method="POST", headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        text = e.read()
        return e.code, json.loads(text) if e.code == 400 else {"error": text.decode(errors="replace")}


def _trial(**change) -> bytes:
    payload = {"subject": "s01", "slot": 0, "u": [[0.0, 0.0]] * 3, "x": [[0.0] * 6] * 3, "raw": [[0.0, 0.0]] * 3,
               "outcome": "crashed"}
    return json.dumps({**payload, **change}).encode()


@pytest.mark.parametrize("path, body, message", [
    ("/api/subject", b"{bad", "not JSON"),
    ("/api/trial", b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
    ("/api/trial", _trial(u=[["0.5", "0"]] * 3), "u: not a list of number lists"),
    ("/api/trial", _trial(raw=[[True, False]] * 3), "raw: not a list of number lists"),
    ("/api/practice", _trial(x0=["a"] * 6), "practice: x0"),
    ("/api/practice", _trial(x0=[1e400] * 6), "not JSON of finite numbers"),
])
def test_bad_input_is_a_400_of_one_line(url, path, body, message):
    status, answer = _post(url + path, body)
    assert status == 400, answer
    assert message in answer["error"] and "\n" not in answer["error"]


def test_the_server_listens_on_127_0_0_1_by_default(tmp_path):
    args = build_parser().parse_args(["collect", "--protocol", "paper_single_subject", "--out", str(tmp_path)])
    assert args.host == "127.0.0.1"
    server = Server(make_app(Session(tmp_path / "out", _protocol(tmp_path))), port=0)
    try:
        assert server.sock.getsockname()[0] == "127.0.0.1" and server.url.startswith("http://127.0.0.1:")
    finally:
        server.sock.close()


@pytest.mark.parametrize("option, value, message", [("--port", "70000", "a port is 0 to 65535"),
                                                    ("--max-pause", "nan", "must be 0 or more seconds"),
                                                    ("--max-pause", "-5", "must be 0 or more seconds")])
def test_a_bad_option_is_refused_before_anything_is_written(tmp_path, capsys, option, value, message):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["collect", "--protocol", "paper_single_subject", "--out", str(tmp_path / "s"),
                                   f"{option}={value}"])
    assert message in capsys.readouterr().err and not (tmp_path / "s").exists()
