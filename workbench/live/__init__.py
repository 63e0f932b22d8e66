"""Live prediction (floor 5): a vehicle's MAVLink telemetry in, a model's predictions out.

It joins the adapters' online path and a model, as the CLI joins them offline; it imports no rerun.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "LivePrediction": "predictor",
    "LinkStats": "predictor",
    "LiveEvent": "predictor",
    "LiveSummary": "predictor",
    "OnlinePredictor": "predictor",
    "listen": "predictor",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
