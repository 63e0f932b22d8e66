"""Live prediction benchmarks: per-step compute and message-to-prediction latency, in process and over loopback UDP.

1. **in process** — every frame of ``sample_logs/landing_s00.tlog`` fed to
:class:`workbench.live.predictor.OnlinePredictor`
   as fast as possible (a CS1 model, 1 s rollouts): per-step compute (aligning the step + the one-step GMR, ŵ and
   the rollout), p50 / p99, and the rerun logging cost per step (:class:`workbench.viewer.live.LiveLogger`, batched).
2. **loopback UDP at 20 Hz** — a separate process sends the tlog's raw frames at real time
   (:func:`adapters.link.mavlink.send_tlog`, ``udpout:127.0.0.1``) and this process receives them
   (``udpin:127.0.0.1``) into the predictor: per-step compute and *message-to-prediction* latency, from the moment
   the sender wrote the frame that completed a step to the moment its prediction was ready (both read from the
   system-wide monotonic clock), p50 / p99. Target: p99 < 5 ms per step.

``python bench/bench_live.py [seconds]`` prints the rows; ``bench/run_all.py`` collects them into
``bench/results.md``.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from harness import markdown_table  # noqa: E402

import adapters  # noqa: E402
from adapters.link.mavlink import open_link, tlog_frames  # noqa: E402
from workbench.live.predictor import OnlinePredictor  # noqa: E402
from workbench.models import HumanBehaviorModel  # noqa: E402
from workbench.plant.system import planar_quadrotor  # noqa: E402
from workbench.viewer.scene import plane_of  # noqa: E402

TLOG = ROOT / "sample_logs" / "landing_s00.tlog"
HORIZON = 1.0

_SENDER = """
import sys, time, numpy as np
from adapters.link.mavlink import send_tlog
stamps = []
n_max = int(sys.argv[3])
send_tlog(sys.argv[1], sys.argv[2], speed=1.0, on_frame=lambda n, t: stamps.append(time.perf_counter()),
          should_stop=lambda: len(stamps) >= n_max)
np.save(sys.argv[4], np.array(stamps))
"""


def _model() -> HumanBehaviorModel:
    ds = adapters.load(TLOG, mapping="planar_quadrotor")
    return HumanBehaviorModel(planar_quadrotor(), n_components=5).fit(ds.by_label("CS1"))


def _pct(a: list[float]) -> tuple[float, float]:
    p50, p99 = np.percentile(np.asarray(a) * 1e3, [50, 99])
    return float(p50), float(p99)


def in_process(model: HumanBehaviorModel) -> list[dict]:
    from workbench import viewer
    from workbench.viewer.live import LiveLogger

    frames = list(tlog_frames(TLOG))
    pr = OnlinePredictor(model, "planar_quadrotor", horizon_s=HORIZON, now=time.perf_counter)
    preds = []
    t0 = time.perf_counter()
    for _, frame in frames:
        pr.feed(frame)
        preds += pr.pop()
    wall = time.perf_counter() - t0
    c50, c99 = _pct([p.compute_seconds for p in preds])
    rows = [{
        "benchmark": "in process: every frame of landing_s00.tlog (align + one-step GMR + ŵ + 1 s rollout)",
        "steps": len(preds), "frames": len(frames), "p50 ms": c50, "p99 ms": c99,
        "steps/s": len(preds) / wall, "target": "p99 < 5 ms",
    }]
    with tempfile.TemporaryDirectory() as tmp:
        rec = viewer.new_recording("bench_live")
        rec.save(Path(tmp) / "live.rrd")
        plane = plane_of(pr.mapping.roles, pr.mapping.state_names)
        logger = LiveLogger(rec, pr.mapping.state_names, pr.mapping.input_names,
                            plane=None if plane is None else (plane.across, plane.up, plane.heading))
        costs = []
        for i, p in enumerate(preds):
            a = time.perf_counter()
            logger.log(p)
            if i % 5 == 4:  # `workbench live` flushes every 0.25 s: every 5 steps at 20 Hz
                logger.flush()
            costs.append(time.perf_counter() - a)
        logger.flush()
        rec.flush()
        rec.disconnect()
    l50, l99 = _pct(costs)
    rows.append({
        "benchmark": "in process: rerun logging per step (LiveLogger, a batch every 5 steps = 0.25 s at 20 Hz)",
        "steps": len(costs), "p50 ms": l50, "p99 ms": l99, "mean ms": 1e3 * float(np.mean(costs)),
    })
    return rows


def loopback(model: HumanBehaviorModel, seconds: float) -> dict:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    frames_per_s = 4.4 * 20  # the sample log's ~4.4 frames per 20 Hz step
    n_frames = int(seconds * frames_per_s)
    pr = OnlinePredictor(model, "planar_quadrotor", horizon_s=HORIZON, now=time.perf_counter)
    compute, latency, received = [], [], 0
    completing: list[int] = []
    with tempfile.TemporaryDirectory() as tmp, open_link(f"udpin:127.0.0.1:{port}") as link:
        stamps = Path(tmp) / "sent.npy"
        sender = subprocess.Popen([sys.executable, "-c", _SENDER, str(TLOG), f"udpout:127.0.0.1:{port}",
                                   str(n_frames), str(stamps)], cwd=ROOT)
        deadline = time.monotonic() + seconds + 30
        while sender.poll() is None and time.monotonic() < deadline:
            if not link.wait(0.05):
                continue
            for data in link.read():
                received += 1
                if pr.feed(data, datagram=True):
                    for p in pr.pop():
                        compute.append(p.compute_seconds)
                        completing.append(received - 1)
                        latency.append(p.computed)
        sender.wait(timeout=30)
        sent = np.load(stamps)
    # a frame's index on both sides is its order: loopback UDP keeps it and loses none at this rate
    lost = len(sent) - received
    lat = [done - sent[i] for done, i in zip(latency, completing, strict=True) if i < len(sent)]
    c50, c99 = _pct(compute)
    l50, l99 = _pct(lat)
    return {
        "benchmark": f"loopback UDP at real time (20 Hz steps, {seconds:g} s): compute per step",
        "steps": len(compute), "frames": received, "lost": lost, "p50 ms": c50, "p99 ms": c99,
        "latency p50 ms": l50, "latency p99 ms": l99, "target": "p99 < 5 ms",
    }


def run(seconds: float = 20.0) -> list[dict]:
    model = _model()
    rows = [*in_process(model), loopback(model, seconds)]
    # a p99 on a shared machine is mostly other processes' time slices: say how busy it was
    load = os.getloadavg()[0] / (os.cpu_count() or 1)
    return [{**r, "load per core": load} for r in rows]


if __name__ == "__main__":
    print(markdown_table(run(float(sys.argv[1]) if len(sys.argv) > 1 else 20.0)))
