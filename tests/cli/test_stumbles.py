"""What a new user meets first: a glob over the sample folder, an output name without a known extension, and the
README's commands writing into out/ instead of the repository root."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from workbench.cli import main

REPO = Path(__file__).resolve().parents[2]


def test_a_glob_over_a_folder_of_logs_skips_what_is_not_a_log(tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(REPO / "sample_logs" / "landing_s00.tlog", logs)
    (logs / "README.md").write_text("# about these logs")
    assert main(["import", str(logs / "*"), "-o", str(tmp_path / "demos.parquet")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["import", str(logs / "*.md"), "-o", str(tmp_path / "x.parquet")]) == 1
    assert "matches no log" in capsys.readouterr().err


def test_an_unknown_output_extension_names_the_ones_the_cli_takes(tmp_path, capsys):
    assert main(["import", str(REPO / "sample_logs" / "landing_s00.tlog"), "-o", str(tmp_path / "out.json")]) == 2
    err = capsys.readouterr().err
    assert "format=" not in err and ".parquet" in err and ".csv" in err and "DIR/" in err


def test_the_readmes_commands_write_under_out():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    commands = re.findall(r"^\.venv/bin/workbench .*$", text, flags=re.M)
    outputs = [o for c in commands for o in re.findall(r"(?:-o|--save) (\S+)", c)]
    assert outputs and all(o.startswith("out/") for o in outputs), outputs


@pytest.mark.parametrize("speed", ["1e-300", "1e300", "0"])
def test_a_replay_speed_out_of_range_is_refused_by_the_parser(speed, capsys):
    with pytest.raises(SystemExit) as info:
        main(["replay", "sample_logs/landing_s00.tlog", "--to", "udpout:127.0.0.1:14550", "--speed", speed])
    assert info.value.code == 2 and "--speed" in capsys.readouterr().err  # previous main: OverflowError on 1e-300
