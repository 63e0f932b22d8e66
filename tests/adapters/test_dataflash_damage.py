"""A damaged DataFlash log says it is damaged when its import stops (issue 41, round 9).

DataFlash has no checksum: a flipped byte in a message's payload is read as data, and the import then stopped on
whatever the damaged values made of the flight. Flipping 200 bytes of beastayyg log_0038 stopped it on the stick
check ("u2 reads RCIN.C3 … does not move with CTUN.ThI"); on the writer's logs below, on "the log has no GPS
stream … the estimator dead-reckons" and "the pilot's inputs u1, u2 are not in this log". What the reader can see
of the damage is the bytes inside the log that are no message (a damaged head, length or type id: it resyncs at
the next head), so the stop leads with them: how many bytes, where.
"""

from __future__ import annotations

import numpy as np
import pytest

import adapters
from adapters.formats import dataflash_write
from adapters.mapping import load_mapping
from adapters.pipeline import build
from adapters.summary import VEHICLE_STREAMS
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


@pytest.mark.parametrize(("style", "seed"), [("old", 3), ("new", 3)])
def test_a_byte_flipped_dataflash_log_says_it_is_damaged_where_and_how_many_bytes(tmp_path, style, seed):
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
    # the stop the pipeline makes of the damaged values follows, as what the import stopped on, not as the finding,
    # and keeps its class (a MappingError stays one)
    m = load_mapping("ardupilot_manual").for_format("dataflash")
    with pytest.raises(DataError) as built:
        build(adapters.read(path, [*m.stream_candidates(), *VEHICLE_STREAMS]), m)
    cause = str(built.value).removeprefix(f"{path}: ")
    assert text.endswith(f"so what the import then stopped on may be the damage's): {cause}")
    assert type(err.value) is type(built.value)


def test_a_log_cut_off_mid_message_is_not_called_damaged(tmp_path):
    # power lost while writing: the last message is cut off by the end of the file, every byte before is a message
    intact = dataflash_write.write_example(tmp_path / "new.bin", "new", "copter", seconds=60.0, seed=5)
    data = intact.read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[: len(data) - 7])
    streams = adapters.read(cut)
    assert streams.skipped.get("truncated messages") == 1 and "damaged_regions" not in streams.info
    assert len(adapters.load(cut, "ardupilot_manual")) == len(adapters.load(intact, "ardupilot_manual"))


def _mode_message_in(data: bytes, streams, t_lo: float, t_hi: float, mode_num: int) -> tuple[bytes, float]:
    """``data`` with one message inside ``[t_lo, t_hi]`` whose type is longer than MODE turned into a MODE (its type
    id damaged): a shorter message with the original's TimeUS, saying ``mode_num``, then the rest of the original,
    bytes that are no message. Returns the damaged bytes and the MODE's log time."""
    from adapters.formats.dataflash import HEAD1, HEAD2

    formats = streams.info["formats"]
    mode = formats["MODE"]
    assert mode["format"].startswith("QMB")  # TimeUS, Mode, ModeNum: the fields the damaged message sets
    longer = {f["type"]: f for f in formats.values() if f["length"] > mode["length"] and f["format"].startswith("Q")}
    buf = np.frombuffer(data, np.uint8)
    heads = np.flatnonzero((buf[:-2] == HEAD1) & (buf[1:-1] == HEAD2))
    for at in heads.tolist():
        f = longer.get(int(buf[at + 2]))
        if f is None:
            continue
        t = int.from_bytes(data[at + 3:at + 11], "little") * 1e-6
        if t_lo < t < t_hi:
            out = bytearray(data)
            out[at + 2] = mode["type"]
            out[at + 11] = out[at + 12] = mode_num
            return bytes(out), t
    raise AssertionError("no message of a longer type in the window")


def test_a_damaged_dataflash_import_that_succeeds_says_so_and_a_mode_read_next_to_the_damage_starts_no_segment(
        tmp_path):
    # beastayyg log 0039 with 200 bytes flipped (seed 1): a 27-byte message's type id read as MODE (14 bytes,
    # ModeNum 0) filed 27 s of ALT_HOLD as STABILIZE, and the import said nothing of the damage
    from adapters.modes import mode_number
    from adapters.streams import damaged_regions

    intact = dataflash_write.write_example(tmp_path / "new.bin", "new", "copter", seconds=60.0, seed=5)
    good = adapters.load(intact, "ardupilot_manual")
    assert not any("damaged" in d.meta for d in good)
    assert not adapters.read(intact).info.get("next_to_damage")
    held = [d for d in good if d.meta["mode"] != "STABILIZE"][0]  # a kept mode the phantom MODE is not
    t0 = held.meta["t0"]
    stabilize = mode_number("arducopter", "STABILIZE")
    data, t_phantom = _mode_message_in(intact.read_bytes(), adapters.read(intact), t0 + float(held.t[-1]) / 2 - 1.0,
                                       t0 + float(held.t[-1]) / 2 + 1.0, stabilize)
    path = tmp_path / "damaged.bin"
    path.write_bytes(data)
    streams = adapters.read(path)
    assert streams.info["damaged_regions"]
    ds = adapters.load(path, "ardupilot_manual")
    # every demonstration says the file is damaged, where, and which value it did not trust
    for d in ds:
        note = d.meta["damaged"]
        assert note.startswith(f"{path}: damaged log, {damaged_regions(streams)} (")
        assert f"MODE.ModeNum {stabilize} (STABILIZE) at log time {t_phantom:.1f} s" in note
    # no time filed under a mode the intact log does not say: each demonstration lies inside one of the intact
    # log's of the same mode; the held mode ends where the phantom was read
    spans = {(d.meta["mode"], d.meta["t0"], d.meta["t0"] + float(d.t[-1])) for d in good}
    for d in ds:
        a, b = d.meta["t0"], d.meta["t0"] + float(d.t[-1])
        assert any(mode == d.meta["mode"] and lo - 1e-9 <= a and b <= hi + 1e-9 for mode, lo, hi in spans), \
            (d.meta["mode"], a, b)
    ends = [d.meta["t0"] + float(d.t[-1]) for d in ds if d.meta["mode"] == held.meta["mode"]]
    assert any(t_phantom - 2 * good.dt <= e <= t_phantom for e in ends), (ends, t_phantom)
    # `inspect` lists the runs (an intact log none)
    from adapters.summary import DAMAGED_RUNS_SHOWN

    assert f"damaged: {damaged_regions(streams, shown=DAMAGED_RUNS_SHOWN)}" in str(adapters.inspect(path)).splitlines()
    assert not adapters.inspect(intact).damaged
