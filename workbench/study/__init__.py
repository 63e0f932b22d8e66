"""Studies (floor 4): evaluation over many windows, statistics, weight ratios, the pipelines shared by
``evaluate``, ``report`` and ``demo``, and the executor (serial or Dask).
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "metric_blocks": "evaluate",
    "primary_metric": "evaluate",
    "horizon_rmse": "evaluate",
    "band_coverage": "evaluate",
    "one_step_coverage": "evaluate",
    "coverage_summary": "evaluate",
    "nominal_coverage": "evaluate",
    "compare": "evaluate",
    "summarize": "evaluate",
    "improvement": "evaluate",
    "method_groups": "evaluate",
    "data_efficiency": "evaluate",
    "per_subject": "evaluate",
    "cross_validate": "evaluate",
    "SubjectStudy": "evaluate",
    "models_for": "evaluate",
    "Executor": "executor",
    "SerialExecutor": "executor",
    "DaskExecutor": "executor",
    "Outcome": "executor",
    "make_executor": "executor",
    "task_seed": "executor",
    "serial": "executor",
    "StudyResult": "pipeline",
    "run_study": "pipeline",
    "run_loso": "pipeline",
    "improvement_table": "pipeline",
    "verdicts": "pipeline",
    "metric_unit": "pipeline",
    "plant_for": "pipeline",
    "AnovaResult": "stats",
    "TTestResult": "stats",
    "anova_oneway": "stats",
    "pairwise_ttests": "stats",
    "RatioInterval": "weights",
    "format_interval": "weights",
    "WeightRatios": "weights",
    "PartFit": "weights",
    "ObjectiveIntervals": "weights",
    "objective_intervals": "weights",
    "ratio_bootstrap": "weights",
    "weight_ratios": "weights",
    "compare_strategies": "weights",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
