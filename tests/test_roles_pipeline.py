"""Vehicle roles end to end (issue 9): a plant without roles and a 4-state plant with roles run every step of the
pipeline; generic code names no state; the plant never sees a test trial; persistence is in every comparison."""

from __future__ import annotations

import io
import re
import tokenize
import tomllib
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.linalg import solve_discrete_are

from workbench.cli import main
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.roles import Roles
from workbench.models import HumanBehaviorModel, PersistenceModel, load_model, make_models
from workbench.plant.system import LinearSystem, planar_quadrotor
from workbench.study import evaluate as ev
from workbench.study.input_prediction import INPUT_METRICS
from workbench.study.pipeline import run_study, verdicts

REPO = Path(__file__).resolve().parents[1]
DT = 0.1


# -- two small plants and their operators --------------------------------------------------------------------
def _lqr_gain(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A stabilizing gain in the workbench's ``u = K x`` convention (any would do; LQR is one line)."""
    Q, R = np.eye(A.shape[0]), np.eye(B.shape[1])
    P = solve_discrete_are(A, B, Q, R)
    return -np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)


def _demos(plant: LinearSystem, n_trials: int, n_steps: int, seed: int, labels=("A",)) -> DemonstrationSet:
    """Closed-loop trials of ``u = K x + w`` with autocorrelated operator variability ``w`` and process noise."""
    rng = np.random.default_rng(seed)
    A, B = plant.A, plant.B
    K = _lqr_gain(A, B)
    n, m = B.shape
    out = []
    for j in range(n_trials):
        x = rng.uniform(-2.0, 2.0, size=n)
        w = np.zeros(m)
        X, U = [], []
        for _ in range(n_steps):
            w = 0.8 * w + 0.2 * rng.normal(size=m)
            u = K @ x + w
            X.append(x)
            U.append(u)
            x = A @ x + B @ u + 0.01 * rng.normal(size=n)
        label = labels[j % len(labels)]
        out.append(Demonstration(DT * np.arange(n_steps), np.array(X), np.array(U),
                                 {"id": f"{label}-{j:02d}", "label": label}))
    return DemonstrationSet(out, plant.state_names, plant.input_names, DT, roles=plant.roles)


def roleless_plant() -> LinearSystem:
    """Three states, one input, no roles: nothing says what any state is."""
    A = np.array([[1.0, DT, 0.0], [0.0, 0.95, DT], [0.0, 0.0, 0.9]])
    B = np.array([[0.0], [0.0], [DT]])
    return LinearSystem(A, B, DT, ("a", "b", "c"), ("u",))


def double_integrators() -> LinearSystem:
    """Two double integrators ``p'' = a`` with roles position = (p1, p2), velocity = (v1, v2)."""
    I2 = np.eye(2)
    A = np.block([[I2, DT * I2], [np.zeros((2, 2)), I2]])
    B = np.vstack([0.5 * DT**2 * I2, DT * I2])
    roles = Roles(position=("p1", "p2"), velocity=("v1", "v2"), units={"p1": "m", "p2": "m", "v1": "m/s",
                                                                        "v2": "m/s"})
    return LinearSystem(A, B, DT, ("p1", "p2", "v1", "v2"), ("a1", "a2"), roles=roles)


PLANTS = {"roleless": roleless_plant, "double_integrators": double_integrators}


@pytest.fixture(scope="module", params=sorted(PLANTS))
def plant_case(request):
    plant = PLANTS[request.param]()
    return request.param, plant, _demos(plant, n_trials=12, n_steps=40, seed=1)


def _cli(*argv: str) -> str:
    buf = io.StringIO()
    with redirect_stdout(buf):
        code = main(list(argv))
    assert code == 0, buf.getvalue()
    return buf.getvalue()


