"""The report: Markdown with PNG figures that exist and are non-trivial images; tables computed from the data."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread

from workbench.models import GMROnlyModel, HumanBehaviorModel, IOCOnlyModel
from workbench.plant.system import planar_quadrotor
from workbench.report.markdown import ReportInputs, write_report
from workbench.sim.landing import simulate_landings
from workbench.study import evaluate as ev
from workbench.study.pipeline import improvement_table

# no objective figure here: without bootstrap intervals no contrast of the objective is identified
# (tests/report/test_report_objective.py draws it)
FIGURES = ("demonstrations", "variability", "predictions", "rmse", "data_efficiency")
HORIZON = 30


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    plant = planar_quadrotor()
    train, test, models, baselines, tables = {}, {}, {}, {}, []
    for label in ("CS1", "CS2"):
        ds = simulate_landings(label, 9, seed=5)
        tr, te = ds.split(3, seed=0)
        train[label], test[label] = tr, te
        # no cross-validated noise scale (noise_folds=0): the figures and tables are the point here (1.1 s a label)
        fitted = {
            "proposed": HumanBehaviorModel(plant, n_components=3, noise_folds=0).fit(tr),
            "ioc_only": IOCOnlyModel(plant).fit(tr),
            "gmr_only": GMROnlyModel(plant, n_components=3, noise_folds=0).fit(tr),
        }
        models[label] = fitted["proposed"]
        baselines[label] = {k: v for k, v in fitted.items() if k != "proposed"}
        tables.append(ev.compare(fitted, te, n_steps=HORIZON, samples=20, seed=0).assign(label=label))
    table = pd.concat(tables, ignore_index=True)
    rmse = table[table["metric"].str.startswith("rmse_")]
    # a small data-efficiency table in the shape the study passes: label, method, n_train, value
    eff = pd.DataFrame(
        [
            {"label": lab, "method": m, "n_train": n, "value": float(v)}
            for lab in ("CS1", "CS2")
            for m in ("proposed", "ioc_only", "gmr_only")
            for n in (2, 4)
            for v in rmse[(rmse["label"] == lab) & (rmse["method"] == m) & (rmse["metric"] == "rmse_position")]["value"]
        ]
    )
    out = tmp_path_factory.mktemp("report")
    path = write_report(
        out,
        ReportInputs(train=train, test=test, models=models, baselines=baselines, rmse=rmse, efficiency=eff,
                     band=table[table["metric"] == "band_position"], n_steps=HORIZON, samples=20,
                     stats="| pair | t |\n|---|---|\n| a vs b | 1 |", notes=["a note"]),
    )
    return {"path": path, "dir": out, "rmse": rmse, "models": models, "train": train, "test": test,
            "baselines": baselines}


def test_report_links_every_figure(report):
    text = report["path"].read_text(encoding="utf-8")
    assert text.startswith("# Workbench report")
    for name in FIGURES:
        assert f"](figures/{name}.png)" in text
    assert "## Statistics of the comparison" in text
    assert "a note" in text
    assert "](figures/objective.png)" not in text and "No objective figure" in text


@pytest.mark.parametrize("name", FIGURES)
def test_figures_are_non_trivial_images(report, name):
    png = report["dir"] / "figures" / f"{name}.png"
    assert png.stat().st_size > 20_000, png.stat().st_size
    img = imread(png)
    assert img.ndim == 3 and img.shape[0] > 250 and img.shape[1] > 400
    gray = img[..., :3].mean(axis=2)
    # not blank: ink on a white page, and plenty of distinct shades (lines, text, heatmaps)
    assert gray.std() > 0.05
    assert (gray < 0.5).mean() > 0.002
    assert len(np.unique(np.round(gray, 2))) > 20


def test_improvement_table_is_computed_from_the_rmse(report):
    from workbench.study.paired import paired_differences

    rmse = report["rmse"]
    paired = paired_differences(rmse, "rmse_position", n_boot=500)
    tab = improvement_table(rmse, paired)
    row = tab[(tab["label"] == "CS1") & (tab["metric"] == "rmse_position")].iloc[0]
    sel = rmse[(rmse["label"] == "CS1") & (rmse["metric"] == "rmse_position")]
    means = sel.groupby(["method", "trial"])["value"].mean().groupby("method").mean()  # every trial weighs the same
    assert row["proposed"] == pytest.approx(means["proposed"])
    assert row["IOC-only"] == pytest.approx(means["ioc_only"])
    d = next(d for d in paired if d.label == "CS1" and d.baseline == "ioc_only")
    assert d.change == pytest.approx(1 - means["proposed"] / means["ioc_only"])
    assert row["vs IOC-only"] == d.sentence()  # the words come from the interval, not from the two means
    assert "vs IOC-only" not in improvement_table(rmse).columns  # no interval, no comparison in words
    # a metric the differences were not computed on says so in its cells, never "nan"
    other = tab[tab["metric"] != "rmse_position"]
    assert len(other) and (other[[c for c in tab.columns if c.startswith("vs ")]] == "—").all().all()


def test_objective_table_matches_the_model(report):
    text = report["path"].read_text(encoding="utf-8")
    o = report["models"]["CS2"].objective_
    assert f"{o.alpha:.3g}" in text
    assert f"{o.M_normalized[2, 2]:.3g}" in text  # the attitude weight Q_φφ


def test_the_calibration_figure_names_each_sigma_level_once_without_overlap():
    from scipy.stats import norm

    from workbench.report.markdown import fig_calibration

    levels = np.arange(0.25, 3.01, 0.25)
    nominal = norm.cdf(levels) - norm.cdf(-levels)
    rows = [{"label": lab, "input": inp, "n_sigma": c, "nominal": p, "coverage": min(1.0, p * f)}
            for lab in ("CS1", "CS2") for inp, f in (("u1", 0.97), ("u2", 1.02))
            for c, p in zip(levels, nominal, strict=True)]
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = fig_calibration(pd.DataFrame(rows))
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in fig.axes:
        named = [t for t in ax.texts if t.get_text() in ("1σ", "2σ", "3σ")]
        assert sorted(t.get_text() for t in named) == ["1σ", "2σ", "3σ"]  # once per panel, not per input
        boxes = [t.get_window_extent(renderer) for t in named]
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                assert not boxes[i].overlaps(boxes[j]), (named[i].get_text(), named[j].get_text())


@pytest.mark.parametrize("name", FIGURES)
def test_every_figure_is_also_written_as_svg_and_pdf(report, name):
    svg = (report["dir"] / "figures" / f"{name}.svg").read_text(encoding="utf-8")
    assert "<svg" in svg and svg.rstrip().endswith("</svg>")
    assert (report["dir"] / "figures" / f"{name}.pdf").read_bytes().startswith(b"%PDF")


def test_the_statistics_tables_are_written_as_csv_and_latex(report):
    from workbench.study.scores import heldout_scores

    tables = report["dir"] / "tables"
    comparison = pd.read_csv(tables / "comparison.csv")
    expected = improvement_table(report["rmse"])
    np.testing.assert_allclose(comparison["proposed"], expected["proposed"], rtol=1e-12)
    scores = pd.read_csv(tables / "heldout_scores.csv")
    rmse = report["rmse"]
    mine = heldout_scores(rmse)
    mine = mine[mine["metric"].str.startswith("rmse_")].reset_index(drop=True)
    shown = scores[scores["metric"].str.startswith("rmse_")].reset_index(drop=True)
    np.testing.assert_allclose(shown["value"], mine["value"], rtol=1e-12)
    for name in ("comparison", "heldout_scores", "data_efficiency"):
        assert r"\begin{tabular}" in (tables / f"{name}.tex").read_text(encoding="utf-8")
    text = report["path"].read_text(encoding="utf-8")
    assert "## Held-out prediction error" in text and "tables/heldout_scores.csv" in text


def test_saving_a_figure_leaves_its_layout_engine_as_it_was(tmp_path):
    """The vector copies reuse the PNG's layout by switching the engine off while they are written; the caller's
    figure gets its engine back."""
    from matplotlib.figure import Figure

    from workbench.report.figure_files import save_figure

    fig = Figure(layout="constrained")
    fig.subplots().plot([0, 1], [0, 1])
    save_figure(fig, tmp_path / "f.png")
    assert fig.get_constrained_layout() and (tmp_path / "f.svg").is_file() and (tmp_path / "f.pdf").is_file()


def test_the_report_gives_no_interval_from_too_few_test_trials(report, tmp_path):
    """3 test trials per strategy (fewer than min_units), 6 pooled: the comparison's cells, the verdicts and the
    paired differences' CSV have no interval for each strategy, with the count in words (the previous main printed
    intervals from 3 trials), and the pooled rows of 6 trials theirs (in the CSV)."""
    from workbench.study.paired import min_units, paired_differences
    from workbench.study.pipeline import verdicts

    rmse, models = report["rmse"], report["models"]
    n = rmse[rmse["label"] == "CS1"]["trial"].nunique()
    assert n < min_units() <= rmse["trial"].nunique()
    paired = paired_differences(rmse, "rmse_position", n_boot=500)
    words = f"no interval ({n} test trials; {min_units()} needed)"
    path = write_report(tmp_path, ReportInputs(
        train=report["train"], test=report["test"], models=models, baselines=report["baselines"], rmse=rmse,
        n_steps=HORIZON, samples=0, paired=paired,
        verdicts=verdicts(paired, "rmse_position")))
    text = path.read_text(encoding="utf-8")
    rows = {line.split("|")[1].strip(): line for line in text.splitlines()
            if line.startswith("| ") and "rmse_position" in line}
    for label in ("CS1", "CS2"):
        assert words in rows[label] and " %]" not in rows[label]
    assert all(words in line for line in text.splitlines() if "not shown to be better" in line)
    csv = pd.read_csv(tmp_path / "tables" / "paired_differences.csv")
    few = csv[csv["label"] != "all"]
    assert few["lo"].isna().all() and few["hi"].isna().all() and (few["no_interval"] == words.removeprefix(
        "no interval (").removesuffix(")")).all()
    assert csv.loc[csv["label"] == "all", "lo"].notna().all()  # the check can fail: 6 pooled trials give theirs
