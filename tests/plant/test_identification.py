"""The identification report's physical checks (workbench/plant/identification.py)."""

from __future__ import annotations

import pytest


def test_a_physics_check_outside_a_factor_2_is_a_warning_naming_the_pair_and_the_likely_cause():
    from workbench.plant.identification import GRAVITY, PhysicalCheck, _disagreement

    dt = 0.1
    check = PhysicalCheck("A[xdot, phi]", 0.2 * GRAVITY * dt, GRAVITY * dt, "g·dt")
    assert not check.within()
    text = _disagreement(check)
    assert text.startswith("A[xdot, phi] is 0.2 × g·dt")
    assert "heading frame" in text and "no GPS" in text


def test_data_that_do_not_excite_a_direction_are_refused_naming_it():
    import numpy as np
    import pytest

    from workbench.errors import ModelError
    from workbench.plant.system import LinearSystem
    from workbench.sim.modes import ModeVehicle, fly

    ds = fly(ModeVehicle(), "angle", seconds=10.0, n=3, seed=0)
    held = ds.with_demos([type(d)(d.t, d.x, np.c_[d.u[:, :1], np.zeros(len(d))], d.meta) for d in ds])
    with pytest.raises(ModelError, match=r"excite only 7 of 8 .*: u2 never moves \(0 in every sample\)"):
        LinearSystem.identify(held)
    twin = ds.with_demos([type(d)(d.t, d.x, np.c_[d.u[:, :1], 2.0 * d.u[:, :1]], d.meta) for d in ds])
    with pytest.raises(ModelError, match=r"excite only 7 of 8 .*combine to \(almost\) nothing along .*u1.*u2|"
                                         r"excite only 7 of 8 .*combine to \(almost\) nothing along .*u2.*u1"):
        LinearSystem.identify(twin)


def test_auto_identifies_the_plant_of_trials_flown_in_a_vehicle_s_flight_mode_at_the_paper_s_step():
    # a PX4 ULog through px4_manual is in the paper's layout at its 0.05 s; its trials carry the plant group of their
    # flight mode. `--plant auto` took the paper's 0.25 kg quadrotor for them (luk8426/flugdrohne's flights: ρ 1.18-1.38
    # on it); a real vehicle's trials get their own identified plant, the paper's own trials keep the paper's model
    import numpy as np

    from workbench.plant.choice import choose_plant
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.modes import ModeVehicle, fly

    paper = planar_quadrotor()
    flown = fly(ModeVehicle(), "angle", seconds=20.0, dt=paper.dt, n=2, seed=1)
    assert tuple(flown.state_names) == paper.state_names and flown.dt == paper.dt  # the paper's layout and step
    plant = choose_plant(flown, "auto")
    assert plant.identification is not None, "identified from the trials, with its report"
    assert not np.allclose(plant.B, paper.B)
    truth = ModeVehicle().plant("angle", paper.dt)
    np.testing.assert_allclose(plant.B, truth.B, atol=0.02)  # the vehicle's own stick response

    # without its flight mode (a log read through a mapping without a mode rule) it is still not the paper's
    # quadrotor: its plant does not reproduce its steps (the previous main gave it the paper's plant here)
    plain = flown.with_demos([type(d)(d.t, d.x, d.u, {"id": d.meta["id"]}) for d in flown])  # no flight mode
    again = choose_plant(plain, "auto")
    assert again.identification is not None and "not the paper's plant" in again.identification.describe()
    np.testing.assert_allclose(again.B, truth.B, atol=0.02)


def _dronekit_mapping(tmp_path):
    """A user's mapping of an ArduCopter telemetry log into the paper's layout at its 0.05 s, without a mode rule
    (so no plant group): the sticks are RC channels 1 and 3, 1000-2000 µs onto [-1, 1]."""
    path = tmp_path / "mine.toml"
    path.write_text(
        'name = "mine"\ndt = 0.05\nstates = ["x", "y", "phi", "xdot", "ydot", "phidot"]\ninputs = ["u1", "u2"]\n'
        '[roles]\nposition = ["x", "y"]\nvelocity = ["xdot", "ydot"]\nheading = "phi"\nvertical = "y"\n'
        '[channels]\nx = "LOCAL_POSITION_NED.y"\ny = { source = "LOCAL_POSITION_NED.z", transform = "ned_up" }\n'
        'phi = "ATTITUDE.roll"\nxdot = "LOCAL_POSITION_NED.vy"\n'
        'ydot = { source = "LOCAL_POSITION_NED.vz", transform = "ned_up" }\nphidot = "ATTITUDE.rollspeed"\n'
        'u1 = { source = "RC_CHANNELS.chan1_raw", scale = 0.002, offset = -3.0 }\n'
        'u2 = { source = "RC_CHANNELS.chan3_raw", scale = 0.002, offset = -3.0 }\n'
        '[segment]\ngap = 0.5\nmin_duration = 1.0\n', encoding="utf-8")
    return path


