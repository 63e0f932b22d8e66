"""MCAP read speed: ``adapters.mcap.read`` vs the ``mcap`` library's own ``iter_decoded_messages`` loop.

Both read the same generated file (the sample-log layout: JSON channels with JSON Schemas, zstd chunks) in the
same run. The library loop only decodes (``json.loads`` per message through our JSON decoder factory, as a
user of the library would write it); ours also flattens every field into columns and sorts by log time.
Target: ours ≤ 1.3× the library loop's time.

Usage: ``python bench/bench_mcap.py [n_messages]`` prints a Markdown table.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness import best_time, markdown_table  # noqa: E402

from adapters import mcap  # noqa: E402

N_MESSAGES = 200_000
REPEATS = 3


def _generate(path: Path, n: int) -> Path:
    """Half the messages on a 6-field nested state topic, half on a 2-element stick array topic."""
    rng = np.random.default_rng(0)
    k = n // 2
    t = 1_704_067_200.0 + 0.05 * np.arange(k)
    state = pd.DataFrame({"t": t, "demo": np.arange(k) // 200})
    for group in ("pose", "twist"):
        for axis in ("x", "y", "phi"):
            state[f"{group}.{axis}"] = rng.standard_normal(k)
    sticks = pd.DataFrame({"t": t, "sticks[0]": rng.uniform(-1, 1, k), "sticks[1]": rng.uniform(-1, 1, k)})
    return mcap.write(path, {"/quadrotor/state": state, "/quadrotor/input": sticks})


def _library_loop(path: Path) -> int:
    from mcap.reader import make_reader

    count = 0
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap.JsonDecoderFactory()])
        for _schema, _channel, _message, _decoded in reader.iter_decoded_messages():
            count += 1
    return count


def run(n_messages: int = N_MESSAGES) -> list[dict]:
    with tempfile.TemporaryDirectory() as tmp:
        path = _generate(Path(tmp) / "bench.mcap", n_messages)
        size = path.stat().st_size
        n = sum(len(f) for f in mcap.read(path).frames.values())
        assert n == _library_loop(path) == n_messages
        ours = best_time(lambda: mcap.read(path), REPEATS, collect=True)
        theirs = best_time(lambda: _library_loop(path), REPEATS, collect=True)
        one_topic = best_time(lambda: mcap.read(path, topics=["/quadrotor/input"]), REPEATS, collect=True)
    return [
        {
            "benchmark": "MCAP read (JSON channels, zstd)",
            "messages": n_messages,
            "file MB": size / 1e6,
            "ours s": ours,
            "mcap iter_decoded_messages s": theirs,
            "ratio ours/mcap": ours / theirs,
            "target": "<= 1.3",
            "ours msg/s": n_messages / ours,
        },
        {
            "benchmark": "MCAP read, one of two topics (index)",
            "messages": n_messages // 2,
            "file MB": size / 1e6,
            "ours s": one_topic,
            "mcap iter_decoded_messages s": theirs,
            "ratio ours/mcap": one_topic / theirs,
            "target": "",
            "ours msg/s": (n_messages // 2) / one_topic,
        },
    ]


if __name__ == "__main__":
    print(markdown_table(run(int(sys.argv[1]) if len(sys.argv) > 1 else N_MESSAGES)))
