"""The command line shows each kind of warning once, and an inverse-LQR warning names what failed."""

from __future__ import annotations

import warnings

import pytest

from workbench.cli import app as cli_main
from workbench.method.inverse_lqr_sdp import _Attempt


def test_a_solution_that_fails_the_post_checks_is_not_called_optimal():
    text = _Attempt("CLARABEL", 2, "optimal", 0.98, 3e-3).describe()
    assert "failed the post-checks" in text and "status=optimal" not in text
    assert _Attempt("SCS", 2, "infeasible").describe() == "SCS stage 2: infeasible"


def test_repeated_warnings_print_once_with_a_count(capsys):
    shown = cli_main._Warnings()
    for k in range(11):
        shown.show(f"inverse LQR: stage 2 failed, error {k * 0.1:.3g}", UserWarning, __file__, 1)
    shown.show("something else entirely", RuntimeWarning, __file__, 2)
    shown.close()
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "warning: inverse LQR: stage 2 failed, error 0"
    assert err[1] == "warning: something else entirely"
    assert "10 more" in err[2] and len(err) == 3
    warnings.resetwarnings()


def test_warnings_of_one_cause_with_other_details_print_once(capsys):
    """A solver warning lists each attempt's status after its cause; resamples differ there, not in the cause (the
    demo opened with three 6-line copies of one inverse-LQR warning)."""
    shown = cli_main._Warnings()
    for status in ("infeasible", "user_limit", "solved (optimal_inaccurate) but failed M ⪰ I"):
        shown.show(f"inverse LQR: stage 2 failed with every solver; returning stage 1. CLARABEL: {status}",
                   UserWarning, __file__, 1)
    shown.show("inverse LQR: no objective passed the checks; nothing returned", UserWarning, __file__, 1)
    shown.close()
    err = capsys.readouterr().err.splitlines()
    assert err[0].endswith("CLARABEL: infeasible") and err[1].startswith("warning: inverse LQR: no objective")
    assert "2 more" in err[2] and len(err) == 3


def test_an_attempt_names_only_the_checks_it_failed(monkeypatch):
    """A solution that meets M ⪰ I but misses the forward check is described by the forward check alone, with the
    bound it broke (the README flight's warning once listed a passing λmin(M)=1 among the failures)."""
    import re

    import numpy as np

    from workbench.errors import SolverError
    from workbench.method import inverse_lqr_sdp as sdp
    from workbench.method.objective import forward_gain
    from workbench.plant.system import planar_quadrotor

    plant = planar_quadrotor()
    A, B = np.asarray(plant.A), np.asarray(plant.B)
    K, _ = forward_gain(A, B, np.eye(A.shape[0]), np.eye(B.shape[1]))
    monkeypatch.setattr(sdp, "forward_gain_tolerance", lambda alpha: 0.0)  # no error can meet it
    with pytest.raises(SolverError) as caught:
        sdp.InverseLQR(A, B, solvers=["CLARABEL"]).solve(K)
    text = str(caught.value).split("Attempts:", 1)[1]  # before it: the checks every solution must pass
    clauses = re.findall(r"failed (the forward check: gain error (\S+) > (\S+))", text)
    assert clauses, text
    for _, error, bound in clauses:
        assert float(error) > float(bound)
    assert "λmin(M)" not in text and "P ⪰ 0" not in text


@pytest.mark.slow
def test_the_readme_flights_identify_fit_warns_once_and_only_of_what_failed(external, tmp_path, capsys):
    """`workbench fit --plant identify` on the README's flight: each warning once, and every failure it lists a
    bound that was broken by the numbers it gives."""
    import re

    flight = external("dronekit_flight.tlog")
    demos = tmp_path / "flight.parquet"
    assert cli_main.main(["import", str(flight), "--mapping", "ardupilot_manual", "-o", str(demos)]) == 0
    capsys.readouterr()
    assert cli_main.main(["fit", str(demos), "--plant", "identify", "-o", str(tmp_path / "flight.npz")]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("warning:")]
    assert len(err) == len(set(err))
    assert not any("more of the warnings above" in ln for ln in err)
    for line in err:
        assert "=1," not in line.replace(" ", "")  # a passing λmin(M)=1 is no failure
        for error, bound in re.findall(r"gain error (\S+) > (\S+)", line):
            assert float(error) > float(bound)
        for value in re.findall(r"λmin\(M\) = (\S+) < 1", line):
            assert float(value) < 1


def test_the_closing_count_names_each_repeated_warning(capsys):
    """A fit of several plant groups warned "fitting on 2 distinct demonstration(s)" for its first group and then
    only "… and 84 more of the warnings above": which warning recurred, and how often, is said."""
    shown = cli_main._Warnings()
    causes = {"HumanBehaviorModel.fit: fitting on 2 distinct demonstration(s)": 3,
              "inverse LQR: the second stage failed with every solver": 5}
    for cause, n in causes.items():
        for k in range(n):
            shown.show(f"{cause}; detail {k}", UserWarning, __file__, 1)
    shown.show("a warning seen once", UserWarning, __file__, 1)
    shown.close()
    last = capsys.readouterr().err.splitlines()[-1]
    assert f"{sum(causes.values()) - len(causes)} more" in last
    for cause, n in causes.items():
        assert f"{n - 1} × {cause}" in last
    assert "seen once" not in last
    warnings.resetwarnings()