def test_auto_identifies_a_real_log_in_the_paper_s_layout_read_without_a_mode_rule(tmp_path):
    # dronekit_flight.tlog through a user's mapping: the paper's states and step, no flight mode, and the previous
    # main gave it the paper's 0.25 kg quadrotor; its recorded steps are not that plant's
    import re

    import numpy as np

    import adapters
    from tests.conftest import external_file
    from workbench.plant.choice import PAPER_RESIDUAL_RATIO, choose_plant, paper_reproduces
    from workbench.plant.system import planar_quadrotor

    paper = planar_quadrotor()
    ds = adapters.load(external_file("dronekit_flight.tlog"), str(_dronekit_mapping(tmp_path)))
    assert tuple(ds.state_names) == paper.state_names and ds.dt == paper.dt
    assert not any(d.meta.get("plant_group") for d in ds)
    # identified, not the paper's: and this mapping pairs the body roll with the world's east velocity on a vehicle
    # that turns, so the identified plant is refused for its physics; `--plant as-fitted` takes it as fitted
    from workbench.errors import ModelError

    with pytest.raises(ModelError, match=r"^the identified plant is not physics: A\[xdot, phi\]"):
        choose_plant(ds, "auto")
    plant = choose_plant(ds, "as-fitted")
    assert plant.identification is not None
    reproduced, why = paper_reproduces(ds, paper)
    assert not reproduced and f"not the paper's plant: {why}" in plant.identification.describe()
    # the ratio said is the residual sums' own, state by state
    x0 = np.vstack([d.x[:-1] for d in ds])
    x1 = np.vstack([d.x[1:] for d in ds])
    u = np.vstack([d.u[:-1] for d in ds])
    z = np.hstack([x0, u, np.ones((len(u), 1))])
    fitted = ((x1 - z @ np.linalg.lstsq(z, x1, rcond=None)[0]) ** 2).sum(axis=0)
    ratios = ((x1 - x0 @ paper.A.T - paper.clip(u) @ paper.B.T) ** 2).sum(axis=0) / fitted
    worst = int(np.argmax(ratios))
    assert ratios[worst] > PAPER_RESIDUAL_RATIO
    said = re.search(r"leaves ([\d.e+]+) times the one-step residual of a plant fitted to these (\d+) steps "
                     r"in (\w+)", why)
    assert float(said.group(1)) == pytest.approx(ratios[worst], rel=1e-3)
    assert int(said.group(2)) == len(u) and said.group(3) == ds.state_names[worst]


@pytest.mark.parametrize("source", ["simulated", "landing_s00.tlog", "landing_s01.mcap", "landing_s02.csv"])
def test_auto_keeps_the_paper_s_plant_for_its_own_trials(source):
    # simulated here (another seed than any measurement of the ratio's default) or the sample logs read back: the
    # paper's plant reproduces their steps up to what storing them rounded
    from pathlib import Path

    import numpy as np

    import adapters
    from workbench.plant.choice import choose_plant
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.landing import simulate_landings

    paper = planar_quadrotor()
    if source == "simulated":
        ds = simulate_landings("CS2", 6, seed=23)
    else:
        ds = adapters.load(Path(__file__).resolve().parents[2] / "sample_logs" / source, "planar_quadrotor")
    plant = choose_plant(ds, "auto")
    assert plant.identification is None
    np.testing.assert_array_equal(plant.A, paper.A)
    np.testing.assert_array_equal(plant.B, paper.B)


