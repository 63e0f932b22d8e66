"""report.md says where the study's plant was held at its physics (the identification report's ``fixed:`` lines)."""

from __future__ import annotations

from types import SimpleNamespace


def test_the_report_says_a_plant_was_held_at_its_physics():
    # report.md never said a plant was held at g·dt; `fit` and `evaluate` print it in the report's `fixed:` lines
    from tests.plant.test_identification import _angle_flights
    from workbench.plant.choice import choose_plant
    from workbench.report.markdown import _held_plant_notes

    ds = _angle_flights(3.0, 0.0)  # one segment of four drifts against the tilt: the free fit fails its check
    plant = choose_plant(ds, "auto")
    (held,) = plant.identification.held
    assert held in plant.identification.fixed and "g·dt" in held
    assert _held_plant_notes(SimpleNamespace(plants={}, plant=plant)) == [f"plant fixed: {held}"]
    as_fitted = choose_plant(ds, "as-fitted")
    assert as_fitted.identification.held == () and _held_plant_notes(SimpleNamespace(plants={}, plant=as_fitted)) == []
    # leave-one-segment-out: each fold's plant from the other segments; the note counts the folds that held it
    folds = {d.id: choose_plant(ds.with_demos([e for e in ds if e.id != d.id]), "auto") for d in ds}
    n_held = sum(bool(p.identification.held) for p in folds.values())
    (note,) = _held_plant_notes(SimpleNamespace(plants=folds, plant=None))
    name = held.split(" (")[0]  # "A[xdot, phi] = 0.9807"
    assert note.startswith(f"plant fixed: {name} (g·dt) in {n_held} of the {len(ds)} folds' plants")
