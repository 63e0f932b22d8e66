"""Checks every model class passes, as scikit-learn runs its common estimator checks: one parametrized test per
convention over :data:`workbench.models.MODEL_CLASSES`, so a new model is checked the day it is registered."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.errors import ModelError
from workbench.models import MODEL_CLASSES, load_model
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings

# small settings where a class takes them, so the checks stay fast; the rest are the class defaults
FAST = {"n_components": 2, "random_state": 0}


@pytest.fixture(scope="module")
def data():
    return planar_quadrotor(), simulate_landings("CS1", n_trials=6, seed=11)


def _make(cls, plant):
    names = set(cls._param_names())
    return cls(plant, **{k: v for k, v in FAST.items() if k in names})


@pytest.fixture(scope="module")
def fitted(data):
    plant, ds = data
    return {name: _make(cls, plant).fit(ds) for name, cls in MODEL_CLASSES.items()}


CLASSES = sorted(MODEL_CLASSES)


@pytest.mark.parametrize("name", CLASSES)
def test_fit_returns_self_and_learns_attributes_ending_in_underscore(name, data):
    plant, ds = data
    model = _make(MODEL_CLASSES[name], plant)
    before = {k for k in vars(model) if k.endswith("_") and not k.startswith("_")}
    assert model.fit(ds) is model
    learned = {k for k in vars(model) if k.endswith("_") and not k.startswith("_")} - before
    assert learned, f"{name}.fit learned no attribute ending in '_'"


@pytest.mark.parametrize("name", CLASSES)
def test_the_constructor_holds_settings_only_and_they_round_trip(name, data):
    plant, _ = data
    model = _make(MODEL_CLASSES[name], plant)
    params = model.get_params()
    assert set(params) == set(type(model)._param_names())
    assert not [k for k in vars(model) if k.endswith("_") and not k.startswith("_")], "learned state before fit"
    again = type(model)(plant, **params)
    assert again.get_params() == params
    assert model.clone().get_params() == params


@pytest.mark.parametrize("name", CLASSES)
def test_unfitted_use_is_refused_with_the_cause(name, data):
    plant, ds = data
    model = _make(MODEL_CLASSES[name], plant)
    with pytest.raises(ModelError, match="not fitted"):
        model.predict(ds[0].x[0], 5)
    with pytest.raises(ModelError, match="not fitted"):
        model.save("never-written.npz")


@pytest.mark.parametrize("name", CLASSES)
def test_predictions_have_the_documented_shapes_and_batch_like_one_by_one(name, data, fitted):
    plant, ds = data
    model = fitted[name]
    n, m, n_steps = plant.n, plant.m, 7
    x0s = np.stack([d.x[0] for d in ds[:3]])
    targets = np.stack([np.zeros(n)] * 3)
    one = model.predict(x0s[0], n_steps, target=targets[0])
    assert np.asarray(one.x).shape == (n_steps + 1, n) and np.asarray(one.u).shape == (n_steps, m)
    many = model.predict_many(x0s, n_steps, targets)
    assert len(many) == 3
    for k, p in enumerate(many):
        single = model.predict(x0s[k], n_steps, target=targets[k])
        np.testing.assert_allclose(p.x, single.x, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", CLASSES)
def test_save_and_load_round_trip_predictions(name, data, fitted, tmp_path):
    plant, ds = data
    model = fitted[name]
    back = load_model(model.save(tmp_path / f"{name}.npz"))
    assert type(back) is type(model) and back.get_params().keys() == model.get_params().keys()
    x0 = ds[1].x[0]
    np.testing.assert_allclose(back.predict(x0, 10).x, model.predict(x0, 10).x, rtol=1e-12, atol=1e-12)


def test_every_registered_class_is_checked():
    """The registry is the list: a model class in workbench/models/ missing from it would escape these checks and
    load_model (every module is searched, so a class in a new module is found the day it is added)."""
    import importlib
    import inspect
    import pkgutil

    import workbench.models
    from workbench.models.behavior import BehaviorModel

    classes = set()
    for info in pkgutil.iter_modules(workbench.models.__path__):
        module = importlib.import_module(f"workbench.models.{info.name}")
        classes |= {obj.__name__ for obj in vars(module).values()
                    if isinstance(obj, type) and issubclass(obj, BehaviorModel) and obj.__module__ == module.__name__
                    and not inspect.isabstract(obj) and not obj.__name__.startswith("_")}
    assert classes == set(MODEL_CLASSES)