def _angle_flights(k_first: float, k_rest: float):
    """Simulated STABILIZE flights whose recorded across-velocity is off the tilt physics: each segment's xdot gets
    ``−k · g·dt · Σ phi`` (the first segment ``k_first``, the others ``k_rest``), so it responds to the lean at
    ``(1 − k) · g·dt`` — a velocity that drifts against the tilt (a dead-reckoned segment) or, with every segment at
    k = 2, a lean of the wrong sign."""
    import numpy as np

    from workbench.plant.identification import GRAVITY
    from workbench.sim.modes import ModeVehicle, fly

    ds = fly(ModeVehicle(), "angle", seconds=20.0, n=4, seed=0)
    ip, iv = ds.state_names.index("phi"), ds.state_names.index("xdot")

    def off(d, k):
        x = d.x.copy()
        x[:, iv] -= k * GRAVITY * ds.dt * np.concatenate([[0.0], np.cumsum(x[:-1, ip])])
        return type(d)(d.t, x, d.u, d.meta)

    return ds.with_demos([off(d, k_first if i == 0 else k_rest) for i, d in enumerate(ds)])


def test_a_plant_that_fails_its_physics_check_is_held_at_the_physics_where_the_data_agree():
    import re

    # beastayyg 0039 / erle 15-12-2014/16 STABILIZE: the free fit put A[xdot, phi] at 0.09 and 0.24 × g·dt (16's short
    # segment split the tilt between the lean and the stick, B[xdot, u1] 0.63), and fit wrote a model on that plant
    import numpy as np

    from workbench.plant.choice import choose_plant
    from workbench.plant.identification import identify_plant

    ds = _angle_flights(3.0, 0.0)  # one segment of four drifts against the tilt
    (free,) = identify_plant(ds, hold=False)[3].checks
    assert not free.within()  # the free fit fails its check
    plant = choose_plant(ds, "auto")
    report = plant.identification
    (check,) = report.checks
    i, j = free.at
    assert plant.A[i, j] == free.expected and check.within() and not report.contradiction
    assert report.free_checks[0].value == free.value  # the free fit is kept in the report
    held = [f for f in report.fixed if f.startswith(f"{free.name} = {free.expected:.4g}")]
    assert len(held) == 1
    assert f"(held; the free fit's {free.value:.4g}" in report.describe()
    assert not any("tilt would" in w for w in report.warnings)
    # the rule: the held plant's held-out squared error is not above the free fit's beyond its interval
    m = re.search(r"RMSE of xdot ([\d.e+-]+) held, ([\d.e+-]+) free; held [\d.e+-]+ % MSE \[[\d.e+-]+ %, "
                  r"[\d.e+-]+ %\]; mean squared difference ([\d.e+-]+) "
                  r"\[([\d.e+-]+), ([\d.e+-]+)\] \(95 % HAC interval over (\d+) held-out samples\)", held[0])
    assert m is not None and float(m.group(4)) <= 0.0
    assert float(m.group(1)) == pytest.approx(report.one_step_rmse[i], rel=2e-3)
    assert float(m.group(2)) == pytest.approx(identify_plant(ds, hold=False)[3].one_step_rmse[i], rel=2e-3)
    # --plant as-fitted takes the least-squares plant as fitted
    assert choose_plant(ds, "as-fitted").A[i, j] == free.value
    assert np.isfinite(plant.A).all()


def test_a_plant_whose_data_contradict_the_physics_is_refused_in_one_line():
    # flug ZweiterFlugtag log_23 (A[xdot, phi] −3 × g·dt), peterbarker_1 (0.22 ×): held at g·dt the plant predicts the
    # held-out velocity worse than the free fit, so no pilot model on either describes this vehicle
    import re

    from workbench.errors import ModelError
    from workbench.plant.choice import choose_plant
    from workbench.plant.identification import identify_plant

    ds = _angle_flights(2.0, 2.0)  # every segment: the velocity answers the lean with the wrong sign
    (free,) = identify_plant(ds, hold=False)[3].checks
    assert free.ratio < 0
    with pytest.raises(ModelError) as info:
        choose_plant(ds, "auto")
    line = str(info.value)
    assert "\n" not in line
    assert line.startswith(f"the identified plant is not physics: {free.name} is {free.ratio:.2g} × g·dt")
    m = re.search(r"predicts the held-out xdot worse \(held-out one-step RMSE of xdot ([\d.e+-]+) held, ([\d.e+-]+) "
                  r"free; held \+[\d.e+-]+ % MSE \[\+[\d.e+-]+ %, \+[\d.e+-]+ %\]; "
                  r"mean squared difference ([\d.e+-]+) \[([\d.e+-]+), ([\d.e+-]+)\]", line)
    assert m is not None and float(m.group(1)) > float(m.group(2)) and float(m.group(4)) > 0.0
    assert "`--plant as-fitted` takes the plant as fitted" in line
    assert choose_plant(ds, "as-fitted").A[free.at] == free.value  # the override


