"""Where a recording goes: an ``.rrd`` file (atomically), a native viewer (``spawn``) or a local web viewer.

The native viewer is started here rather than by ``RecordingStream.spawn``: that looks for ``rerun`` on ``PATH``
only (the venv's own viewer beside ``sys.executable`` is missed when the venv is not activated) and, on a
machine without a display, the viewer dies while the SDK keeps waiting for it. Here a missing display or a
viewer that exits at start is one clear :class:`~workbench.errors.WorkbenchError`, never a hang.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from workbench import interrupts
from workbench.atomic import atomic_path, deferred_interrupt
from workbench.errors import UsageError, WorkbenchError

__all__ = ["has_display", "open_output", "rerun_executable"]

SPAWN_TIMEOUT = 20.0  # s for a native viewer to listen; a software-rendered one on a busy machine needs ~5
SPAWN_GRACE = 2.0  # s a viewer must outlive its listening socket: it listens first, then fails to open a window
FLUSH_TIMEOUT = 60.0  # s: a viewer that went away must not keep ``workbench`` waiting forever


def has_display() -> bool:
    """Whether a native viewer could open a window here."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def rerun_executable() -> list[str]:
    """The ``rerun`` viewer: the one beside this Python (an unactivated venv), else on ``PATH``, else the module."""
    exe = Path(sys.executable).with_name("rerun")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun"]