# -- the whole pipeline --------------------------------------------------------------------------------------
def test_every_pipeline_step_runs_on_the_plant(plant_case, tmp_path, monkeypatch):
    from workbench.report import figure_files

    name, plant, ds = plant_case
    demos = tmp_path / "demos.parquet"
    ds.save(demos)
    # the roles' path through each command, not the objective's resampling (tests/cli, tests/method) nor the
    # figures' vector copies (tests/report): those were four fifths of this test's time
    common = ("--n-components", "2", "--plant", "identify")
    no_resampling = ("--bootstrap", "0")
    monkeypatch.setattr(figure_files, "VECTOR_FORMATS", ())

    # fit: the model file keeps the roles
    model_file = tmp_path / "model.npz"
    _cli("fit", str(demos), "-o", str(model_file), *common, *no_resampling)
    model = load_model(model_file)
    assert model.plant.roles == ds.roles

    # predict: one row per step, every state named
    pred_file = tmp_path / "pred.csv"
    _cli("predict", "--model", str(model_file), str(demos), "--horizon", "1", "-o", str(pred_file))
    pred = pd.read_csv(pred_file)
    assert len(pred) == round(1 / DT) + 1 and set(ds.state_names) <= set(pred.columns)

    # evaluate: persistence among the methods, metrics from the roles (or every state without them)
    results = tmp_path / "results.csv"
    out = _cli("evaluate", str(demos), *common, "--samples", "10", "--no-efficiency", "--horizon", "1",
               "-o", str(results))
    table = pd.read_csv(results)
    assert set(table.loc[~table["metric"].isin(INPUT_METRICS), "method"]) == {"proposed", "ioc_only", "gmr_only",
                                                                             "persistence"}
    assert "persistence" in out
    blocks = ev.metric_blocks(plant)
    assert {f"rmse_{b}" for b in blocks} <= set(table["metric"])
    if plant.roles:
        assert set(blocks) == {"position", "velocity"}
    else:
        assert set(blocks) == {"state"} | {f"state_{s}" for s in plant.state_names}
    assert not table[table["method"] == "persistence"]["metric"].str.startswith("band_").any()

    # view: a recording of the demonstrations with the model's predictions
    rrd = tmp_path / "view.rrd"
    _cli("view", str(demos), "--model", str(model_file), "--horizon", "1", "--samples", "5", "--save", str(rrd))
    assert rrd.is_file() and rrd.stat().st_size > 0

    # report: the comparison table has a persistence column and a "vs persistence" change
    report_dir = tmp_path / "report"
    _cli("report", str(demos), "-o", str(report_dir), *common, *no_resampling, "--samples", "10", "--efficiency",
         "4", "--repeats", "1", "--horizon", "1")
    text = (report_dir / "report.md").read_text()
    assert "persistence" in text and "vs persistence" in text


def test_persistence_is_constant_velocity_with_roles_and_holds_the_state_without(plant_case):
    name, plant, ds = plant_case
    model = PersistenceModel(plant).fit(ds)
    x0 = ds[0].x[5]
    H = 7
    p = model.predict(x0, H, samples=20)
    expected = np.tile(x0, (H + 1, 1))
    for pos, vel in zip(plant.r.position, plant.r.velocity, strict=True):
        expected[:, pos] = x0[pos] + DT * np.arange(H + 1) * x0[vel]
    np.testing.assert_allclose(p.x, expected, atol=1e-12)
    assert p.x_bands is None  # no noise model: no band rather than a zero-width one


def test_persistence_model_file_round_trip(tmp_path):
    plant = double_integrators()
    ds = _demos(plant, n_trials=3, n_steps=20, seed=10)
    model = PersistenceModel(plant).fit(ds)
    back = load_model(model.save(tmp_path / "p.npz"))
    assert isinstance(back, PersistenceModel) and back.plant.roles == plant.roles
    x0 = ds[2].x[3]
    np.testing.assert_array_equal(back.predict(x0, 9).x, model.predict(x0, 9).x)


def test_a_goal_rotation_needs_the_plane_it_turns():
    from workbench.errors import ModelError
    from workbench.method.frames import FrameSpec, goal_frame

    with pytest.raises(ModelError, match="position_idx"):
        goal_frame(np.zeros(4), 1, phi=0.3)
    with pytest.raises(ModelError, match="position_idx"):
        FrameSpec(("start", "goal"), angle_index=2)
    np.testing.assert_array_equal(goal_frame(np.zeros(4), 1).T, np.eye(5))  # no angle: no rotation, no plane


