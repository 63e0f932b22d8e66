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
    "MethodSettings": "behavior",
    "TaskGMRModel": "taskgmr",
    "demo_list": "fitting",
    "goal_of": "fitting",
    "references": "fitting",
    "fit_gain": "fitting",
    "as_vector": "fitting",
    "json_seed": "fitting",
    "objective_state": "storage",
    "objective_restore": "storage",
    "save_model": "storage",
    "restore_model": "storage",
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
    "Method": "registry",
    "REGISTRY": "registry",
    "METHODS": "registry",
    "METHOD_TITLES": "registry",
    "MODEL_CLASSES": "factory",
    "default_model": "factory",
    "make_model": "factory",
    "make_models": "factory",
    "load_model": "storage",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
