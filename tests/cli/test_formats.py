"""Every declared log format (adapters/formats/declared/) through every entry point that takes a log.

The formats come from the registry, never from a list here: a format added there is tested here the day it is
added. Each one gets a log written by its own writer from simulated landings (through the planar-quadrotor mapping,
which the writer inverts), then: ``inspect`` it, ``import`` it (the trials come back), ``import -`` from standard
input (recognised by its bytes, and named with ``--format``), a folder of one log per format imported as a dataset,
``demo --logs`` finding it (and, marked slow, running on it), ``simulate -o - --output-format`` writing it,
``view --save`` recording it, and rerun's importer claiming it or passing it on.
"""

from __future__ import annotations

import io
import sys

import numpy as np
import pytest

import adapters
from adapters.formats import FORMATS
from adapters.mapping import load_mapping
from workbench.cli import main
from workbench.data.dataset import load_demonstrations

MAPPING = "planar_quadrotor"
ALL = list(FORMATS.values())
IDS = [f.name for f in ALL]


class _Stdin(io.TextIOWrapper):
    """A piped standard input for in-process runs."""

    def __init__(self, data: bytes) -> None:
        super().__init__(io.BytesIO(data))

    def isatty(self) -> bool:
        return False


def _landings(seed: int):
    from workbench.sim.landing import simulate_landings

    return (simulate_landings("CS1", 2, seed=seed, subject="s00")
            + simulate_landings("CS2", 2, seed=seed + 1, subject="s00"))


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """One log per declared format, written by that format's writer, all in one folder: {name: (path, trials)};
    each from its own landings (a dataset refuses the same trial twice)."""
    folder = tmp_path_factory.mktemp("formats")
    out = {}
    for i, f in enumerate(ALL):
        ds = _landings(2 * i)
        out[f.name] = (adapters.write(ds, folder / f"landing_{f.name}{f.suffix}", MAPPING), ds)
    return out


@pytest.fixture(scope="module")
def logs(written):
    return {name: path for name, (path, _) in written.items()}


@pytest.fixture
def demos(written, fmt):
    return written[fmt.name][1]


def test_every_format_has_a_writer_to_make_its_test_log():
    """Without one this module cannot make the format's log: give the format a writer or this test a sample file."""
    assert [f.name for f in ALL if not f.writable] == []
    assert len(ALL) >= 5  # the registry found the shipped formats (a broken discovery must not pass as "none")


def _same_trials(got, demos, fmt) -> None:
    """The trials the log was written from, within what the format stores: a field the mapping scales (a stick in
    thousandths) to half its step, a float field to float32's precision; metadata where the format carries it."""
    m = load_mapping(MAPPING).for_format(fmt.name)
    assert len(got) == len(demos)
    assert [len(d) for d in got] == [len(d) for d in demos]
    for j, name in enumerate(got.input_names):
        scale = abs(m.channel(name).factor)
        step = 0.5 * scale if scale != 1 else 1e-6
        for a, b in zip(got, demos, strict=True):
            np.testing.assert_allclose(a.u[:, j], b.u[:, j], atol=step, rtol=0, err_msg=f"{fmt.name}: {name}")
    for a, b in zip(got, demos, strict=True):
        np.testing.assert_allclose(a.x, b.x, rtol=1e-6, atol=1e-6, err_msg=fmt.name)
    if m.meta.source is not None or m.meta.text is not None:
        assert got.labels == demos.labels and got.ids == demos.ids


@pytest.mark.parametrize("fmt", ALL, ids=IDS)
def test_inspect(fmt, logs, capsys):
    assert main(["inspect", str(logs[fmt.name])]) == 0
    assert capsys.readouterr().out.startswith(f"{logs[fmt.name]}: {fmt.name}, ")


@pytest.mark.parametrize("fmt", ALL, ids=IDS)
def test_import_gives_the_trials_back(fmt, logs, demos, tmp_path):
    out = tmp_path / "demos.parquet"
    assert main(["import", str(logs[fmt.name]), "--mapping", MAPPING, "-o", str(out)]) == 0
    _same_trials(load_demonstrations(out), demos, fmt)


@pytest.mark.parametrize("how", ["sniffed", "--format"])
@pytest.mark.parametrize("fmt", [f for f in ALL if f.stdin], ids=[f.name for f in ALL if f.stdin])
def test_import_from_standard_input(fmt, how, logs, demos, tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "stdin", _Stdin(logs[fmt.name].read_bytes()))
    out = tmp_path / "demos.parquet"
    named = ["--format", fmt.name] if how == "--format" else []
    assert main(["import", "-", *named, "--mapping", MAPPING, "-o", str(out)]) == 0
    got = load_demonstrations(out)
    _same_trials(got, demos, fmt)
    assert {d.meta.get("source") for d in got} == {"<stdin>"}


