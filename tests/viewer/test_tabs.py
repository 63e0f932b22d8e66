"""Checks every tab of a session recording passes (workbench/viewer/tabs/), as test_formats.py runs every log format
through every entry point: one parametrized test per convention over :data:`workbench.viewer.tabs.TABS`, so a tab is
checked the day its module is added.

Which question each answers: is the tab in the table, in its place; does a full session (a model, a baseline,
predictions, scores) give it something to show, named after it, in the blueprint; does it show only entities that
were logged (a view of a path nothing wrote is an empty panel); does a session without a model still build.
"""

from __future__ import annotations

from typing import Any

import pytest

from workbench.viewer.blueprint import session_blueprint
from workbench.viewer.session import log_session, new_recording
from workbench.viewer.tabs import TABS

NAMES = [t.name for t in TABS]


@pytest.fixture(scope="module")
def sessions():
    """A session with a model per strategy (CS1 only), a baseline and predictions, and one without a model."""
    from workbench.models import HumanBehaviorModel, IOCOnlyModel
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.landing import simulate_landings

    plant = planar_quadrotor()
    demos = simulate_landings("CS1", 4, seed=5) + simulate_landings("CS2", 2, seed=6)
    cs1 = demos.by_label("CS1")
    train = cs1.with_demos(list(cs1)[:3])
    model = HumanBehaviorModel(plant, n_components=2, noise_folds=0, fit_objective=False).fit(train)
    ioc = IOCOnlyModel(plant).fit(train)
    full = log_session(new_recording(), demos, models={"CS1": model}, baselines={"CS1": {"ioc_only": ioc}},
                       n_steps=10, samples=4)
    bare = log_session(new_recording(), demos)
    return {"full": full, "bare": bare}


def _views(item: Any) -> list[Any]:
    """Every view inside a blueprint container (a view has an origin; a container has contents)."""
    if hasattr(item, "origin"):
        return [item]
    return [v for c in item.contents for v in _views(c)]


def _logged(path: str, entities: list[str]) -> bool:
    path = path.strip("/")
    return not path or any(e == path or e.startswith(path + "/") for e in entities)


def test_the_table_finds_the_tabs_in_their_order():
    assert len(TABS) >= 5 and len(set(NAMES)) == len(NAMES)  # the shipped tabs (a broken discovery must not pass)
    assert [t.order for t in TABS] == sorted(t.order for t in TABS)
    assert all(t.description and "\n" not in t.description for t in TABS)


@pytest.mark.parametrize("tab", TABS, ids=NAMES)
def test_a_full_session_gives_the_tab_views_named_after_it_in_the_blueprint(tab, sessions):
    session = sessions["full"]
    views = tab.views(session)
    assert views, f"{tab.name}: nothing to show in a session with models, predictions and scores"
    assert all(v.name == tab.name or v.name.startswith(f"{tab.name} · ") for v in views), [v.name for v in views]
    shown = [t.name for t in session_blueprint(session).root_container.contents]
    assert all(v.name in shown for v in views)


@pytest.mark.parametrize("tab", TABS, ids=NAMES)
def test_the_tab_shows_only_what_was_logged(tab, sessions):
    for which in ("full", "bare"):
        session = sessions[which]
        for view in (v for container in tab.views(session) for v in _views(container)):
            assert _logged(str(view.origin), session.entities), (which, view.name, view.origin)
            queries = [view.contents] if isinstance(view.contents, str) else list(view.contents or ())
            for query in queries:  # "$origin/**" (rerun's default) is the origin's subtree
                path = str(query).removeprefix("+ ").removesuffix("/**").replace("$origin", str(view.origin))
                assert _logged(path, session.entities), (which, view.name, query)


def test_a_session_without_a_model_shows_its_trials_and_nothing_of_a_model(sessions):
    shown = [t.name for t in session_blueprint(sessions["bare"]).root_container.contents]
    assert "states" in shown and "inputs & variability" in shown
    assert not any(name.startswith(("predictions", "objective")) for name in shown)
