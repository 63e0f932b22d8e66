"""A mapping entry the log holds but reads wrongly is the mapping's error, named with its file, entry and cause;
only a source the log lacks is "not in this log"."""

from __future__ import annotations

from pathlib import Path

import pytest

import adapters
from workbench.errors import MappingError

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_logs" / "landing_s02.csv"


def _mine(tmp_path: Path, **entries: str) -> Path:
    """The shipped planar_quadrotor mapping with some of its CSV channel entries rewritten (a user's copy)."""
    text = (ROOT / "adapters" / "mappings" / "planar_quadrotor.toml").read_text(encoding="utf-8")
    for name, source in entries.items():
        old = f'\n{name} = "csv.{name}"\n'
        assert old in text
        text = text.replace(old, f'\n{name} = "{source}"\n')
    path = tmp_path / "mine.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_a_column_count_mismatch_beside_an_absent_field_names_the_entry_not_the_log(tmp_path):
    # u1 reads two fields where its transform takes one, phidot a misspelt field: the log holds u1's fields, so
    # "the pilot's input u1 is not in this log, so there is no pilot to model" was false
    mapping = _mine(tmp_path, u1="csv.u1,u2", phidot="csv.phidotx")
    with pytest.raises(MappingError) as info:
        adapters.load(SAMPLE, str(mapping))
    text = str(info.value)
    assert "not in this log" not in text and "\n" not in text
    assert text.startswith(f"{mapping}: mapping 'planar_quadrotor', entry [csv.channels] u1 = 'csv.u1,u2': ")
    assert "needs 1 column(s) from 'csv.u1,u2', but stream 'csv' has 2" in text and str(SAMPLE) in text


def test_fields_the_log_lacks_are_still_not_in_this_log(tmp_path):
    mapping = _mine(tmp_path, u1="csv.stick1", phidot="csv.phidotx")
    with pytest.raises(MappingError, match=r"the pilot's input u1 is not in this log, so there is no pilot to model: "
                                           r".*has no field 'stick1'.*; also not in it: phidot \(csv\.phidotx\)"):
        adapters.load(SAMPLE, str(mapping))