def test_a_folder_of_every_format_imports_as_one_dataset(logs, written, tmp_path, capsys):
    """``import DIR/ -o DATASET/``: the folder contributes every format's log (a .bin was once left out)."""
    folder = next(iter(logs.values())).parent
    assert main(["import", str(folder), "--mapping", MAPPING, "-o", str(tmp_path / "dataset") + "/"]) == 0
    assert f"from {len(ALL)} of {len(ALL)} logs" in capsys.readouterr().out
    got = load_demonstrations(tmp_path / "dataset")
    assert len(got) == sum(len(ds) for _, ds in written.values())
    assert {str(d.meta.get("source")) for d in got} == {str(p) for p in logs.values()}


def test_the_demo_finds_every_formats_logs(logs):
    from workbench.cli.study import demo_logs

    folder = next(iter(logs.values())).parent
    assert demo_logs(folder) == sorted(logs.values())


@pytest.mark.parametrize("fmt", ALL, ids=IDS)
def test_simulate_writes_it_to_standard_output(fmt, tmp_path, capsysbinary):
    assert main(["simulate", "--trials", "1", "--strategy", "CS1", "-o", "-",
                 "--output-format", fmt.output_name]) == 0
    data = capsysbinary.readouterr().out
    path = tmp_path / f"out{fmt.suffix}"
    path.write_bytes(data)
    assert adapters.detect_format(path) is fmt
    assert len(adapters.load(path, mapping=MAPPING)) == 1


@pytest.mark.parametrize("fmt", ALL, ids=IDS)
def test_view_saves_a_recording(fmt, logs, demos, tmp_path, capsys):
    out = tmp_path / "view.rrd"
    assert main(["view", str(logs[fmt.name]), "--mapping", MAPPING, "--save", str(out)]) == 0
    assert f"({len(demos)} demonstrations)" in capsys.readouterr().out
    assert out.stat().st_size > 0


@pytest.mark.parametrize("fmt", ALL, ids=IDS)
def test_view_saves_the_raw_log(fmt, logs, tmp_path, capsys):
    """``view LOG --raw``: the log's own streams."""
    out = tmp_path / "raw.rrd"
    n_streams = len(adapters.read(logs[fmt.name]))
    assert main(["view", str(logs[fmt.name]), "--raw", "--save", str(out)]) == 0
    assert f"(the raw log: {n_streams} streams" in capsys.readouterr().out
    assert out.stat().st_size > 0


@pytest.mark.slow
def test_the_demo_runs_on_a_folder_of_every_format(tmp_path, capsys):
    """``demo --logs DIR`` over one log per format (six trials a strategy each, enough for its split): every log
    imported, the study and its outputs made (4 min under load, 41 s of CPU)."""
    folder = tmp_path / "logs"
    folder.mkdir()
    n = 0
    for i, f in enumerate(ALL):
        from workbench.sim.landing import simulate_landings

        ds = (simulate_landings("CS1", 6, seed=2 * i, subject=f"s{i:02d}")
              + simulate_landings("CS2", 6, seed=2 * i + 1, subject=f"s{i:02d}"))
        adapters.write(ds, folder / f"landing_{f.name}{f.suffix}", MAPPING)
        n += len(ds)
    assert main(["demo", "--logs", str(folder), "--out", str(tmp_path / "out"), "--samples", "0",
                 "--no-efficiency"]) == 0
    out = capsys.readouterr().out
    assert f"imported {n} demonstrations" in out and f"from {len(ALL)} logs" in out
    assert all(f"1 {f.output_name}" in out for f in ALL)


@pytest.mark.parametrize("fmt", ALL, ids=IDS)
def test_rerun_importer_claims_the_formats_that_declare_it(fmt, logs, capfdbinary):
    """``rerun-importer-workbench LOG``: an rrd stream for a format whose ``rerun_importer`` is true, else 66 (rerun
    asks the next importer)."""
    from workbench.cli.loader import INCOMPATIBLE
    from workbench.cli.loader import main as importer

    status = importer([str(logs[fmt.name])])
    stream = capfdbinary.readouterr().out  # rerun writes to the file descriptor itself
    if fmt.rerun_importer:
        assert status == 0 and stream.startswith(b"RRF")
    else:
        assert status == INCOMPATIBLE and not stream
