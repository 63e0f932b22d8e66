"""Model files written by an earlier version load and predict the same numbers (tests/fixtures/README.md).

The file format stores a class name, never a module path, so moving a module must not break a user's files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.models import MODEL_CLASSES, load_model

DATA = Path(__file__).resolve().parents[1] / "fixtures"
#: The fixtures that exist, not one per model class: a class registered after a fixture was written has none (a new
#: baseline is its module and its test, not a file written by a version that never knew it).
OLD_FILES = sorted(p.name.removesuffix("_0.1.0.npz") for p in DATA.glob("*_0.1.0.npz"))
MAIN_CASES = sorted(p.stem.removeprefix("main_") for p in DATA.glob("main_*.npz")
                    if p.name != "main_model_predictions.npz")


def test_the_fixtures_are_found_and_name_known_classes():
    """The lists above come from the folder; an empty folder (or a class renamed away) must not pass silently."""
    assert {"HumanBehaviorModel", "IOCOnlyModel", "GMROnlyModel", "PersistenceModel"} <= set(OLD_FILES)
    assert set(OLD_FILES) <= set(MODEL_CLASSES), sorted(set(OLD_FILES) - set(MODEL_CLASSES))
    assert {"proposed", "proposed_cv", "ioc_only", "gmr_only", "persistence"} <= set(MAIN_CASES)
    expected = np.load(DATA / "main_model_predictions.npz")
    assert {k.split("/")[0] for k in expected.files if "/" in k} == set(MAIN_CASES)


@pytest.mark.parametrize("name", OLD_FILES)
def test_a_file_written_before_the_subpackages_loads_and_predicts_the_same(name):
    expected = np.load(DATA / "old_model_predictions.npz")
    model = load_model(DATA / f"{name}_0.1.0.npz")
    assert type(model).__name__ == name
    pred = model.predict(expected["x0"], 20, target=expected["target"])
    np.testing.assert_allclose(pred.x, expected[name], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("case", MAIN_CASES)
def test_a_file_written_by_the_main_before_the_registry_loads_and_predicts_the_same(case):
    """Files written by the main of issue 30's second round (tests/fixtures/write_model_files.py, run with that
    checkout): every model class, a "cv" proposed model and one fitted without targets, with the records added
    since 0.1.0 (envelope, training trials, gain choice, auto settings). Means, bands and input distributions."""
    expected = np.load(DATA / "main_model_predictions.npz")
    model = load_model(DATA / f"main_{case}.npz")
    x0, target, X = expected["x0"], expected["target"], expected["X"]
    np.testing.assert_allclose(model.predict(x0, 20, target=target).x, expected[f"{case}/x"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(model.predict(x0, 20).x, expected[f"{case}/x_free"], rtol=1e-9, atol=1e-12)
    bands = model.predict(x0, 20, target=target, samples=16, seed=0).x_bands
    if f"{case}/x_bands" in expected:
        np.testing.assert_allclose(bands, expected[f"{case}/x_bands"], rtol=1e-9, atol=1e-12)
    else:
        assert bands is None
    mean, cov = model.input_distribution(X, x0, target)
    np.testing.assert_allclose(mean, expected[f"{case}/u_mean"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(cov, expected[f"{case}/u_cov"], rtol=1e-9, atol=1e-12)


def test_a_header_nested_beyond_the_parser_is_a_model_file_error(tmp_path):
    from workbench.models.files import ModelFileError

    text = ("[" * 200_000 + "]" * 200_000).encode()
    path = tmp_path / "nested.npz"
    np.savez(path, __header__=np.frombuffer(text, dtype=np.uint8))
    with pytest.raises(ModelFileError, match="nested deeper"):
        load_model(path)  # the previous main let json's RecursionError out


@pytest.mark.parametrize("name", OLD_FILES)
def test_an_old_file_does_not_know_its_training_trials(name):
    from workbench.models.training import in_sample, split_words, training_known

    model = load_model(DATA / f"{name}_0.1.0.npz")
    assert not training_known(model) and model.train_ids_ is None and model.data_digest_ is None
    assert in_sample(model, []) == []
    assert "unknown" in split_words(model, [])


def test_a_model_file_records_its_training_trials_and_their_digest(tmp_path, quadrotor, cs1_demos):
    from workbench.data.digest import set_digest, trial_digest
    from workbench.models import HumanBehaviorModel
    from workbench.models.training import held_out, in_sample

    train, test = cs1_demos.split(2, seed=0)
    model = HumanBehaviorModel(quadrotor, n_components=2, fit_objective=False).fit(train)
    back = load_model(model.save(tmp_path / "m.npz"))
    assert back.train_ids_ == tuple(train.ids)
    assert back.train_digests_ == tuple(trial_digest(d) for d in train)
    assert back.data_digest_ == set_digest(train)
    assert in_sample(back, cs1_demos) == list(train.ids)
    assert held_out(back, cs1_demos) == list(test.ids)
    # the same samples under another id are still in-sample (the digest knows them)
    renamed = [type(d)(d.t, d.x, d.u, {**d.meta, "id": "other-" + d.id}) for d in train]
    assert in_sample(back, renamed) == [d.id for d in renamed]
    # one sample changed under a new id: held out
    d = test[0]
    moved = type(d)(d.t, d.x + 1e-6, d.u, {**d.meta, "id": "moved"})
    assert in_sample(back, [moved]) == []


def test_a_header_integer_beyond_a_floats_range_is_a_model_file_error(tmp_path, quadrotor, cs1_demos):
    # every reader float()s its header numbers: 10**400 in the auto settings ended load_model in OverflowError
    import json

    from tests.forgeries import rewrite_model_file
    from workbench.models import HumanBehaviorModel
    from workbench.models.files import ModelFileError

    src = tmp_path / "m.npz"
    HumanBehaviorModel(quadrotor, n_components=1, noise_folds=0, fit_objective=False).fit(cs1_demos).save(src)

    def huge(text: str, value: int) -> str:
        header = json.loads(text)
        header["reg_covar_chosen"] = value
        return json.dumps(header)

    fits = tmp_path / "fits.npz"
    rewrite_model_file(src, fits, lambda t: huge(t, 10**300))
    assert load_model(fits).reg_covar_ == float(10**300)  # the largest a float holds still reads
    bad = tmp_path / "huge.npz"
    rewrite_model_file(src, bad, lambda t: huge(t, 10**400))
    with pytest.raises(ModelFileError, match="number too long to read"):
        load_model(bad)
