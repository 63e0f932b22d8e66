"""The report's prediction figure keeps the recorded trial in view where a rollout diverges: a LOITER log's IOC-only
rollout reached 4e7 m and set the axes, so the recorded track and every other method were a flat line at 0."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from workbench.data.demonstrations import Demonstration
from workbench.data.roles import Roles
from workbench.defaults import DIVERGED_FACTOR
from workbench.report.figures import fig_predictions


def test_a_diverging_rollout_is_named_and_leaves_the_axes_to_the_recorded_trial():
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.normal(size=(40, 2)), axis=0)
    demo = Demonstration(t=np.arange(40) * 0.1, x=x, u=rng.normal(size=(40, 1)), meta={"id": "t1", "label": "A"})
    lo, hi = x.min(axis=0), x.max(axis=0)
    span = hi - lo
    steady = SimpleNamespace(x=x[:21] + 0.1, x_bands=None)
    blow = x[:21].copy()
    blow[-1] = hi + 100 * DIVERGED_FACTOR * span  # far beyond the recorded range at the horizon's end
    roles = Roles(position=("p", "q"), vertical="q")  # a plane: the path panel first, then p(t) and q(t)
    fig = fig_predictions({"A": (demo, {"proposed": steady, "ioc_only": SimpleNamespace(x=blow, x_bands=None)})},
                          ["p", "q"], 0.1, roles)
    path, *times = fig.axes[:3]
    for ax, j in zip(times, (0, 1), strict=True):
        assert ax.get_ylim() == (lo[j] - span[j], hi[j] + span[j])
    assert path.get_xlim() == (lo[0] - span[0], hi[0] + span[0])
    labels = {t.get_text() for t in fig.legends[0].get_texts()}
    assert "IOC-only (diverges, off the axes)" in labels and "proposed" in labels

    # without a diverging rollout the axes are matplotlib's own (they hold every line)
    fig = fig_predictions({"A": (demo, {"proposed": steady})}, ["p", "q"], 0.1, roles)
    assert fig.axes[1].get_ylim()[1] >= max(x[:21, 0].max(), steady.x[:, 0].max())


def test_a_long_trial_id_stays_inside_the_prediction_figure():
    """The report of erle_pxf_copter_10-11-2014_105.BIN titled its path panel "rle_pxf_copter_10-11-2014_105-000
    (all): path, 3.0 s": the title ran past the figure's left edge."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    rng = np.random.default_rng(2)
    x = np.cumsum(rng.normal(size=(40, 2)), axis=0)
    trial = "erle_pxf_copter_10-11-2014_105-000"
    demo = Demonstration(t=np.arange(40) * 0.1, x=x, u=rng.normal(size=(40, 1)), meta={"id": trial, "label": "all"})
    roles = Roles(position=("p", "q"), vertical="q")
    fig = fig_predictions({"all": (demo, {"proposed": SimpleNamespace(x=x[:31] + 0.1, x_bands=None)})},
                          ["p", "q"], 0.1, roles)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    title = fig.axes[0].title
    assert trial in title.get_text().replace("\n", "")
    box, page = title.get_window_extent(renderer), fig.bbox
    assert page.x0 <= box.x0 and box.x1 <= page.x1, (box, page)
