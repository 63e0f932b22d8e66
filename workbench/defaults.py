"""The defaults that more than one place uses, defined once (python-control's ``config.defaults`` idea, as names).

The command line's options and the library's signatures import these; ``tests/test_defaults.py`` checks that
every signature named in :data:`USED_BY` has them and lists the ones not yet converted.
"""

from __future__ import annotations

__all__ = [
    "DEFAULT_N_COMPONENTS", "DT_PAPER_S", "GAIN_RESAMPLES", "HORIZON_S", "NOISE_HORIZON_S", "N_COMPONENTS",
    "N_STEPS", "OBJECTIVE_RESAMPLES", "ONLINE_HORIZON_S", "ONLINE_N_STEPS", "PAIRED_RESAMPLES", "PAPER_N_COMPONENTS",
    "PAPER_SETTINGS", "PLANT_CHOICES", "REG_COVAR", "STUDY_SAMPLES", "TIMING", "DIVERGED_FACTOR",
]

N_COMPONENTS = 5  # G, Gaussian components of the TP-GMM / GMR (the paper's)
REG_COVAR = 0.5  # the variability model's covariance regularizer, in standardized units
# The one default model (workbench.models.default_model): `fit`, `evaluate`, `report`, `demo` and the Python API
# (make_model, make_models, run_study) choose G (1, 2 or 5) and the regularizer by cross-validation, and fall back
# to K̂x where the variability model does not lower the held-out error
DEFAULT_N_COMPONENTS = "cv"
# the paper's settings by name (--n-components paper): G = N_COMPONENTS, reg_covar = REG_COVAR, no cross-validation
PAPER_SETTINGS = "paper"
# --plant: the paper's planar quadrotor, identified from the data (held at its physics where a check fails and the
# held-out data do not show the held plant worse), auto (the paper's for its own trials), or the identified plant as
# fitted (no hold; not to be confused with identification's structure "free", every entry fitted)
PLANT_CHOICES = ("auto", "paper", "identify", "as-fitted")
DT_PAPER_S = 0.05  # the planar quadrotor's sampling step in seconds (the paper's)
HORIZON_S = 3.0  # prediction horizon in seconds (the command line's --horizon; the paper's)
N_STEPS = round(HORIZON_S / DT_PAPER_S)  # the same horizon in grid steps at the paper's step: 60
ONLINE_HORIZON_S = 1.0  # the rollout at every step of `live` and `replay`, in seconds: short, for assistance
# resamples of the training trials for the intervals of the task objective and its weight ratios (fit, report,
# demo: --bootstrap)
OBJECTIVE_RESAMPLES = 100

# the name of the default before issue 40, when only the studies used it
STUDY_N_COMPONENTS = DEFAULT_N_COMPONENTS
# the pilot's reaction delay and lag (workbench.method.timing): identified per pilot and used by the gain, the
# objective and prediction ("identify"), or none, the paper's u = K x ("none"); `timing=` of a model, `--timing`
TIMING = "identify"
PAPER_N_COMPONENTS = N_COMPONENTS  # G of the method paper's quadrotor study (the default is the paper's)
NOISE_HORIZON_S = HORIZON_S  # seconds over which a model's input noise is judged (its rollouts' horizon)
ONLINE_N_STEPS = round(ONLINE_HORIZON_S / DT_PAPER_S)  # the online rollout in grid steps: 20
STUDY_SAMPLES = 100  # Monte Carlo samples per predicted trial in a study's scores
PAIRED_RESAMPLES = 4000  # bootstrap resamples of a paired method difference's interval
GAIN_RESAMPLES = 200  # bootstrap resamples of the gain's interval
# a rollout diverges where its states lie farther from the centre of the recorded trial's states than this many
# times the farthest recorded state (on the scored blocks): an order of magnitude beyond anything the pilot flew,
# so its error measures the blow-up, not the model; evaluate prints "diverges" there instead of a number
DIVERGED_FACTOR = 10.0
