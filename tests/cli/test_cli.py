"""The ``workbench`` command through a subprocess: every command's happy path on sample_logs/, and bad input.

Bad input (missing file, corrupt log, wrong mapping, a model file from a newer version) must exit non-zero with
ONE line on stderr naming the cause — never a traceback — and leave no output file behind.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from workbench.data.demonstrations import DemonstrationSet
from workbench.models import load_model, make_models

REPO = Path(__file__).resolve().parents[2]
SAMPLE_LOGS = REPO / "sample_logs"
LOGS = sorted(p for p in SAMPLE_LOGS.glob("*") if p.suffix in (".tlog", ".mcap", ".csv"))

pytestmark = pytest.mark.skipif(len(LOGS) < 3, reason=f"{SAMPLE_LOGS} lacks the sample logs (make sample-logs)")


def wb(*args: str, cwd: Path | None = None, timeout: float = 180) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "160", "PYTHONWARNINGS": "ignore::DeprecationWarning"}
    return subprocess.run(
        [sys.executable, "-m", "workbench", *args], capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env
    )


def ok(result: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert result.returncode == 0, f"exit {result.returncode}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    return result


def one_line_error(result: subprocess.CompletedProcess, *needles: str) -> str:
    """Exit ≠ 0, stderr is exactly one line starting 'error:', naming every needle, and no traceback."""
    assert result.returncode != 0, result.stdout
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: "), lines[0]
    assert "Traceback" not in result.stderr + result.stdout
    for needle in needles:
        assert needle.lower() in lines[0].lower(), (needle, lines[0])
    return lines[0]


def rrd_verify(path: Path) -> None:
    exe = Path(sys.executable).with_name("rerun")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "rerun"]
    r = subprocess.run([*cmd, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """The sample logs imported and a CS1 model fitted, made once per run: under pytest-xdist by the first worker
    whose test needs them while it holds a file lock (the other waits, then reads them; tests/conftest.py names the
    run's shared folder); each test writes its own outputs beside them."""
    shared = os.environ.get("WORKBENCH_TEST_SHARED")
    d = Path(shared) / "cli" if shared else tmp_path_factory.mktemp("cli")
    d.mkdir(parents=True, exist_ok=True)
    with open(d / ".lock", "a+") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (d / ".made").is_file():
            ok(wb("import", *map(str, LOGS), "--mapping", "planar_quadrotor", "-o", str(d / "demos.parquet")))
            # the model file is the point here; the objective's resampled intervals (2/3 of the fit's time) have tests
            ok(wb("fit", str(d / "demos.parquet"), "--label", "CS1", "--n-components", "3", "--bootstrap", "0",
                  "-o", str(d / "cs1.npz")))
            (d / ".made").touch()
    return d


# -- happy paths -----------------------------------------------------------------------------------------
def test_help_teaches_every_command():
    r = ok(wb("--help"))
    for cmd in ("simulate", "inspect", "import", "fit", "predict", "evaluate", "view", "replay", "report", "demo"):
        assert cmd in r.stdout
    r = ok(wb("fit", "--help"))
    assert "example:" in r.stdout and "--n-components" in r.stdout


@pytest.mark.parametrize("log", LOGS, ids=[p.suffix for p in LOGS])
def test_inspect_each_format(log):
    r = ok(wb("inspect", str(log)))
    assert log.name in r.stdout
    assert "stream" in r.stdout and "rate" in r.stdout


def test_import_joins_every_format(work):
    ds = DemonstrationSet.load(work / "demos.parquet")
    expected = sum(len(__import__("adapters").load(p)) for p in LOGS)
    assert len(ds) == expected
    assert set(ds.labels) == {"CS1", "CS2"}
    assert len({d.meta.get("subject") for d in ds}) == len(LOGS)
    r = ok(wb("inspect", str(work / "demos.parquet")))
    assert f"{len(ds)} trials" in r.stdout


def test_simulate_writes_parquet_and_logs(tmp_path):
    ok(wb("simulate", "--strategy", "CS2", "--trials", "3", "--seed", "4", "-o", str(tmp_path / "s.parquet")))
    ds = DemonstrationSet.load(tmp_path / "s.parquet")
    assert len(ds) == 3 and ds.labels == ["CS2"]
    ok(wb("simulate", "--strategy", "CS1", "--trials", "2", "-o", str(tmp_path / "s.csv")))
    ok(wb("inspect", str(tmp_path / "s.csv")))


def test_fit_chooses_components_by_bic(tmp_path):
    ok(wb("simulate", "--strategy", "CS1", "--trials", "4", "-o", str(tmp_path / "s.parquet")))
    r = ok(wb("fit", str(tmp_path / "s.parquet"), "--n-components", "bic", "--bootstrap", "0",
              "-o", str(tmp_path / "m.npz")))
    g = load_model(tmp_path / "m.npz").n_components_
    assert f"chose {g} components by BIC" in r.stdout


def test_fit_writes_a_loadable_model(work):
    model = load_model(work / "cs1.npz")
    assert model.K_.shape == (2, 6)
    assert model.labels_ == ("CS1",)
    assert model.n_components_ == 3


def test_predict_equals_model_predict(work):
    out = work / "pred.csv"
    ds = DemonstrationSet.load(work / "demos.parquet").by_label("CS1")
    demo = ds[1]
    ok(wb("predict", str(work / "demos.parquet"), "--model", str(work / "cs1.npz"), "--demo", demo.id,
          "--start", "5", "--horizon", "1.0", "-o", str(out)))
    df = pd.read_csv(out)
    model = load_model(work / "cs1.npz")
    H = int(round(1.0 / ds.dt))
    pred = model.predict(demo.x[5], H, target=demo.target, task_x0=demo.x[0])
    assert len(df) == H + 1
    np.testing.assert_allclose(df[list(ds.state_names)].to_numpy(), pred.x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(df["t"].to_numpy(), demo.t[5] + ds.dt * np.arange(H + 1))


def test_evaluate_prints_the_comparison(work):
    out = work / "results.csv"
    r = ok(wb("evaluate", str(work / "demos.parquet"), "--label", "CS2", "--n-components", "3", "--samples", "0",
              "--no-efficiency", "--horizon", "2", "-o", str(out)))
    # the metric by its name (the raw key "rmse_position" went with the means table its percentages misread)
    assert "position RMSE" in r.stdout and "IOC-only" in r.stdout and "persistence" in r.stdout
    df = pd.read_csv(out)
    from workbench.study.input_prediction import INPUT_METRICS, NO_PILOT

    methods = {"proposed", "ioc_only", "gmr_only", "persistence"}
    assert set(df.loc[~df["metric"].isin(INPUT_METRICS), "method"]) == methods
    # the pilot's own input: every model that predicts one, beside the plant with no pilot (issue 40 §4)
    assert set(df.loc[df["metric"].isin(INPUT_METRICS), "method"]) == (methods - {"persistence"}) | set(NO_PILOT)
    assert set(df["label"]) == {"CS2"}


def test_view_writes_a_verified_recording(work):
    out = work / "view.rrd"
    r = ok(wb("view", str(work / "demos.parquet"), "--model", f"CS1={work / 'cs1.npz'}", "--horizon", "1",
              "--samples", "10", "--save", str(out)))
    assert f"rerun {out}" in r.stdout
    rrd_verify(out)
    from rerun.chunk import RrdReader

    paths = {c.entity_path for c in RrdReader(out).stream()}
    cs1 = DemonstrationSet.load(work / "demos.parquet").by_label("CS1")[0].id
    assert f"/demos/{cs1}/variability/u1/gmr" in paths
    assert f"/demos/{cs1}/predictions/from_0/proposed/y" in paths
    assert "/models/CS1/Q" in paths


def test_view_of_a_raw_log(tmp_path):
    out = tmp_path / "raw.rrd"
    ok(wb("view", str(LOGS[0]), "--save", str(out)))
    rrd_verify(out)


def test_replay_no_wait(work):
    out = work / "replay.rrd"
    r = ok(wb("replay", str(work / "demos.parquet"), "--model", str(work / "cs1.npz"), "--no-wait",
              "--horizon", "0.5", "--save", str(out)))
    assert "real time" in r.stdout and "3σ band" in r.stdout
    rrd_verify(out)


def test_report_writes_markdown_and_figures(work, tmp_path, monkeypatch):
    from workbench.cli import main
    from workbench.report import figure_files

    out = tmp_path / "report"
    # in this process (the report's own command line is run as a program by test_claims.py), the PNGs only: the
    # vector copies are tests/report's
    monkeypatch.setattr(figure_files, "VECTOR_FORMATS", ())
    assert main(["report", str(work / "demos.parquet"), "-o", str(out), "--label", "CS1", "--n-components", "3",
                 "--samples", "10", "--efficiency", "5,10", "--repeats", "1", "--horizon", "2", "--bootstrap", "6",
                 "-q"]) == 0
    text = (out / "report.md").read_text()
    for fig in ("demonstrations", "objective", "variability", "predictions", "rmse", "data_efficiency"):
        assert (out / "figures" / f"{fig}.png").stat().st_size > 10_000
        assert f"figures/{fig}.png" in text
    assert "Statistics of the comparison" in text and "Which number answers which question" in text
    assert "3 subjects" in text  # the sample logs hold three subjects (too few to resample: said)
    # one strategy: no mixed model (it is read for the strategies only); the methods compared as methods
    assert "Mixed-effects model" not in text and "corrected resampled t" in text


def test_demo_end_to_end():
    # the demo the viewer tests share (tests/viewer/viewer_recordings.py: 12 resamples of the objective intervals,
    # two points of the data-efficiency curve, every phase runs), checked here rather than run a second time
    out, said = _recordings().demo_run()
    assert f"rerun {out / 'demo.rrd'}" in said
    for f in ("demo.rrd", "report.md", "demos.parquet", "results.csv", "models/CS1.npz", "models/CS2.npz",
              "figures/predictions.png", "figures/data_efficiency.png"):
        assert (out / f).is_file(), f
    rrd_verify(out / "demo.rrd")
    load_model(out / "models" / "CS2.npz")
    # the phases it prints account for its whole time (issue 18): the top-level parts add up to the total, the
    # strategies' own phases (in brackets, process time of the workers) aside
    done = next(line for line in said.splitlines() if line.startswith("done in"))
    total = float(re.match(r"done in ([\d.]+) s", done).group(1))
    top = re.sub(r"\[[^\]]*\]", "", done.split("(", 1)[1])
    parts = [float(v) for v in re.findall(r"([\d.]+) s\b", top)]
    assert len(parts) >= 8 and abs(sum(parts) - total) <= 0.05 * len(parts) + 1e-9, done


def _recordings():
    """tests/viewer/viewer_recordings.py, the run's shared CLI recordings (pytest's importlib mode: by path)."""
    import importlib.util

    path = REPO / "tests" / "viewer" / "viewer_recordings.py"
    spec = importlib.util.spec_from_file_location("_viewer_recordings", path)
    loader = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(loader)
    return loader.load()


# -- bad input -------------------------------------------------------------------------------------------
def test_missing_file(tmp_path):
    out = tmp_path / "m.npz"
    one_line_error(wb("fit", str(tmp_path / "nope.parquet"), "-o", str(out)), "nope.parquet", "no such file")
    assert not out.exists()
    one_line_error(wb("inspect", str(tmp_path / "nope.tlog")), "nope.tlog")
    one_line_error(wb("predict", "--model", str(tmp_path / "nope.npz"), "--x0", "0,1,0,0,0,0", "-o",
                      str(tmp_path / "p.csv")), "nope.npz")


def test_debug_shows_the_traceback(tmp_path):
    r = wb("--debug", "fit", str(tmp_path / "nope.parquet"), "-o", str(tmp_path / "m.npz"))
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_corrupt_logs(tmp_path):
    garbage = tmp_path / "garbage.tlog"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    out = tmp_path / "x.parquet"
    one_line_error(wb("import", str(garbage), "-o", str(out)), "garbage.tlog")
    assert not out.exists()
    mcap = next(p for p in LOGS if p.suffix == ".mcap")
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 3])
    r = wb("import", str(truncated), "-o", str(out))
    if r.returncode == 0:  # a reader may recover the complete part of a truncated file: then it must say so
        assert out.exists()
        assert "warning: " in r.stderr and "skipped" in r.stderr
    else:
        one_line_error(r, "truncated.mcap")
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    one_line_error(wb("import", str(empty), "-o", str(out)), "empty.csv")