def test_the_held_plant_is_judged_worse_only_beyond_its_autocorrelation_robust_interval():
    # one-step errors of a plant are autocorrelated: the comparison's interval must widen with it (Newey–West), so
    # a difference an iid interval would call significant is not a refusal
    import numpy as np
    from scipy import stats

    from workbench.plant.identification import _held_vs_free

    rng = np.random.default_rng(5)
    n = 600
    free = rng.normal(size=(n, 1))
    slow = np.zeros(n)
    for k in range(1, n):  # an AR(1) disturbance with 0.95 per step: slowly wandering errors
        slow[k] = 0.95 * slow[k - 1] + 0.3 * rng.normal()
    held = np.sqrt(np.maximum(free[:, 0] ** 2 + slow + 0.02, 0.0))[:, None]
    d = held[:, 0] ** 2 - free[:, 0] ** 2
    iid = stats.ttest_1samp(d, 0.0).confidence_interval(0.95)
    verdict = _held_vs_free(held, free)
    assert verdict.mean_held - verdict.mean_free == pytest.approx(d.mean())
    assert verdict.hi - verdict.lo > iid.high - iid.low  # wider than the interval that ignores the autocorrelation
    # the same wandering difference, shifted so that the iid interval lies above 0 by half its width: the HAC
    # interval, wider by the autocorrelation, still holds 0, so the held plant is not judged worse
    large = 5.0 + free  # squared errors far from 0, so that the shift leaves every held error real
    d0 = slow - slow.mean()
    half = (lambda c: (c.high - c.low) / 2.0)(stats.ttest_1samp(d0, 0.0).confidence_interval(0.95))
    shifted = np.sqrt(large[:, 0] ** 2 + d0 + 1.5 * half)[:, None]
    d = shifted[:, 0] ** 2 - large[:, 0] ** 2
    assert stats.ttest_1samp(d, 0.0).confidence_interval(0.95).low > 0.0  # an iid interval would refuse the plant
    close = _held_vs_free(shifted, large)
    assert close.lo < 0.0 < close.hi and not close.worse
    # errors twice as large everywhere: worse beyond any interval
    assert _held_vs_free(2.0 * free, free).worse
    assert not _held_vs_free(free, free).worse  # the same forecasts: no difference


def test_the_held_versus_free_comparison_says_too_little_in_words_and_gives_the_relative_difference():
    # nofold.py: a plant whose folds could not be fitted printed "RMSE of xdot nan held, nan free (no held-out samples
    # to compare them by)", and one held-out sample "1 held, 0.5 free (no held-out samples …)"
    import re

    import numpy as np

    from workbench.plant.identification import _held_vs_free

    none = _held_vs_free(np.empty((0, 1)), np.empty((0, 1))).describe("xdot")
    assert "nan" not in none and none.startswith("no held-out samples of xdot")
    one = _held_vs_free(np.array([[1.0]]), np.array([[0.5]])).describe("xdot")
    assert "too few held-out samples to compare: 1" in one and "no held-out" not in one
    rng = np.random.default_rng(3)
    free = rng.normal(size=(400, 1))
    held = 1.1 * free + 0.1 * rng.normal(size=(400, 1))
    verdict = _held_vs_free(held, free)
    text = verdict.describe("xdot")
    m = re.search(r"; held ([+-][\d.e+-]+) % MSE \[([+-][\d.e+-]+) %, ([+-][\d.e+-]+) %\]", text)
    assert m is not None
    mse_held, mse_free = float(np.mean(held**2)), float(np.mean(free**2))
    assert float(m.group(1)) == pytest.approx(100.0 * (mse_held - mse_free) / mse_free, rel=5e-3)
    assert float(m.group(2)) == pytest.approx(100.0 * verdict.lo / mse_free, rel=5e-3)
    assert float(m.group(3)) == pytest.approx(100.0 * verdict.hi / mse_free, rel=5e-3)


