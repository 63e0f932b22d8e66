"""Arming from a DataFlash log's EV events (ARMED 10, DISARMED 11): disarmed spans are not imported, a log that
declares EV but never armed is refused as never armed, and a log that declares no EV (old ArduPlane) records no
arming, so nothing is dropped on its account.

Before, the DataFlash mappings had ``armed = false``: a never-armed log was refused on its modes, or imported.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.formats import dataflash_write
from workbench.errors import DataError


def _log(tmp_path, name, events=None, seconds=40.0, drop_ev=False):
    """The example ArduCopter 3.2-era log with its EV events replaced by ``events`` [(time from the start, id)]."""
    streams, options = dataflash_write.example_streams("old", "copter", seconds=seconds, seed=3)
    t0 = float(streams["ATT"]["t"].iloc[0])
    if drop_ev:
        del streams["EV"]
    elif events is not None:
        streams["EV"] = pd.DataFrame({"t": [t0 + a for a, _ in events], "Id": np.array([i for _, i in events],
                                                                                      np.uint8)})
    return dataflash_write.write(tmp_path / name, streams, **options), t0


def test_disarmed_spans_are_not_imported(tmp_path):
    events = [(1.0, 10), (2.0, 15), (14.0, 11), (18.0, 10), (38.0, 11)]
    path, t0 = _log(tmp_path, "armed.bin", events)
    armed = [(t0 + 1.0, t0 + 14.0), (t0 + 18.0, t0 + 38.0)]
    ds = adapters.load(path, "ardupilot_manual")
    assert len(ds)
    for d in ds:
        start, end = d.meta["t0"], d.meta["t0"] + d.t[-1]
        assert any(a - 1e-9 <= start and end <= b + 1e-9 for a, b in armed), (start, end)
    summary = adapters.inspect(path)
    np.testing.assert_allclose(np.array(summary.armed), armed, atol=1e-6)


def test_a_log_that_never_armed_is_refused_as_never_armed(tmp_path):
    # erlerobot/logs pxf/rover/2-8-2014/mpu9250-ms5611/2.BIN (ArduCopter V3.2-rc2): EV LAND_COMPLETE, NOT_LANDED only
    path, _ = _log(tmp_path, "never.bin", [(1.0, 18), (2.0, 28)])
    with pytest.raises(DataError, match=r"never armed: the log records arming as events \(EV\.Id = 10 on arming\) "
                                        r"and holds none among its 2 EV message\(s\)"):
        adapters.load(path, "ardupilot_manual")
    assert adapters.inspect(path).armed_text == "armed: never armed"


def test_a_log_that_declares_ev_but_holds_none_never_armed(tmp_path):
    # ArduPilot/MethodicConfigurator's backend_log_80k.bin (ArduCopter V4.6.2): EV declared, no event, 0.03 m/s
    path, _ = _log(tmp_path, "silent.bin", [(1.0, 18)])
    data = bytearray(path.read_bytes())
    streams = adapters.read(path)
    assert streams.counts["EV"] == 1
    # the one EV message's type id turned into an undescribed one: EV stays declared, with no message
    ev_type = streams.info["formats"]["EV"]["type"]
    at = data.find(bytes([0xA3, 0x95, ev_type]), data.find(b"EV\x00\x00") + 80)
    data[at + 2] = 0xFE
    path.write_bytes(bytes(data))
    read = adapters.read(path)
    assert read.counts["EV"] == 0 and "EV" not in read.frames
    with pytest.raises(DataError, match=r"never armed: .* holds none among its 0 EV message\(s\)"):
        adapters.load(path, "ardupilot_manual")


def test_a_log_that_declares_no_ev_records_no_arming(tmp_path):
    # old ArduPlane (erlerobot/logs pxf/plane/4-12-2014/329.BIN) declares no EV: nothing is dropped for arming
    path, _ = _log(tmp_path, "no_ev.bin", drop_ev=True)
    assert "EV" not in adapters.read(path).counts
    assert len(adapters.load(path, "ardupilot_manual"))


def test_a_log_that_begins_armed_is_armed_until_its_first_disarm(tmp_path):
    path, t0 = _log(tmp_path, "began_armed.bin", [(20.0, 11)])
    ds = adapters.load(path, "ardupilot_manual")
    assert ds and all(d.meta["t0"] + d.t[-1] <= t0 + 20.0 + 1e-9 for d in ds)
    assert adapters.inspect(path).armed[0][1] == pytest.approx(t0 + 20.0)