def test_wrong_mapping(tmp_path):
    tlog = next(p for p in LOGS if p.suffix == ".tlog")
    out = tmp_path / "x.parquet"
    one_line_error(wb("import", str(tlog), "--mapping", "px4_manual", "-o", str(out)))
    one_line_error(wb("import", str(tlog), "--mapping", "no_such_mapping", "-o", str(out)), "no_such_mapping")
    assert not out.exists()


def test_model_file_from_a_newer_version(work, tmp_path):
    with np.load(work / "cs1.npz", allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays["__header__"].tobytes().decode())
    header["version"] = int(header["version"]) + 1
    arrays["__header__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    newer = tmp_path / "newer.npz"
    with open(newer, "wb") as fh:
        np.savez(fh, **arrays)
    out = tmp_path / "p.csv"
    one_line_error(wb("predict", str(work / "demos.parquet"), "--model", str(newer), "-o", str(out)),
                   "newer.npz", "newer")
    assert not out.exists()
    one_line_error(wb("replay", str(work / "demos.parquet"), "--model", str(newer), "--no-wait", "--save",
                      str(tmp_path / "r.rrd")), "newer")


def test_bad_options_are_one_line(work, tmp_path):
    one_line_error(wb("replay", str(work / "demos.parquet"), "--model", str(work / "cs1.npz"), "--demo", "nope",
                      "--no-wait", "--save", str(tmp_path / "r.rrd")), "nope")
    one_line_error(wb("fit", str(work / "demos.parquet"), "--label", "CS9", "-o", str(tmp_path / "m.npz")), "CS9")
    not_a_model = tmp_path / "not_a_model.npz"
    not_a_model.write_text("hello")
    one_line_error(wb("predict", "--model", str(not_a_model), "--x0", "0,1,0,0,0,0", "-o", str(tmp_path / "p.csv")),
                   "not_a_model.npz")


def test_fit_bootstrap_prints_the_intervals_of_ioc_bootstrap(tmp_path):
    from workbench.method.resampling import bootstrap
    from workbench.plant.system import planar_quadrotor

    ok(wb("simulate", "--strategy", "CS1", "--trials", "8", "-o", str(tmp_path / "s.parquet")))
    r = ok(wb("fit", str(tmp_path / "s.parquet"), "--n-components", "2", "--bootstrap", "12",
              "-o", str(tmp_path / "m.npz")))
    assert "resamples fitted, 95 % intervals: the objective's percentiles, K̂'s t over trials" in r.stdout
    model = load_model(tmp_path / "m.npz")
    gain = model.gain_method_  # the estimator the fit chose (printed with its reason)
    assert f"gain {gain} (" in r.stdout
    # the resamples decide the default gain's rule again (the pilot's timing where it fits, else the paper's gain)
    from workbench.models.fitting import timing_setting

    expected = bootstrap(DemonstrationSet.load(tmp_path / "s.parquet"), planar_quadrotor(), n_boot=12, seed=0,
                         method="iv" if gain == "liml" else gain, timing=timing_setting(model))
    assert "pilot timing: " in r.stdout
    lines = {line.split(":")[0].strip(): line for line in r.stdout.splitlines() if ": " in line}
    names = ("x", "y", "phi", "xdot", "ydot", "phidot")
    for key, lo, hi in (("diag Q/λmax", expected.Q_diag_lo, expected.Q_diag_hi),
                        ("K̂ row u1", expected.K_lo[0], expected.K_hi[0])):
        for name, a, b in zip(names, lo, hi, strict=True):
            assert f"{name} [{a:.3g}, {b:.3g}]" in lines[key]


def test_evaluate_per_subject_prints_the_repeated_measures_statistics(tmp_path):
    from workbench.plant.system import planar_quadrotor
    from workbench.study import evaluate

    ok(wb("simulate", "--strategy", "CS2", "--trials", "5", "--subjects", "3", "-o", str(tmp_path / "s.parquet")))
    r = ok(wb("evaluate", str(tmp_path / "s.parquet"), "--per-subject", "--n-components", "2", "--horizon", "2",
              "-o", str(tmp_path / "ps.csv")))
    plant = planar_quadrotor()
    expected = evaluate.per_subject(lambda: make_models(plant, n_components=2, random_state=0),
                                    DemonstrationSet.load(tmp_path / "s.parquet"), n_steps=40, seed=0)
    out = " ".join(r.stdout.split())  # a terminal wraps
    assert f"ours: {expected.rm_anova}" in out
    # the paper's own analysis beside it, labelled as the paper's: one-way over its three methods, Student t-tests
    assert f"the paper's analysis, as the paper ran it: {expected.paper_anova}" in out
    assert expected.paper_anova.groups == ("proposed", "ioc_only", "gmr_only") and "F(2, 6)" in out
    assert "pairwise two-sample Student t-tests" in out and out.count("(Student)") == 3
    assert "the difference: the paper's ANOVA treats each method's 3 subjects as 3 independent groups" in out
    assert set(pd.read_csv(tmp_path / "ps.csv")["subject"]) == set(expected.subjects)
    # 3 held-out trials, one per subject: fewer than min_units, so no paired interval and no verdict by a number
    from workbench.models.registry import METHOD_TITLES
    from workbench.study.paired import min_units

    n = len(expected.subjects)
    assert n < min_units()
    for base in ("ioc_only", "gmr_only", "persistence"):
        said = f"proposed vs {METHOD_TITLES[base]}: no interval ({n} test trials; {min_units()} needed) ({n} held-out"
        assert said in out
    assert "worse than" not in out and "lower by" not in out and "higher by" not in out
