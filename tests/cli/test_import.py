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
