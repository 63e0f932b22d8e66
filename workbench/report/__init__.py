"""The report (floor 5): one Markdown file with PNG figures.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "ReportInputs": "markdown",
    "fig_data_efficiency": "markdown",
    "fig_demonstrations": "markdown",
    "fig_objective": "markdown",
    "fig_calibration": "markdown",
    "fig_predictions": "markdown",
    "fig_rmse": "markdown",
    "fig_variability": "markdown",
    "save_figure": "figure_files",
    "write_report": "markdown",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
