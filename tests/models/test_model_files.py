"""Model files written by an earlier version load and predict the same numbers (tests/fixtures/README.md).

The file format stores a class name, never a module path, so moving a module must not break a user's files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.models import MODEL_CLASSES, load_model

DATA = Path(__file__).resolve().parents[1] / "fixtures"


@pytest.mark.parametrize("name", sorted(MODEL_CLASSES))
def test_a_file_written_before_the_subpackages_loads_and_predicts_the_same(name):
    expected = np.load(DATA / "old_model_predictions.npz")
    model = load_model(DATA / f"{name}_0.1.0.npz")
    assert type(model).__name__ == name
    pred = model.predict(expected["x0"], 20, target=expected["target"])
    np.testing.assert_allclose(pred.x, expected[name], rtol=1e-9, atol=1e-12)


def test_a_header_nested_beyond_the_parser_is_a_model_file_error(tmp_path):
    from workbench.models.files import ModelFileError

    text = ("[" * 200_000 + "]" * 200_000).encode()
    path = tmp_path / "nested.npz"
    np.savez(path, __header__=np.frombuffer(text, dtype=np.uint8))
    with pytest.raises(ModelFileError, match="nested deeper"):
        load_model(path)  # the previous main let json's RecursionError out
