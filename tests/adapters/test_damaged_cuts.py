"""A damaged log whose lost data (or garbled segmentation values) cut one flight into several demonstrations says
so in one line naming the file and every cut, rather than splitting silently (a PX4 ULog with 200 random bytes
flipped imported as 4 demonstrations where the intact log gives 1, with only "skipped corrupt regions: 1")."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.formats import ulog

N_FLIPPED = 200


def _flight(tmp_path):
    """One 60 s flight in the workbench's ULog layout (one trial marker throughout): imports as one demonstration."""
    n = 1200
    k = np.arange(n)
    t = 1.0 + 0.05 * k
    state = pd.DataFrame({"t": t, "demo": np.zeros(n, dtype=np.int32), "x": np.sin(0.01 * k),
                          "y": 1 + np.cos(0.013 * k), "phi": 0.1 * np.sin(0.05 * k), "xdot": np.cos(0.01 * k),
                          "ydot": np.sin(0.02 * k), "phidot": np.cos(0.05 * k)})
    sticks = pd.DataFrame({"t": t, "u1": np.sin(0.07 * k), "u2": np.cos(0.03 * k)})
    return ulog.write(tmp_path / "flight.ulg", {"planar_state": state, "planar_input": sticks})


def _damaged(path, seed):
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(seed)
    first_data = data.index(b"planar_input") + 64  # past the definitions: the damage is in the flight's messages
    for at in rng.choice(np.arange(first_data, len(data)), N_FLIPPED, replace=False):
        data[at] ^= int(rng.integers(1, 256))
    out = path.with_name(f"damaged_{seed}.ulg")
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("seed", [0, 1, 4])  # 1 and 4: a silence of every channel; 0 and 1: a garbled marker
def test_a_damaged_flight_cut_into_pieces_names_the_file_and_every_cut(tmp_path, seed):
    intact = _flight(tmp_path)
    whole = adapters.load(intact, "planar_quadrotor")
    assert len(whole) == 1 and "damaged" not in whole[0].meta
    path = _damaged(intact, seed)
    ds = adapters.load(path, "planar_quadrotor")
    assert len(ds) > 1  # what the damage did: pieces of the one flight
    note = ds[0].meta["damaged"]
    assert all(d.meta["damaged"] == note for d in ds) and "\n" not in note
    assert note.startswith(f"{path}: damaged file, the ulog reader skipped damaged data")
    assert f"{len(ds)} demonstrations in all" in note
    # every cut is named at the end of the piece before it, in seconds since the log's first mapped sample
    ends = [d.meta["t_start"] + d.t[-1] for d in ds[:-1]]
    listed = [float(x) for x in re.findall(r"(?:at |\), )(\d+\.\d) s \(", note)]
    assert listed == pytest.approx(ends, abs=0.05 + 1e-9)  # printed to 0.1 s


def test_two_segments_of_one_trial_marker_one_of_them_cut_get_distinct_ids(tmp_path):
    # seed 5: the trial marker reads otherwise for a while, so marker 0 makes two segments, the second cut in two;
    # the ids were x-0.1 (a segment repeated) and x-0.1 (a piece numbered), and import stopped at "id is not unique"
    ds = adapters.load(_damaged(_flight(tmp_path), 5), "planar_quadrotor")
    assert len(set(ds.ids)) == len(ds) > 2
    assert list(ds.ids) == [f"damaged_5-0.{k + 1}" for k in range(len(ds))]  # numbered in time order
    assert [d.meta["t0"] for d in ds] == sorted(d.meta["t0"] for d in ds)
