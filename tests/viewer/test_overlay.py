"""Several logs on one clock (workbench/viewer/overlay.py): alignment at arming, takeoff, start or an offset; one
colour per log; logs of different formats and rates as recorded."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from adapters.rawlog import NumericStream, RawLog, TextLog
from workbench import palette
from workbench.errors import DataError
from workbench.viewer import style
from workbench.viewer.overlay import alignment_time

EXTERNAL = Path(__file__).resolve().parents[2].parent / "shared" / "external"


def _raw(t_start=100.0, armed=((130.0, 200.0),), height=None, path="a.tlog"):
    streams = []
    if height is not None:
        t, h = height
        streams.append(NumericStream("GLOBAL_POSITION_INT", np.asarray(t, float), ("relative_alt",),
                                     1000.0 * np.asarray(h, float)[:, None], ("mm",)))
    return RawLog(path, "tlog", t_start, 300.0, tuple(streams), TextLog(np.zeros(0), (), (), ()), None, (), (),
                  tuple(armed), True, "copter")


def test_alignment_points_are_found_from_the_log():
    assert alignment_time(_raw(), "start")[0] == 100.0
    assert alignment_time(_raw(), "arming")[0] == 130.0
    assert alignment_time(_raw(), "12.5")[0] == 112.5
    t = np.arange(100.0, 200.0, 0.5)
    h = np.where(t < 150.0, 0.2, 0.2 + (t - 150.0))  # on the ground until 150 s, then climbing 1 m/s
    when, words = alignment_time(_raw(height=(t, h)), "takeoff")
    assert 151.0 <= when <= 151.5 and "takeoff" in words


def test_a_missing_event_names_the_log_and_the_way_out():
    with pytest.raises(DataError, match=r"b\.bin: no arming.*--align takeoff, start"):
        alignment_time(_raw(armed=(), path="b.bin"), "arming")
    with pytest.raises(DataError, match="no takeoff"):
        alignment_time(_raw(height=(np.arange(10.0) + 100, np.zeros(10))), "takeoff")


@pytest.mark.slow  # two real logs read and logged: ~20 s (the alignment itself is the fast tests' above)
@pytest.mark.skipif(not (EXTERNAL / "erle_copter_83.BIN").is_file(), reason="the shared real logs are absent")
def test_two_logs_of_other_formats_and_rates_overlay_on_one_clock(tmp_path):
    from rerun.chunk import RrdReader

    import adapters
    from workbench.cli import main

    logs = [EXTERNAL / "erle_copter_83.BIN", EXTERNAL / "dronekit_flight.tlog"]
    out = tmp_path / "o.rrd"
    assert main(["view", *map(str, logs), "--raw", "--save", str(out), "-q"]) == 0
    colors, first_t = {}, {}
    for chunk in RrdReader(out).stream():
        path = chunk.entity_path
        if not path.endswith("/pilot/roll/actual"):
            continue
        batch = chunk.to_record_batch()
        if chunk.is_static and "SeriesLines:colors" in batch.schema.names:
            colors.setdefault(path, set()).update(c[0] for c in batch.column("SeriesLines:colors").to_pylist())
        elif "time" in batch.schema.names:
            import pyarrow as pa

            t = batch.column("time").cast(pa.int64()).to_numpy() / 1e9
            first_t[path] = min(first_t.get(path, np.inf), float(t.min()))
    assert len(colors) == 2  # one colour per log, the k-th of the strategies' set
    for k, log in enumerate(logs):
        path = f"/logs/{log.name}/pilot/roll/actual"
        assert int(style.packed(palette.strategy_color(k))[0]) in colors[path], path
    # each log's 0 s is its arming: the tlog's telemetry starts long before it, so its series start below 0
    tlog = adapters.read(logs[1])
    from adapters.rawlog import raw_log

    arm = raw_log(tlog).armed[0][0] - raw_log(tlog).t_start
    tlog_first = next(v for p, v in first_t.items() if "dronekit" in p)
    assert tlog_first < 0 and abs(tlog_first + arm) < 5.0


def test_subjects_overlay_on_the_trials_clock_one_colour_each():
    from workbench.sim.landing import simulate_landings
    from workbench.viewer import session

    ds = simulate_landings("CS1", n_trials=4, seed=0)
    ds = ds.with_demos([d.with_meta(subject=f"p{k % 2}") for k, d in enumerate(ds)])
    logger = session.SessionLogger(session.new_recording(), ds, color_by="subject")
    by_subject: dict[str, set] = {}
    for d in ds:
        by_subject.setdefault(d.meta["subject"], set()).add(logger.colors[d.id])
    assert all(len(c) == 1 for c in by_subject.values())  # one colour per subject …
    assert len({next(iter(c)) for c in by_subject.values()}) == 2  # … and two subjects, two colours
    assert set(logger.session.label_colors) == {"p0", "p1"}  # the key names subjects, not the strategy
    with pytest.raises(DataError, match="--color-by"):
        session.SessionLogger(session.new_recording(), ds, color_by="pilot_shoe_size")


@pytest.mark.slow  # two real logs mapped twice: ~50 s
@pytest.mark.skipif(not (EXTERNAL / "erle_copter_83.BIN").is_file(), reason="the shared real logs are absent")
def test_mapped_logs_of_different_dt_name_the_way_out_and_resample_on_request(tmp_path, capsys):
    from workbench.cli import main

    logs = [str(EXTERNAL / "dronekit_flight.tlog"), str(EXTERNAL / "erle_copter_83.BIN")]
    assert main(["view", *logs, "--save", str(tmp_path / "a.rrd"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "different dt" in err and "--resample" in err and "--raw" in err
    assert main(["view", *logs, "--resample", "--save", str(tmp_path / "b.rrd"), "-q"]) == 0
    assert (tmp_path / "b.rrd").stat().st_size > 0
