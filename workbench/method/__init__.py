"""The method (floor 2): Algorithm 1 of the method paper, piece by piece.

Gain estimation (:mod:`.gain`, eqs. (12)-(14)), the task objective by inverse LQR (:mod:`.objective`,
:mod:`.inverse_lqr_sdp`, eqs. (15)-(19)), structured (diagonal) costs and their ratio intervals (:mod:`.structured`,
:mod:`.ratio_profile`), the bootstrap over demonstrations (:mod:`.resampling`), the pilot's reaction delay and lag
(:mod:`.timing`), task frames, TP-GMM and GMR
(:mod:`.frames`, :mod:`.tpgmm`, :mod:`.gmr`, eqs. (24)-(30)) and the variability model built from them
(:mod:`.variability`).
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "BootstrapResult": "resampling",
    "GainBootstrap": "resampling",
    "bootstrap_gain": "resampling",
    "bootstrap": "resampling",
    "spectral_radius": "closed_loop",
    "check_stabilizing": "closed_loop",
    "Frame": "frames",
    "FrameSpec": "frames",
    "identity_frame": "frames",
    "start_frame": "frames",
    "goal_frame": "frames",
    "frames_for_demo": "frames",
    "frames_for_task": "frames",
    "project": "frames",
    "GainMethod": "gain",
    "stack_demonstrations": "gain",
    "iv_instruments": "gain",
    "gain_from_arrays": "gain",
    "estimate_gain": "gain",
    "iv_relevance": "gain",
    "GainChoice": "gain",
    "choose_gain": "gain",
    "IV_OR_DIRECT": "gain",
    "GAIN_METHODS": "gain",
    "GaussianMixture": "gmr",
    "ConditionalGMM": "gmr",
    "GMRModel": "gmr",
    "GMRResult": "gmr",
    "inv_lower": "gmr",
    "InverseLQR": "inverse_lqr_sdp",
    "inverse_lqr": "inverse_lqr_sdp",
    "Structure": "objective",
    "forward_gain_tolerance": "objective",
    "forward_gain": "objective",
    "TaskObjective": "objective",
    "PartDistance": "ratio_profile",
    "ratio_names": "ratio_profile",
    "critical_value": "ratio_profile",
    "fit": "ratio_profile",
    "explains": "ratio_profile",
    "interval": "ratio_profile",
    "factor_interval": "ratio_profile",
    "PseudoTrue": "pseudo_true",
    "PilotTiming": "timing",
    "identify_timing": "timing",
    "decoupled_parts": "structured",
    "memo_lqr": "structured",
    "gain_jacobian": "structured",
    "closest_structured_objective": "structured",
    "ComponentSelection": "tpgmm",
    "select_components": "tpgmm",
    "TaskGMR": "variability",
    "TaskConditional": "variability",
    "resolve_frame_spec": "variability",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
