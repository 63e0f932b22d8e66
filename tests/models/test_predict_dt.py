"""``predict`` steps at the model's dt: demonstrations at another dt are refused, or resampled when asked."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from workbench.cli import main
from workbench.errors import ModelError
from workbench.models import HumanBehaviorModel
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings

MODEL_DT = 0.1


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Demonstrations at dt = 0.05 s and a model fitted on the same trials resampled to dt = 0.1 s."""
    d = tmp_path_factory.mktemp("predict_dt")
    fine = simulate_landings("CS1", 4, seed=2)
    coarse = fine.resample(MODEL_DT)
    model = HumanBehaviorModel(planar_quadrotor(dt=MODEL_DT), n_components=2, fit_objective=False,
                               noise_folds=0).fit(coarse)
    return {"fine": fine.save(d / "fine.parquet"), "coarse": coarse.save(d / "coarse.parquet"),
            "model": model.save(d / "m.npz"), "fine_set": fine, "coarse_set": coarse, "model_obj": model}


def test_model_refuses_or_resamples(files):
    model, fine, coarse = files["model_obj"], files["fine_set"], files["coarse_set"]
    assert model.demos_at_model_dt(coarse) is coarse
    with pytest.raises(ModelError, match=r"dt = 0.05 s but the model steps at dt = 0.1 s"):
        model.demos_at_model_dt(fine)
    back = model.demos_at_model_dt(fine, resample=True)
    assert back.dt == MODEL_DT and back.ids == fine.ids
    np.testing.assert_array_equal(back[0].x, coarse[0].x)


def test_cli_refuses_demonstrations_at_another_dt(files, tmp_path, capsys):
    out = tmp_path / "p.csv"
    code = main(["predict", str(files["fine"]), "--model", str(files["model"]), "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1, err
    assert str(files["fine"]) in err[0] and "dt = 0.05 s" in err[0] and "--resample" in err[0]
    assert not out.exists()


def test_cli_resamples_when_asked_and_labels_with_the_models_dt(files, tmp_path, capsys):
    out = tmp_path / "p.csv"
    horizon_s = 3.0
    fine = files["fine_set"]
    start = 8  # t = 0.40 s in the file: step 4 on the model's 0.1 s grid
    code = main(["predict", str(files["fine"]), "--model", str(files["model"]), "--resample", "--demo",
                 fine[1].id, "--start", str(start), "--horizon", str(horizon_s), "-o", str(out)])
    stdout = capsys.readouterr().out
    assert code == 0
    steps = int(round(horizon_s / MODEL_DT))
    k = int(round((fine[1].t[start] - fine[1].t[0]) / MODEL_DT))
    assert "resampled" in stdout and f"to the model's dt = {MODEL_DT:g} s" in stdout
    assert f"step {start} (t = {fine[1].t[start]:.3f} s) of {fine[1].id} is step {k} on the model's grid" in stdout
    assert f"predicted {steps} steps ({steps * MODEL_DT:.2f} s)" in stdout
    df = pd.read_csv(out)
    assert len(df) == steps + 1
    np.testing.assert_allclose(np.diff(df["t"].to_numpy()), MODEL_DT)
    demo = files["coarse_set"][1]
    pred = files["model_obj"].predict(demo.x[k], steps, target=demo.target, task_x0=demo.x[0])
    np.testing.assert_allclose(df[list(fine.state_names)].to_numpy(), pred.x, rtol=1e-9, atol=1e-12)


def test_cli_accepts_demonstrations_at_the_models_dt(files, tmp_path, capsys):
    out = tmp_path / "p.csv"
    assert main(["predict", str(files["coarse"]), "--model", str(files["model"]), "--horizon", "2", "-o",
                 str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "resampled" not in stdout and "predicted 20 steps (2.00 s)" in stdout


@pytest.mark.parametrize("command", ["view", "replay"])
def test_view_and_replay_refuse_demonstrations_at_another_dt(files, tmp_path, capsys, command):
    # their predictions step at the model's dt: drawn against a file at another dt they would be at the wrong times
    out = tmp_path / f"{command}.rrd"
    args = [command, str(files["fine"]), "--model", str(files["model"]), "--save", str(out)]
    if command == "replay":
        args += ["--no-wait"]
    code = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1, err
    assert str(files["fine"]) in err[0] and "dt = 0.05 s" in err[0] and "--resample" in err[0]
    assert not out.exists()
    assert main([*args, "--resample"]) == 0
    stdout = capsys.readouterr().out
    assert f"resampled {files['fine']} from dt = 0.05 s to the model's dt = {MODEL_DT:g} s" in stdout
    assert out.stat().st_size > 0
