"""The command line shows each kind of warning once, and an inverse-LQR warning names what failed."""

from __future__ import annotations

import warnings

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
