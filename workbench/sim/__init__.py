"""Simulated operators (floor 2): the landing simulator and operators whose task objective is known.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "OperatorProfile": "landing",
    "operator_profile": "landing",
    "simulate_landings": "landing",
    "simulate_trial": "landing",
    "simulate_study": "landing",
    "LQROperator": "operators",
    "lqr_operator_demos": "operators",
    "ErraticOperator": "operators",
    "erratic_operator_demos": "operators",
    "DelayedPilot": "operators",
    "delayed_pilot_demos": "operators",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
