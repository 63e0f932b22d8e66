"""``workbench import``: what the options change in the written demonstrations, and what they leave alone."""

from __future__ import annotations

import pytest

import adapters
from workbench.cli import main
from workbench.data.dataset import load_demonstrations


@pytest.fixture(scope="module")
def copter_log(tmp_path_factory):
    from adapters.formats.dataflash_write import write_example

    return write_example(tmp_path_factory.mktemp("import") / "copter.bin", "new", "copter", seconds=60.0, rate=1.0,
                         seed=4)


@pytest.mark.parametrize("option", ["--set-label", "--label"])
def test_a_set_label_keeps_the_mappings_roles(copter_log, tmp_path, option):
    """The label is the only change: the mapping's roles (positions, velocities, heading) stay, so metrics and the
    viewer's scene still find the vehicle (the set was once rebuilt without them)."""
    expected = adapters.load(copter_log, mapping="ardupilot_manual")
    assert expected.roles is not None and expected.roles.position  # else the test checks nothing
    out = tmp_path / "demos.parquet"
    assert main(["import", str(copter_log), "--mapping", "ardupilot_manual", option, "X", "-o", str(out)]) == 0
    ds = load_demonstrations(out)
    assert ds.labels == ["X"]
    assert ds.roles == expected.roles
    assert ds.ids == expected.ids


def test_a_folder_with_a_dataflash_log_imports_it(copter_log, tmp_path, capsys):
    """``import DIR/`` takes every declared format's files from a folder: a DataFlash ``.bin`` was left out (the
    folder held "no logs"; fails on the previous main)."""
    folder = tmp_path / "logs"
    folder.mkdir()
    (folder / copter_log.name).write_bytes(copter_log.read_bytes())
    expected = adapters.load(copter_log, mapping="ardupilot_manual")
    out = tmp_path / "dataset"
    assert main(["import", str(folder), "--mapping", "ardupilot_manual", "-o", f"{out}/"]) == 0
    assert "from 1 of 1 logs" in capsys.readouterr().out
    assert load_demonstrations(out).n_samples == expected.n_samples


def test_a_demonstrations_file_names_the_log_its_import_skipped_data_of(capsys):
    # fit demos.parquet printed "warning: demos.parquet: skipped bytes: 27613, crc failures: 1314", blaming a file
    # that is not damaged: the counts are those of the log it was imported from, carried in its meta
    from pathlib import Path

    import numpy as np

    from workbench.cli.inputs import Source
    from workbench.cli.reading import _warn_about
    from workbench.data import Demonstration, DemonstrationSet

    meta = {"id": "f-000", "source": "flight.tlog", "skipped": {"bytes": 12, "crc_failures": 3}}
    ds = DemonstrationSet([Demonstration(np.arange(5) * 0.1, np.zeros((5, 1)), np.zeros((5, 1)), meta)], ["x"], ["u"],
                          dt=0.1)
    _warn_about(Source("demos.parquet", Path("demos.parquet"), "demos.parquet", demos=True), ds)
    said = capsys.readouterr().err
    assert said.strip() == ("warning: demos.parquet (its import from flight.tlog): skipped bytes: 12, "
                            "crc failures: 3"), said
    _warn_about(Source("flight.tlog", Path("flight.tlog"), "flight.tlog", demos=False), ds)
    assert capsys.readouterr().err.strip() == "warning: flight.tlog: skipped bytes: 12, crc failures: 3"