def test_full_state_rmse_without_roles():
    plant = roleless_plant()
    ds = _demos(plant, n_trials=4, n_steps=30, seed=2)
    model = PersistenceModel(plant).fit(ds)
    H = 10
    table = ev.compare({"persistence": model}, ds, n_steps=H)
    d = ds[1]
    err = np.tile(d.x[0], (H, 1)) - d.x[1 : H + 1]  # the held state against the record, steps 1..H
    got = table[(table["trial"] == d.id)].set_index("metric")["value"]
    assert got["rmse_state"] == pytest.approx(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    for j, s in enumerate(plant.state_names):
        assert got[f"rmse_state_{s}"] == pytest.approx(np.sqrt(np.mean(err[:, j] ** 2)))
    assert ev.primary_metric(plant) == "rmse_state"
    assert ev.primary_metric(double_integrators()) == "rmse_position"


def test_model_without_roles_has_no_goal_rotation_and_roles_survive_the_file(tmp_path):
    plant = roleless_plant()
    ds = _demos(plant, n_trials=8, n_steps=30, seed=3)
    m = HumanBehaviorModel(plant, n_components=2, fit_objective=False, noise_folds=0).fit(ds)
    assert m.frame_spec_.angle_index is None
    quad = planar_quadrotor()
    from workbench.method.variability import resolve_frame_spec

    spec = resolve_frame_spec(("start", "goal"), quad.state_names, roles=quad.r)
    assert spec.angle_index == quad.r.heading and spec.position_idx == quad.r.plane
    di = double_integrators()
    m2 = HumanBehaviorModel(di, n_components=2, fit_objective=False, noise_folds=0).fit(_demos(di, 8, 30, 4))
    m2.save(tmp_path / "m.npz")
    assert load_model(tmp_path / "m.npz").plant.roles == di.roles


def test_unknown_target_moves_positions_with_the_start():
    """Trained on last states (no targets), a new task's goal positions are its start plus the mean travel."""
    plant = double_integrators()
    ds = _demos(plant, n_trials=8, n_steps=30, seed=5)
    model = PersistenceModel(plant).fit(ds)
    travel = np.mean([d.x[-1] - d.x[0] for d in ds], axis=0)
    x0 = np.array([10.0, -3.0, 0.5, 0.0])
    goal = model.default_target(x0)
    pos = list(plant.r.position)
    np.testing.assert_allclose(goal[pos], x0[pos] + travel[pos])
    others = [j for j in range(plant.n) if j not in pos]
    np.testing.assert_allclose(goal[others], np.mean([d.x[-1] for d in ds], axis=0)[others])
    roleless = PersistenceModel(roleless_plant()).fit(_demos(roleless_plant(), 4, 20, 6))
    np.testing.assert_allclose(roleless.default_target(np.full(3, 9.0)), roleless.target_)


# -- no leakage ----------------------------------------------------------------------------------------------
def _perturbed(ds: DemonstrationSet, trial_id: str) -> DemonstrationSet:
    """The set with one trial's states and inputs changed (same id, same place in the set)."""
    out = []
    for d in ds:
        if d.id == trial_id:
            rng = np.random.default_rng(9)
            d = Demonstration(d.t, d.x + rng.normal(size=d.x.shape), d.u + rng.normal(size=d.u.shape), d.meta)
        out.append(d)
    return ds.with_demos(out)


def test_study_identifies_the_plant_from_training_trials_only():
    plant = double_integrators()
    ds = _demos(plant, n_trials=10, n_steps=30, seed=7)
    kwargs = dict(test_size=0.2, n_steps=5, n_components=2, samples=0, efficiency=(4,), repeats=1, seed=0)
    seen: list[set[str]] = []

    def identify(train: DemonstrationSet) -> LinearSystem:
        seen.append(set(train.ids))
        return LinearSystem.identify(train, structure="free")

    base = run_study(ds, identify, **kwargs)
    test_ids = {d.id for te in base.test.values() for d in te}
    train_ids = {d.id for tr in base.train.values() for d in tr}
    # the study's plant first, from its training trials; then each method-level split identifies its own from the
    # split's training part (issue 40 §1; that no split's test trial reaches it: tests/study/test_method_level.py)
    assert seen[0] == train_ids and not test_ids & train_ids
    assert len(seen) > 1 and all(len(ids) == len(train_ids) for ids in seen[1:]) and len(set(map(frozenset, seen))) > 1
    changed_test = run_study(_perturbed(ds, sorted(test_ids)[0]), identify, **kwargs)
    np.testing.assert_array_equal(changed_test.plant.A, base.plant.A)
    np.testing.assert_array_equal(changed_test.plant.B, base.plant.B)
    # the check can fail: a changed training trial does change the plant
    changed_train = run_study(_perturbed(ds, sorted(train_ids)[0]), identify, **kwargs)
    assert not np.array_equal(changed_train.plant.A, base.plant.A)
    # persistence is in the comparison and in the data-efficiency curve
    assert "persistence" in set(base.table["method"]) and "persistence" in set(base.efficiency["method"])
    assert "persistence" in base.baselines["A"]


def test_cli_identifies_the_plant_from_training_trials_only(tmp_path, monkeypatch):
    """``evaluate`` (split and per subject) hands the plant choice training trials only: no scored trial among them."""
    import workbench.plant.choice as choice

    plant = roleless_plant()
    ds = _demos(plant, n_trials=8, n_steps=30, seed=8)
    ds = ds.with_demos(d.with_meta(subject=f"s{j % 2}") for j, d in enumerate(ds))
    path = tmp_path / "demos.parquet"
    ds.save(path)
    seen: list[set[str]] = []
    real = choice.choose_plant

    def spy(data, *args, **kwargs):
        seen.append(set(data.ids))
        return real(data, *args, **kwargs)

    monkeypatch.setattr(choice, "choose_plant", spy)
    quick = ("--n-components", "2", "--plant", "identify", "--samples", "0", "--no-efficiency", "--horizon", "1")
    for extra in (("--holdout", "split"), ("--per-subject",)):
        seen.clear()
        out = tmp_path / f"results{len(extra)}.csv"
        _cli("evaluate", str(path), *quick, *extra, "-o", str(out))
        scored = set(pd.read_csv(out)["trial"])
        # with a random split, the study's plant comes first; the method-level splits that follow each identify
        # their own on the split's training part, which may hold the study's test trials but never the split's
        # (tests/study/test_method_level.py)
        study = seen[:1] if extra == ("--holdout", "split") else seen
        assert study and scored and all(not ids & scored for ids in study), (extra, seen, scored)


def test_per_subject_identifies_each_plant_without_the_held_out_trials():
    plant = double_integrators()
    parts = []
    for s in ("s1", "s2", "s3"):
        sub = _demos(plant, n_trials=4, n_steps=25, seed=int(s[1]))
        parts.append(sub.with_demos(d.with_meta(id=f"{s}-{d.id}", subject=s) for d in sub))
    ds = parts[0] + parts[1] + parts[2]
    seen: list[set[str]] = []

    def models_for_subject(train):
        seen.append(set(train.ids))
        return make_models(LinearSystem.identify(train, structure="free"), n_components=2)

    res = ev.per_subject(models_for_subject, ds, n_test=1, n_steps=5)
    tested = set(res.table["trial"])
    assert len(seen) == 3 and all(not ids & tested for ids in seen)
    assert "persistence" in res.groups and res.metric == "rmse_position"


# -- honest verdicts -----------------------------------------------------------------------------------------
def test_verdict_says_plainly_when_the_proposed_model_is_not_better():
    from workbench.study.paired import min_units, paired_differences

    rng = np.random.default_rng(0)
    rows = []
    for method, scale in (("proposed", 1.0), ("ioc_only", 0.9), ("gmr_only", 1.5), ("persistence", 2.0)):
        for t in range(min_units() + 2):  # enough test trials for an interval (fewer: tests/study/test_paired.py)
            rows.append((f"tr{t}", "L", 0, method, "rmse_position", scale * (1 + 0.01 * rng.random())))
    table = pd.DataFrame(rows, columns=["trial", "label", "start", "method", "metric", "value"])
    paired = paired_differences(table, "rmse_position", n_boot=500)
    lines = verdicts(paired, "rmse_position")
    ioc = next(d for d in paired if d.baseline == "ioc_only")
    assert ioc.hi < 0  # the proposed model is clearly worse here
    # the interval shows it worse: the verdict says so, with the interval, not only "not shown to be better"
    assert len(lines) == 1 and "persistence" not in lines[0] and "not shown" not in lines[0]
    worse = f"worse than IOC-only by {100 * -ioc.change:.0f} % [{100 * -ioc.hi:.0f} %, {100 * -ioc.lo:.0f} %]"
    assert worse in lines[0] and ioc.sentence().startswith("higher by")
    assert "these fitted models" in lines[0]  # which question the interval answers
    better = table.assign(value=np.where(table["method"] == "proposed", 0.5 * table["value"], table["value"]))
    assert verdicts(paired_differences(better, "rmse_position", n_boot=500), "rmse_position") == []


# -- no state is named or indexed in generic code --------------------------------------------------------------
EXEMPT = {"roles.py", "simulate.py", "sample_logs.py"}


def _state_names() -> set[str]:
    """Every state name the shipped plant and mappings use (computed, not listed here)."""
    names = set(planar_quadrotor().state_names)
    for toml in (REPO / "adapters" / "mappings").glob("*.toml"):
        names |= set(tomllib.loads(toml.read_text()).get("states", []))
    return names


def _source_without_planar_quadrotor(path: Path) -> str:
    """system.py minus the paper's plant (its roles and ``planar_quadrotor``), which may name its states."""
    text = path.read_text()
    if path.name == "system.py":
        start = text.index("PLANAR_QUADROTOR_ROLES = Roles(")
        text = text[:start]
    return text


def _offences(text: str, names: set[str]) -> list[str]:
    long_names = {s for s in names if len(s) > 1}
    short = "|".join(re.escape(s) for s in sorted(names - long_names))
    found = []
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.STRING:
            try:
                value = eval(tok.string, {})  # a literal: its value, prefixes and quotes resolved
            except Exception:  # noqa: BLE001 - f-strings and the like are not a bare name
                continue
            if value in long_names:
                found.append(f"line {tok.start[0]}: state name {tok.string}")
    patterns = [
        rf"\.index\(\s*['\"]({short})['\"]",  # names.index("x")
        rf"['\"]({short})['\"]\s+(not\s+)?in\s+\w*names",  # "x" in state_names
        rf"==\s*['\"]({short})['\"]",
        r"(position|velocity|pos|vel|plane|axes)\w*\s*(:[^=\n]*)?=\s*[(\[]\s*\d+\s*,\s*\d+\s*[)\]]",  # = (0, 1)
        r"(position|velocity|pos|vel|plane|axes)\w*['\"]?\s*,\s*[(\[]\s*\d+\s*,\s*\d+\s*[)\]]",  # get("pos…", (0, 1))
        r"[(\[]\s*\d+\s*,\s*\d+\s*[)\]]\s*#.*(position|velocity)",
        r"\"(position|velocity)\"\s*:\s*[(\[]\s*\d+\s*,",  # {"position": (0, 1)}
    ]
    for lineno, line in enumerate(text.splitlines(), 1):
        if any(re.search(pattern, line) for pattern in patterns):
            found.append(f"line {lineno}: {line.strip()}")
    return list(dict.fromkeys(found))


def test_generic_code_names_no_state_and_no_position_index():
    names = _state_names()
    assert {"phi", "xdot"} <= names  # the check below looks for what is really there
    bad = {}
    for path in sorted((REPO / "workbench").rglob("*.py")):
        if path.name in EXEMPT:
            continue
        offences = _offences(_source_without_planar_quadrotor(path), names)
        if offences:
            bad[str(path.relative_to(REPO))] = offences
    assert not bad, "generic code names a state or a position index; read the plant's roles instead:\n" + "\n".join(
        f"{p}: {o}" for p, offs in bad.items() for o in offs
    )


def test_the_state_name_check_catches_what_it_must():
    names = _state_names()
    caught = [
        'att = list(state_names).index("phi") if "phi" in state_names else None',
        'ix = names.index("x") if "x" in names else 0',
        'DEFAULT_BLOCKS = {"position": (0, 1), "velocity": (3, 4)}',
        "position_idx: tuple[int, int] = (0, 1),",
        'idx = tuple(getattr(self, "position_idx", (0, 1)))',
    ]
    for line in caught:
        assert _offences(line + "\n", names), line
    fine = ['ax.grid(alpha=0.3, axis="y")', 'for name in ("x", "u", "Sigma_u"):', "idx = system.r.position"]
    for line in fine:
        assert not _offences(line + "\n", names), line
