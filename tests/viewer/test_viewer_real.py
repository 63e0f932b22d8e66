"""The recordings in the real rerun viewer: ``rerun --headless`` (software Vulkan) driven by
``rerun.experimental.ViewerClient``, as ``../shared/tools/rrd-look`` does.

``rerun rrd verify`` passes on a file that crashes the viewer (a chunk without rows panics its time panel), so
the CLI's demo, replay and real-flight recordings are opened in one viewer process, which must survive each and
show a non-trivial first view. A control recording with two empty chunks proves the harness sees a crash.

Skipped where the software Vulkan driver is missing; ``.ci/run`` installs it, locally run
``apt-get update && apt-get install -y --no-install-recommends mesa-vulkan-drivers libvulkan1``.
"""

from __future__ import annotations

import glob
import io
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rerun as rr

from . import viewer_recordings

recordings = viewer_recordings.load()  # the same recordings test_viewer.py reads, made once per session

RERUN = Path(sys.executable).with_name("rerun")
LAVAPIPE = "/usr/share/vulkan/icd.d/lvp_icd*.json"
INSTALL = "apt-get update && apt-get install -y --no-install-recommends mesa-vulkan-drivers libvulkan1"
pytestmark = [
    pytest.mark.skipif(not glob.glob(LAVAPIPE), reason=f"no software Vulkan driver ({LAVAPIPE}); run: {INSTALL}"),
    pytest.mark.skipif(not RERUN.exists(), reason=f"no rerun viewer beside {sys.executable}"),
]
START_TIMEOUT = 60.0
SETTLE = 2.0  # s after the first screenshot: the viewer has drawn a few frames, the time panel among them


class HeadlessViewer:
    """One ``rerun --headless`` process on 127.0.0.1 and a client driving it; stopped with its process group."""

    def __init__(self, tmp: Path) -> None:
        from rerun.experimental import ViewerClient

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self.log = tmp / "viewer.log"
        env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp)}
        with open(self.log, "w") as out:
            self.proc = subprocess.Popen(
                [str(RERUN), "--headless", "--bind", "127.0.0.1", "--port", str(port), "--hide-welcome-screen",
                 "--window-size", "1280x800"], stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env=env, start_new_session=True)
        end = time.monotonic() + START_TIMEOUT
        while "Headless viewer running" not in self.log.read_text():
            if self.proc.poll() is not None or time.monotonic() > end:
                self.stop()
                pytest.fail(f"the headless viewer did not start:\n{self.log.read_text()[-2000:]}")
            time.sleep(0.2)
        self.client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")

    def crashed(self) -> str | None:
        """The viewer's panic (or exit), if it died."""
        text = self.log.read_text()
        if "panicked" in text:
            return text[text.index("panicked"):][:600]
        if self.proc.poll() is not None:
            return f"the viewer exited with status {self.proc.returncode}: {text[-600:]}"
        return None

    def open(self, path: Path) -> np.ndarray:
        """Open ``path``, wait for it to load and be drawn, and return the screenshot as RGB pixels."""

        opened = self.client.open(str(path))
        end = time.monotonic() + 60
        while self.client.get_state().loading and time.monotonic() < end and not self.crashed():
            time.sleep(0.2)
        assert self.crashed() is None, self.crashed()
        assert self.client.get_state().active_recording in opened.store_ids
        image = self.screenshot()
        time.sleep(SETTLE)
        assert self.crashed() is None, self.crashed()
        return image

    def screenshot(self) -> np.ndarray:
        from PIL import Image

        return np.asarray(Image.open(io.BytesIO(self.client.take_screenshot())).convert("RGB"))

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()


@pytest.fixture(scope="module")
def viewer(tmp_path_factory):
    recordings.cli_recordings()  # made first: a viewer started earlier would only compete for the CPU
    v = HeadlessViewer(tmp_path_factory.mktemp("viewer"))
    yield v
    v.stop()


def _non_trivial(image: np.ndarray) -> tuple[float, int]:
    """Pixel spread and number of distinct colors: a blank or one-color window has neither."""
    return float(image.std()), len(np.unique(image.reshape(-1, 3), axis=0))


@pytest.mark.parametrize("kind", ["demo", "replay", "flight"])
def test_the_viewer_opens_the_recording_and_shows_it(viewer, kind):
    image = viewer.open(recordings.cli_recording(kind))
    spread, n_colors = _non_trivial(image)
    # loaded is not yet drawn: under load the first frame can come before every plot (467 colours once)
    deadline = time.monotonic() + 20
    while not (spread > 10 and n_colors > 500) and time.monotonic() < deadline:
        time.sleep(0.5)
        image = viewer.screenshot()
        spread, n_colors = _non_trivial(image)
    assert image.shape[0] >= 400 and image.shape[1] >= 600
    assert spread > 10 and n_colors > 500, (kind, spread, n_colors)
    # every tab's views exist in the viewer (the blueprint arrived with the recording)
    names = {v.name for v in viewer.client.get_state().views}
    expected = {"demo": "u1 [stick]", "replay": "x [m]", "flight": "x [m]"}[kind]
    assert any(n == expected or n.startswith(f"{expected}:") for n in names), sorted(n for n in names if n)


def test_the_harness_sees_a_viewer_crash(tmp_path):
    """Control: two chunks without rows on one timeline (what the guard prevents) must be reported as a crash."""
    path = tmp_path / "empty_chunks.rrd"
    rec = rr.RecordingStream("workbench_control")
    rec.save(path)
    for entity, values in (("a", []), ("b", []), ("c", [0.0, 1.0])):
        t = np.arange(len(values), dtype=np.float64)
        index = [rr.TimeColumn("time", duration=t)]
        rec.send_columns(entity, indexes=index, columns=rr.Scalars.columns(scalars=values))
    rec.flush()
    rec.disconnect()
    control = HeadlessViewer(tmp_path)
    try:
        control.client.open(str(path))
        end = time.monotonic() + 30
        while control.crashed() is None and time.monotonic() < end:
            time.sleep(0.5)
        assert control.crashed() is not None, "a recording with empty chunks did not crash the viewer"
    finally:
        control.stop()
