"""A damaged DataFlash log says it is damaged when its import stops (issue 41, round 9).

DataFlash has no checksum: a flipped byte in a message's payload is read as data, and the import then stopped on
whatever the damaged values made of the flight. Flipping 200 bytes of beastayyg log_0038 stopped it on the stick
check ("u2 reads RCIN.C3 … does not move with CTUN.ThI"); on the writer's logs below, on "the log has no GPS
stream … the estimator dead-reckons" and "the pilot's inputs u1, u2 are not in this log". What the reader can see
of the damage is the bytes inside the log that are no message (a damaged head, length or type id: it resyncs at
the next head), so the stop leads with them: how many bytes, where.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import adapters
from adapters.formats import dataflash_write
from workbench.errors import DataError

N_FLIPPED = 200
MAX_MESSAGE = 255  # bytes: a DataFlash message's length is one byte


def _flipped(path, seed: int):
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(seed)
    at = rng.choice(np.arange(len(data)), N_FLIPPED, replace=False)
    for k in at:
        data[k] ^= int(rng.integers(1, 256))
    out = path.with_name(f"{path.stem}_flipped_{seed}.bin")
    out.write_bytes(bytes(data))
    return out, np.sort(at)


@pytest.mark.parametrize(
    ("style", "seed", "stop"),
    [
        ("old", 3, "the log has no GPS stream"),  # a damaged GPS FMT: "dead-reckons"
        ("new", 3, "the pilot's inputs u1, u2 are not in this log"),  # RCIN's FMT name read "RC}N"
    ],
)
def test_a_byte_flipped_dataflash_log_says_it_is_damaged_where_and_how_many_bytes(tmp_path, style, seed, stop):
    intact = dataflash_write.write_example(tmp_path / f"{style}.bin", style, "copter", seconds=60.0, seed=5)
    assert len(adapters.load(intact, "ardupilot_manual")) >= 1
    assert "damaged_regions" not in adapters.read(intact).info  # an intact log has no byte outside a message
    path, flipped = _flipped(intact, seed)
    streams = adapters.read(path)
    regions = streams.info["damaged_regions"]
    # no run before the message that holds the first flipped byte (the intact bytes before it are all messages);
    # later runs need not be near a flip: a damaged FMT makes every message of its type a run
    assert regions[0][0] >= flipped[0] - MAX_MESSAGE
    total = sum(size for _, size, _ in regions)
    assert total == streams.skipped["bytes"]  # the file ends on a whole message: no run is its tail
    with pytest.raises(DataError) as err:
        adapters.load(path, "ardupilot_manual")
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith(
        f"{path}: damaged log, {total} bytes in {len(regions)} runs that are no dataflash "
        f"message, at byte {regions[0][0]} ("
    )
    # the stop it made of the damaged values follows, as what the import stopped on, not as the finding
    assert re.search(
        rf"so what the import then stopped on may be the damage's\): mapping 'ardupilot_manual': "
        rf".*{re.escape(stop)}",
        text,
    )


def test_a_log_cut_off_mid_message_is_not_called_damaged(tmp_path):
    # power lost while writing: the last message is cut off by the end of the file, every byte before is a message
    intact = dataflash_write.write_example(tmp_path / "new.bin", "new", "copter", seconds=60.0, seed=5)
    data = intact.read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[: len(data) - 7])
    streams = adapters.read(cut)
    assert streams.skipped.get("truncated messages") == 1 and "damaged_regions" not in streams.info
    assert len(adapters.load(cut, "ardupilot_manual")) == len(adapters.load(intact, "ardupilot_manual"))
