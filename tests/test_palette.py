"""One meaning per colour (issue 38): every role its own colours, the methods told apart by readers with a red-green
colour-vision deficiency, and every figure drawing each method in its own line style and marker.

The simulation is Machado, Oliveira & Fernandes (2009) at full severity (:data:`workbench.palette.CVD_MATRICES`);
colours count as distinct at a CIE76 difference of :data:`DISTINCT` or more.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from workbench import palette
from workbench.models.registry import REGISTRY

#: CIE76 difference from which two colours read as two at a glance (2.3 is just noticeable)
DISTINCT = 15.0
DEFICIENCIES = tuple(palette.CVD_MATRICES)


def _closest_pair(colors, deficiency=None):
    seen = [c if deficiency is None else palette.simulate(c, deficiency) for c in colors]
    return min(palette.delta_e(a, b) for a, b in itertools.combinations(seen, 2))


def test_no_two_roles_share_a_colour():
    owner: dict[tuple[int, int, int], str] = {}
    for role, colors in palette.ROLES.items():
        for c in colors:
            assert owner.setdefault(tuple(c), role) == role, f"{c} is both {owner[tuple(c)]} and {role}"


def test_method_colours_are_far_from_every_other_role():
    # a strategy's orange must not read as a method at a glance: CS1's ŵ beside IOC-only's prediction
    for role, colors in palette.ROLES.items():
        if role == "method":
            continue
        for m in REGISTRY:
            near = min(palette.delta_e(m.colour, c) for c in colors)
            assert near >= DISTINCT, f"{m.title}'s colour is {near:.1f} from a {role} colour"


@pytest.mark.parametrize("recorded", [palette.RECORDED_PAPER, palette.RECORDED_SCREEN], ids=["paper", "screen"])
@pytest.mark.parametrize("deficiency", [None, *DEFICIENCIES])
def test_methods_and_the_recording_stay_distinct_under_colour_blindness(recorded, deficiency):
    colors = [m.colour for m in REGISTRY] + [recorded]
    assert _closest_pair(colors, deficiency) >= DISTINCT


def test_the_check_fails_for_the_old_tab10_methods():
    """The check can fail: the methods' tab10 colours before issue 38 (proposed green, IOC-only red) became one
    olive under deuteranopia."""
    old = [(44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75), (40, 40, 40)]
    assert _closest_pair(old) >= DISTINCT  # apart for normal vision …
    assert _closest_pair(old, "deuteranopia") < DISTINCT  # … not for a deuteranope


def test_simulation_matches_the_published_matrix():
    # Machado 2009 keeps white white and maps pure red to a dark olive for deuteranopia (its matrix's first column)
    assert np.allclose(palette.simulate((255, 255, 255), "deuteranopia"), (255, 255, 255), atol=1.0)
    r, g, b = palette.simulate((255, 0, 0), "deuteranopia")
    assert r > b and g > b and abs(r - g) < 40


def test_every_method_has_its_own_line_style_and_marker():
    assert len({m.dash for m in REGISTRY}) == len(REGISTRY)
    assert len({m.marker for m in REGISTRY}) == len(REGISTRY)


def test_strategies_stay_apart():
    assert _closest_pair(palette.STRATEGY_COLORS) >= DISTINCT


@pytest.mark.parametrize("deficiency", [None, *DEFICIENCIES])
def test_the_testbeds_outcomes_stay_apart_under_colour_blindness(deficiency):
    from workbench.collect.task import OUTCOMES

    assert set(palette.OUTCOME_COLORS) == set(OUTCOMES)
    assert _closest_pair(palette.OUTCOME_COLORS.values(), deficiency) >= DISTINCT


# -- every figure draws a method in its registry style -------------------------------------------------------------
class _Pred:
    def __init__(self, x):
        self.x = x


def _lines_by_label(fig):
    out = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            out.setdefault(line.get_label(), []).append(line)
        for c in ax.containers:  # an error bar's data line carries its container's label
            if hasattr(c, "lines") and c.lines[0] is not None:
                out.setdefault(c.get_label(), []).append(c.lines[0])
    return out


def _check(lines, titles):
    from matplotlib.colors import to_hex
    from matplotlib.lines import Line2D

    for m in REGISTRY:
        if m.title not in titles:
            continue
        assert lines.get(m.title), f"{m.title} is not drawn"
        for line in lines[m.title]:
            assert to_hex(line.get_color()) == m.colour_hex
            # the dash pattern, not its name: a fifth method's dashes are a tuple (matplotlib names four styles)
            assert line._unscaled_dash_pattern == Line2D([], [], linestyle=m.dash)._unscaled_dash_pattern, m.title
            assert line.get_marker() == m.marker, m.title


def test_figures_draw_each_method_in_its_style(tmp_path):
    from workbench.data.demonstrations import Demonstration
    from workbench.report.figures import fig_data_efficiency, fig_predictions

    rng = np.random.default_rng(0)
    demo = Demonstration(t=np.arange(20) * 0.1, x=rng.normal(size=(20, 2)), u=rng.normal(size=(20, 1)),
                         meta={"id": "t1", "label": "A"})
    preds = {m.name: _Pred(rng.normal(size=(11, 2))) for m in REGISTRY}
    fig = fig_predictions({"A": (demo, preds)}, ["p", "q"], 0.1)
    _check(_lines_by_label(fig), {m.title for m in REGISTRY})
    rows = [{"label": "A", "method": m.name, "n_train": n, "trial": f"t{k}", "value": float(rng.random())}
            for m in REGISTRY for n in (2, 4, 8) for k in range(3)]
    fig = fig_data_efficiency(pd.DataFrame(rows))
    _check(_lines_by_label(fig), {m.title for m in REGISTRY})
    # one key entry per name: "recorded" was listed twice
    labels = [t.get_text() for t in fig.legends[0].get_texts()] if fig.legends else []
    assert len(labels) == len(set(labels))
