"""The defaults that more than one place uses, defined once (python-control's ``config.defaults`` idea, as names).

The command line's options and the library's signatures import these; ``tests/test_defaults.py`` checks that
every signature named in :data:`USED_BY` has them and lists the ones not yet converted.
"""

from __future__ import annotations

__all__ = [
    "DT_PAPER_S", "HORIZON_S", "N_COMPONENTS", "N_STEPS", "OBJECTIVE_RESAMPLES", "ONLINE_HORIZON_S", "REG_COVAR",
    "STUDY_N_COMPONENTS", "TIMING",
]

N_COMPONENTS = 5  # G, Gaussian components of the TP-GMM / GMR (the paper's)
REG_COVAR = 0.5  # the variability model's covariance regularizer, in standardized units
# evaluate / report / demo choose G (1, 2 or 5) and the regularizer by cross-validation, and may fall back to K̂x
STUDY_N_COMPONENTS = "cv"
DT_PAPER_S = 0.05  # the planar quadrotor's sampling step in seconds (the paper's)
HORIZON_S = 3.0  # prediction horizon in seconds (the command line's --horizon; the paper's)
N_STEPS = round(HORIZON_S / DT_PAPER_S)  # the same horizon in grid steps at the paper's step: 60
ONLINE_HORIZON_S = 1.0  # the rollout at every step of `live` and `replay`, in seconds: short, for assistance
# resamples of the training trials for the intervals of the task objective and its weight ratios (fit, report,
# demo: --bootstrap)
OBJECTIVE_RESAMPLES = 100
# the pilot's reaction delay and lag (workbench.method.timing): identified per pilot and used by the gain, the
# objective and prediction ("identify"), or none, the paper's u = K x ("none"); `timing=` of a model, `--timing`
TIMING = "identify"
