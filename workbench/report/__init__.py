"""The report (floor 5): one Markdown file with PNG figures.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "ReportInputs": "markdown",
    "fig_data_efficiency": "figures",
    "fig_demonstrations": "figures",
    "fig_objective": "figures",
    "fig_calibration": "figures",
    "fig_predictions": "figures",
    "fig_rmse": "figures",
    "fig_variability": "figures",
    "save_figure": "figure_files",
    "write_report": "markdown",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
