"""``workbench inspect``'s table and mode spans say only what the log's stamps support, and agree with themselves."""

from __future__ import annotations

from workbench.cli import app as cli_main


def _rows(text: str) -> list[list[str]]:
    return [[c.strip() for c in ln.split("│")[1:-1]] for ln in text.splitlines()
            if ln.startswith("│") and ln.split("│")[1].strip()]


def test_a_stream_without_a_time_span_has_no_rate(tmp_path, capsys, monkeypatch):
    """An old DataFlash log's PARM messages carry no time stamp: 395 of them at one instant read "0 Hz" (erle
    10-11-2014_105.BIN), as if the stream had been silent; a rate needs two stamps apart."""
    from adapters.formats import dataflash_write

    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    log = dataflash_write.write(tmp_path / "old.bin", streams, **options)
    monkeypatch.setenv("COLUMNS", "200")
    assert cli_main.main(["inspect", str(log)]) == 0
    rows = {r[0]: r for r in _rows(capsys.readouterr().out)}
    spanless = [r for r in rows.values() if r[3] == r[4]]
    assert spanless, rows  # the untimed streams
    for name, count, rate, start, end, _ in rows.values():
        if start == end:
            assert rate == "—", (name, rate)
        else:
            assert float(rate) > 0 and int(count) > 1


def test_a_mode_span_s_duration_is_its_shown_end_minus_its_shown_start(tmp_path, capsys, monkeypatch):
    """erle 10-11-2014_105.BIN read "LOITER 85.0–95.6 s (10.7 s)": each number rounded on its own."""
    import re

    import numpy as np

    from adapters.formats import dataflash_write

    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    mode = streams["MODE"]
    # mode changes at hundredths that round the start up and the end down (or the other way)
    mode["t"] = mode["t"].iloc[0] + np.array([0.0, 6.04, 13.46, 20.26, 26.74])[: len(mode)]
    log = dataflash_write.write(tmp_path / "modes.bin", streams, **options)
    monkeypatch.setenv("COLUMNS", "400")
    assert cli_main.main(["inspect", str(log)]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("flight modes"))
    spans = re.findall(r"([\d.]+)–([\d.]+) s \(([\d.]+) s\)", line)
    assert len(spans) >= 3, line
    for a, b, d in spans:
        assert f"{float(b) - float(a):.1f}" == d, line
