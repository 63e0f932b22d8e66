"""``--scheduler`` pointed at something that is not a Dask scheduler: one clear line within ~10 s, never a hang
or a MemoryError. Local servers on 127.0.0.1 only."""

from __future__ import annotations

import http.server
import os
import socket
import subprocess
import sys
import threading
import time

import pytest

from workbench.errors import WorkbenchError
from workbench.study.handshake import check_scheduler

from ..forgeries import serve


def test_a_real_scheduler_passes():
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cluster:
        check_scheduler(cluster.scheduler_address, timeout=5)


def test_random_bytes_are_not_a_scheduler():
    srv, address = serve(lambda conn: conn.sendall(os.urandom(4096)))
    with srv, pytest.raises(WorkbenchError, match="not a Dask scheduler"):
        check_scheduler(address, timeout=5)


def test_a_plausible_length_then_garbage_is_not_a_scheduler():
    srv, address = serve(lambda conn: conn.sendall((100).to_bytes(8, "little") + os.urandom(100)))
    with srv, pytest.raises(WorkbenchError, match="not a Dask handshake"):
        check_scheduler(address, timeout=5)


def test_an_http_server_is_refused_within_the_time_limit():
    httpd = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    start = time.monotonic()
    try:
        with pytest.raises(WorkbenchError, match="no handshake within 1 s"):
            check_scheduler(f"tcp://127.0.0.1:{httpd.server_address[1]}", timeout=1)
    finally:
        httpd.shutdown()
    assert time.monotonic() - start < 3


def test_nothing_listening_is_one_line():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(WorkbenchError, match="cannot reach"):
        check_scheduler(f"127.0.0.1:{port}", timeout=2)


@pytest.mark.slow
def test_the_cli_answers_an_http_server_in_one_line_within_the_limit(tmp_path):
    httpd = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        start = time.monotonic()
        out = subprocess.run([sys.executable, "-m", "workbench", "import", "sample_logs/landing_s00.tlog", "-o",
                              str(tmp_path / "ds/"), "--scheduler", f"tcp://127.0.0.1:{httpd.server_address[1]}"],
                             capture_output=True, text=True, timeout=60,
                             cwd=os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
        took = time.monotonic() - start
    finally:
        httpd.shutdown()
    assert out.returncode == 1 and len(out.stderr.strip().splitlines()) == 1 and "not a Dask scheduler" in out.stderr
    assert took < 20


@pytest.mark.parametrize("scheme", ["tls", "ucx", "ws", "wss"])
def test_schemes_other_than_tcp_are_refused_by_name(scheme):
    from workbench.study.executor import DaskExecutor

    with pytest.raises(WorkbenchError, match=f"tcp://HOST:PORT only, not {scheme}://"):
        DaskExecutor(scheduler=f"{scheme}://127.0.0.1:8786", timeout=2)  # previous main: TypeError, WebSocketError


def test_a_scheduler_without_workers_is_waited_for_then_an_error():
    from dask.distributed import LocalCluster

    from workbench.study.executor import DaskExecutor

    with LocalCluster(n_workers=0, processes=False, protocol="tcp://", dashboard_address=":0") as cluster:
        start = time.monotonic()
        with pytest.raises(WorkbenchError, match=r"has no worker \(waited 1 s\)"):
            DaskExecutor(scheduler=cluster.scheduler_address, timeout=5, worker_wait=1.0)
        assert time.monotonic() - start < 15


def test_an_address_with_an_unclosed_ipv6_bracket_is_a_workbench_error():
    with pytest.raises(WorkbenchError, match="not a scheduler address"):
        check_scheduler("tcp://[::1", timeout=1)  # urllib's ValueError before
