"""A fit on fewer than three distinct demonstrations warns; identical copies count once."""

from __future__ import annotations

import warnings

import pytest

from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DegenerateFitWarning, WorkbenchWarning
from workbench.models import GMROnlyModel, HumanBehaviorModel, IOCOnlyModel
from workbench.models.fitting import MIN_DISTINCT_DEMOS
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings


@pytest.fixture(scope="module")
def trials():
    return simulate_landings("CS1", MIN_DISTINCT_DEMOS, seed=4)


def _copies(ds: DemonstrationSet, k: int) -> DemonstrationSet:
    """``k`` copies of the first trial under different ids (the same trial loaded ``k`` times)."""
    return DemonstrationSet([ds[0].with_meta(id=f"copy-{i}") for i in range(k)], ds.state_names, ds.input_names,
                            ds.dt, roles=ds.roles)


MODELS = {
    "ioc-only": lambda s: IOCOnlyModel(s),
    "proposed": lambda s: HumanBehaviorModel(s, n_components=2, fit_objective=False, noise_folds=0),
    "gmr-only": lambda s: GMROnlyModel(s, n_components=2),
}


@pytest.mark.parametrize("kind", list(MODELS))
def test_one_demonstration_warns(trials, kind):
    with pytest.warns(DegenerateFitWarning, match="1 distinct demonstration") as record:
        MODELS[kind](planar_quadrotor(dt=trials.dt)).fit(trials[:1])
    assert issubclass(record[0].category, WorkbenchWarning)
    assert record[0].filename == __file__  # points at the caller's fit, not inside the workbench


def test_ten_identical_copies_count_as_one(trials):
    with pytest.warns(DegenerateFitWarning, match=r"1 distinct demonstration\(s\) \(10 given; identical copies"):
        IOCOnlyModel(planar_quadrotor(dt=trials.dt)).fit(_copies(trials, 10))


def test_enough_distinct_demonstrations_fit_silently(trials):
    assert len({d.id for d in trials}) == MIN_DISTINCT_DEMOS
    with warnings.catch_warnings():
        warnings.simplefilter("error", DegenerateFitWarning)
        IOCOnlyModel(planar_quadrotor(dt=trials.dt)).fit(trials)
        # two distinct trials plus a copy are still two
    with pytest.warns(DegenerateFitWarning, match="2 distinct"):
        IOCOnlyModel(planar_quadrotor(dt=trials.dt)).fit(trials[:2] + _copies(trials, 1))


def test_persistence_learns_nothing_and_does_not_warn_of_what_it_lacks(trials):
    """evaluate on a two-segment LOITER group warned "PersistenceModel.fit: fitting on 1 distinct demonstration(s);
    the gain, the variability's mixture and its noise rest on fewer than 3 trials": persistence has none of them."""
    from workbench.models.baselines import PersistenceModel

    with warnings.catch_warnings():
        warnings.simplefilter("error", DegenerateFitWarning)
        PersistenceModel(planar_quadrotor(dt=trials.dt)).fit(trials[:1])
    with pytest.warns(DegenerateFitWarning, match="1 distinct demonstration"):  # a model that learns still warns
        IOCOnlyModel(planar_quadrotor(dt=trials.dt)).fit(trials[:1])
