"""Behavior models (floor 3): the proposed model, its baselines, one factory, predictions and model files.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "AutoSettings": "autoconfig",
    "choose_settings": "autoconfig",
    "IOCOnlyModel": "baselines",
    "GMROnlyModel": "baselines",
    "PersistenceModel": "baselines",
    "BehaviorModel": "behavior",
    "TaskGMRModel": "behavior",
    "demo_list": "behavior",
    "goal_of": "behavior",
    "references": "behavior",
    "fit_gain": "behavior",
    "as_vector": "behavior",
    "json_seed": "behavior",
    "objective_state": "behavior",
    "objective_restore": "behavior",
    "ModelFile": "files",
    "ModelFileError": "files",
    "write_model_file": "files",
    "read_model_file": "files",
    "Prediction": "prediction",
    "Policy": "prediction",
    "rollout_mean": "prediction",
    "rollout_samples": "prediction",
    "psd_sqrt": "prediction",
    "fit_noise": "prediction",
    "calibrate_band_scale": "prediction",
    "HumanBehaviorModel": "proposed",
    "restore_model": "proposed",
    "METHODS": "names",
    "METHOD_TITLES": "names",
    "MODEL_CLASSES": "factory",
    "make_model": "factory",
    "make_models": "factory",
    "load_model": "factory",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