def _listening(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _spawn_viewer(port: int, timeout: float = SPAWN_TIMEOUT) -> None:
    """Start a native viewer listening on ``port`` (or reuse one already there); raise if it cannot show."""
    if _listening(port):
        return
    if not has_display():
        raise WorkbenchError(
            "--spawn needs a display (DISPLAY and WAYLAND_DISPLAY are unset): use --save FILE.rrd and open it "
            "elsewhere, or --serve for a web viewer"
        )
    log = tempfile.TemporaryFile()
    cmd = [*rerun_executable(), "--bind", "127.0.0.1", "--port", str(port), "--memory-limit", "75%"]
    try:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
    except OSError as exc:
        raise WorkbenchError(f"could not start the rerun viewer {cmd[0]}: {exc.strerror or exc}") from None
    end, up_since = time.monotonic() + timeout, None
    while time.monotonic() < end:
        if proc.poll() is not None:
            log.seek(0)
            lines = [ln for ln in log.read().decode(errors="replace").splitlines() if ln.strip()]
            # the viewer's last line ends with the cause ("…: Failed to open connection to X server")
            cause = lines[-1].rsplit(": ", 1)[-1].strip() if lines else f"exit status {proc.returncode}"
            raise WorkbenchError(f"the rerun viewer could not open a window ({cause}); use --save FILE.rrd or --serve")
        if up_since is None and _listening(port):
            up_since = time.monotonic()
        if up_since is not None and time.monotonic() - up_since >= SPAWN_GRACE:
            return
        time.sleep(0.1)
    proc.terminate()
    raise WorkbenchError(f"the rerun viewer did not start within {timeout:g} s; use --save FILE.rrd or --serve")


class open_output:
    """Attach the chosen output to a recording: ``save`` (an .rrd, atomically), ``spawn`` or ``serve``.

    Use as a context manager around the logging; on exit the blueprint (if any) is sent, the stream flushed,
    and a saved file moved into place. ``spawn`` starts (or reuses) a native viewer on ``spawn_port``; ``serve``
    hosts a web viewer and gRPC proxy on 127.0.0.1 only (the rerun SDK's own server binds every interface) and
    keeps serving until interrupted.
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        *,
        save: str | os.PathLike | None = None,
        spawn: bool = False,
        serve: bool = False,
        web_port: int = 9090,
        grpc_port: int = 9876,
        spawn_port: int = 9876,
    ) -> None:
        if sum((save is not None, spawn, serve)) != 1:
            raise UsageError("choose exactly one output: --save FILE.rrd, --spawn or --serve")
        self.rec = rec
        self.save = None if save is None else Path(save)
        self.spawn = spawn
        self.serve = serve
        self.web_port = web_port
        self.grpc_port = grpc_port
        self.spawn_port = spawn_port
        self.blueprint: rrb.Blueprint | None = None
        self._atomic: atomic_path | None = None
        self._server: subprocess.Popen | None = None

    def __enter__(self) -> open_output:
        if self.save is not None:
            self._atomic = atomic_path(self.save)
            tmp = self._atomic.__enter__()
            try:
                self.rec.save(tmp)
            except BaseException as exc:  # Ctrl-C here skips __exit__: the temp file would stay behind
                self._atomic.__exit__(type(exc), exc, exc.__traceback__)
                raise
        elif self.spawn:
            _spawn_viewer(self.spawn_port)
            self.rec.connect_grpc(f"rerun+http://127.0.0.1:{self.spawn_port}/proxy")
        else:
            self._server = _start_local_server(self.grpc_port, self.web_port)
            self.rec.connect_grpc(f"rerun+http://127.0.0.1:{self.grpc_port}/proxy")
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        failed = exc_type is not None
        try:
            # A file's flush is short: Ctrl-C is held back until it ends (a KeyboardInterrupt raised between the
            # SDK's calls while its writer threads still run is how the interpreter once aborted), then raised
            # before the file is renamed into place, so an interrupted run leaves no recording behind.
            with deferred_interrupt() if self.save is not None else contextlib.nullcontext():
                if not failed and self.blueprint is not None:
                    self.rec.send_blueprint(self.blueprint, make_active=True, make_default=True)
                try:
                    self.rec.flush(timeout_sec=FLUSH_TIMEOUT)
                except RuntimeError as err:  # the SDK's own words for a viewer that went away: "connection severed"
                    if self.save is not None:
                        # "File-writer thread shut down prematurely": its thread failed to write (a full disk)
                        raise WorkbenchError(f"{self.save}: the recording could not be written ({_free(self.save)}; "
                                             "rerun's file writer stopped); nothing was saved") from None
                    raise WorkbenchError(f"the rerun viewer went away while receiving the recording ({err})") from None
                if self.save is not None:
                    self.rec.disconnect()
        except BaseException:
            failed = True
            raise
        finally:
            if self._atomic is not None:
                # the recording goes into place only when everything before succeeded, never after an interrupt
                self._atomic.__exit__(KeyboardInterrupt if failed and exc_type is None else exc_type, exc, tb)

    @property
    def url(self) -> str:
        """For ``serve``: the web viewer's address, connected to the local gRPC proxy."""
        from urllib.parse import quote

        proxy = quote(f"rerun+http://127.0.0.1:{self.grpc_port}/proxy", safe="")
        return f"http://127.0.0.1:{self.web_port}?url={proxy}"

    def wait(self) -> None:
        """For ``serve``: keep the local server up until Ctrl-C (or SIGTERM), then stop it."""
        if self._server is None:
            return
        _wait_then_stop(self._server)


def _free(path: Path) -> str:
    """The free space where ``path`` goes, in words: the likely cause of a writer thread that stopped."""
    try:
        free = shutil.disk_usage(path.parent if str(path.parent) else ".").free
    except OSError:
        return "the folder cannot be read"
    return "the disk is full" if free < (1 << 20) else f"{free / 2**20:.0f} MiB free there"


def _wait_then_stop(proc: subprocess.Popen) -> None:
    import signal

    def _interrupt(signum, frame):  # a SIGTERM must stop the server too, not orphan it
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        proc.wait()
    except KeyboardInterrupt:
        interrupts.clear()  # Ctrl-C is how the user closes the served viewer: the command ends normally
    finally:
        signal.signal(signal.SIGTERM, previous)
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()


def _start_local_server(grpc_port: int, web_port: int) -> subprocess.Popen:
    """A rerun gRPC proxy with a web viewer, bound to 127.0.0.1 (never every interface)."""
    cmd = [*rerun_executable(), "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc_port),
           "--web-viewer-port", str(web_port)]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL)
