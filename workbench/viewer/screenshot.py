"""The README's screenshot, made from the demo's recording by rerun's own viewer: ``make readme-screenshot``.

``python -m workbench.viewer.screenshot out/demo.rrd docs/viewer.png`` starts ``rerun --headless`` on 127.0.0.1
(software Vulkan), opens the recording, waits until it is drawn and saves the first view. Beside the PNG it writes
``docs/viewer.json``: the PNG's digest and the held-out scores text the first view shows (the recording's
``scores`` document), so ``tests/test_readme.py`` can tell a screenshot that no longer shows what the demo prints
(the README once showed 0.0996 where the demo printed 0.111) without opening a viewer.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["first_view_scores", "main", "take"]

START_TIMEOUT = 60.0
SETTLE_S = 15.0  # after loading: every plot drawn on a software rasterizer under load (rrd-look waits 20)


def first_view_scores(rrd: str | os.PathLike) -> str:
    """The held-out scores text of a session recording (its ``scores`` document), as the first view shows it."""
    from rerun.chunk import RrdReader

    from workbench.viewer.entities import SCORES

    for chunk in RrdReader(Path(rrd)).stream():
        if chunk.entity_path.strip("/") == SCORES.strip("/") and chunk.is_static:
            batch = chunk.to_record_batch()
            for name in batch.schema.names:
                if name.endswith("TextDocument:text"):
                    value = batch.column(name).to_pylist()[0]
                    return str(value[0] if isinstance(value, list) else value)
    return ""


def take(rrd: str | os.PathLike, png: str | os.PathLike, *, size: str = "1600x1000") -> Path:
    """Open ``rrd`` in a headless rerun viewer and save its first view to ``png``; a ``.json`` beside it records
    the PNG's digest and :func:`first_view_scores`."""
    from rerun.experimental import ViewerClient

    rerun = Path(sys.executable).with_name("rerun")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    png = Path(png)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "viewer.log"
        with open(log, "w") as out:
            proc = subprocess.Popen([str(rerun), "--headless", "--bind", "127.0.0.1", "--port", str(port),
                                     "--hide-welcome-screen", "--window-size", size], stdout=out,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    env={**os.environ, "XDG_RUNTIME_DIR": tmp}, start_new_session=True)
        try:
            end = time.monotonic() + START_TIMEOUT
            while "Headless viewer running" not in log.read_text():
                if proc.poll() is not None or time.monotonic() > end:
                    raise RuntimeError(f"the headless viewer did not start: {log.read_text()[-600:]}")
                time.sleep(0.2)
            client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
            client.open(str(Path(rrd).resolve()))
            end = time.monotonic() + 60
            while client.get_state().loading and time.monotonic() < end:
                time.sleep(0.2)
            time.sleep(SETTLE_S)
            png.parent.mkdir(parents=True, exist_ok=True)
            client.save_screenshot(str(png))
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(timeout=10)
    record = {"source": "out/demo.rrd (make demo)", "png_sha256": hashlib.sha256(png.read_bytes()).hexdigest(),
              "scores": first_view_scores(rrd)}
    png.with_suffix(".json").write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return png


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m workbench.viewer.screenshot RECORDING.rrd OUT.png", file=sys.stderr)
        return 2
    import glob

    if not glob.glob("/usr/share/vulkan/icd.d/lvp_icd*.json") and not os.environ.get("WORKBENCH_VULKAN"):
        print("screenshot: no software Vulkan driver (apt-get install -y --no-install-recommends "
              "mesa-vulkan-drivers libvulkan1); the README's screenshot is left as it is", file=sys.stderr)
        return 0
    print(f"wrote {take(args[0], args[1])} and {Path(args[1]).with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
