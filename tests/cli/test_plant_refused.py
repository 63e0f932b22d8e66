"""A plant refused for its physics: the command line names the file and plant group in its one error line, and prints
the identification report that line refers to (on standard error, before it)."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("command", ["fit", "evaluate"])
def test_a_refused_plant_names_file_and_group_after_its_report(tmp_path, capsys, command):
    # `workbench fit log23.parquet` (flug log_23) printed "error: the identified plant is not physics: …", naming
    # neither the file nor the group, and no report of the plant it refused
    from tests.plant.test_identification import _angle_flights
    from workbench.cli.app import main
    from workbench.data.plant_groups import plant_groups

    ds = _angle_flights(2.0, 2.0)  # every segment: the velocity answers the lean with the wrong sign
    (group,) = plant_groups(ds)
    path = ds.save(tmp_path / "wrong_sign.parquet")
    # evaluate said "error: the identified plant is not physics: …" as fit did (its refusal, from its plant of all
    # segments, came through as a plain ModelError)
    extra = [] if command == "fit" else ["--holdout", "split"]
    status = main([command, str(path), *extra, "-o", str(tmp_path / ("m.npz" if command == "fit" else "r.parquet"))])
    err = capsys.readouterr().err
    assert status == 1 and not (tmp_path / "m.npz").exists() and not (tmp_path / "r.parquet").exists()
    error = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(error) == 1
    done = "fitted" if command == "fit" else "evaluated"
    assert error[0].startswith(f"error: {path}: plant group {group}: not {done}: the identified plant is not physics")
    report = err.index("plant identification (")
    assert report < err.index(error[0]) and "check: A[xdot, phi]" in err[report:err.index(error[0])]