def test_a_horizon_no_held_out_piece_lasts_is_said_in_words_not_nan():
    # erle 15-12-2014/16's STABILIZE group (82 samples in 3 held-out pieces, a 3 s horizon of 30 steps) printed
    # "3 s (30 steps): plant nan, persistence nan" and a column of nan; its position rows printed 4.975e-17
    from workbench.plant.identification import identify_plant
    from workbench.sim.modes import ModeVehicle, fly

    ds = fly(ModeVehicle(), "angle", seconds=10.0, n=3, seed=0)
    horizon = 2 * ds.dt * max(len(d) for d in ds)  # longer than any piece
    _, _, _, report = identify_plant(ds, horizon_s=horizon)
    text = report.describe()
    assert "nan" not in text.lower() and "e-1" not in text
    assert f"({report.n_steps} steps): not scored: no held-out piece lasts that long" in text
    _, _, _, scored = identify_plant(ds, horizon_s=1.0)  # pieces of 10 s hold a 1 s horizon
    assert "not scored" not in scored.describe() and "—" not in scored.describe()


def test_an_rmse_cell_says_diverges_and_its_rounding_floor_is_the_states_own_scale():
    # an RMSE that overflowed printed "—" (as if not scored); the floor below which a value is rounding was 1e-12
    # whatever the state's units, so a state measured in small units printed a real error of 1e-13 as 0
    import numpy as np

    from workbench.plant.identification import ROUNDING, _rms, _rmse_cell

    assert _rmse_cell(np.inf, 1.0) == "diverges" and _rmse_cell(np.nan, 1.0) == "—"
    tiny_state = 1e-9  # a state whose standard deviation is 1e-9 of its unit
    error = 10.0 * ROUNDING * tiny_state
    assert float(_rmse_cell(error, tiny_state)) == pytest.approx(error, rel=1e-3)
    assert _rmse_cell(0.1 * ROUNDING * tiny_state, tiny_state) == "0"
    with np.errstate(over="ignore", invalid="ignore"):
        overflowed = np.array([[np.inf, 1.0], [-np.inf, 2.0]]) - np.array([[np.inf, 0.0], [0.0, 0.0]])
    rms = _rms([overflowed], 2)
    assert np.isinf(rms[0]) and rms[1] == pytest.approx(np.sqrt(2.5))  # scored and overflowed: diverges, not "—"
    assert np.isnan(_rms([], 2)).all()  # not scored


def test_the_report_of_a_plant_from_one_segment_says_segment():
    """A PX4 log with one POSCTL segment printed "1008 sample pairs, 1 segments"."""
    from workbench.plant.system import LinearSystem
    from workbench.sim.modes import ModeVehicle, fly

    one = fly(ModeVehicle(), "angle", seconds=20.0, n=1, seed=0)
    first = LinearSystem.identify(one).identification.describe().splitlines()[0]
    assert f"sample pairs, {len(one)} segment;" in first, first
    two = fly(ModeVehicle(), "angle", seconds=10.0, n=2, seed=0)
    assert f"sample pairs, {len(two)} segments;" in LinearSystem.identify(two).identification.describe().splitlines()[0]


def test_a_fixed_row_s_one_step_score_is_said_to_be_persistence_s_rule():
    """The plant's table printed "y 0.02324 0.02324" (plant, persistence) without a word: a fixed kinematic row
    moves the position on at its recorded velocity, which is persistence's rule, so the two agree by construction."""
    from workbench.plant.system import LinearSystem
    from workbench.sim.modes import ModeVehicle, fly

    report = LinearSystem.identify(fly(ModeVehicle(), "angle", seconds=10.0, n=3, seed=0)).identification
    fixed = {f.split("[", 1)[0] for f in report.fixed}
    assert fixed  # the test is about a plant with fixed rows
    rows = {ln.split()[0]: ln for ln in report.describe().splitlines()[1:] if ln.startswith("  ") and
            ln.split()[0] in report.state_names}
    for name, line in rows.items():
        assert line.endswith(" *") == (name in fixed), line
        if name in fixed:
            assert any(ln.startswith("  * a fixed row") for ln in report.describe().splitlines())
            i = report.state_names.index(name)
            assert report.one_step_rmse[i] == report.one_step_rmse_persistence[i]
