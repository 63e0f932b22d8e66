"""Saving and restoring every behavior model: one module for the model file's contents.

:func:`save_model` writes what every model shares (the plant, target, noise, training record and settings) and
the arrays its class's ``_state()`` hook returns; :func:`restore_model` builds the class the file names (among the
registered methods' classes, :func:`workbench.models.registry.model_classes`) and hands the file to its
``_restore(mf)`` hook. The parts several classes share — the task objective, the gain's choice, the TP-GMM — are
here too. The byte format (a versioned ``.npz`` without pickle) is :mod:`workbench.models.files`.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from workbench.data.pilot_task import PilotTask
from workbench.data.roles import Roles
from workbench.errors import DataError, ModelError
from workbench.method.frames import FrameSpec
from workbench.method.gain import GainChoice
from workbench.method.objective import TaskObjective
from workbench.method.variability import TaskGMR
from workbench.models.files import ModelFile, ModelFileError, read_model_file, write_model_file
from workbench.models.fitting import json_seed
from workbench.models.prediction import RHO_MAX
from workbench.models.registry import model_classes
from workbench.models.timed import Timing
from workbench.plant.system import LinearSystem

__all__ = [
    "save_model",
    "settings_json",
    "load_model",
    "restore_model",
    "objective_state",
    "objective_restore",
    "gain_choice_state",
    "gain_choice_restore",
    "gmr_state",
    "gmr_restore",
    "StoredModel",
]


class StoredModel(Protocol):
    """What this module reads and calls on a model: every :class:`~workbench.models.behavior.BehaviorModel` is one.

    An interface, not the class: the base class's ``save`` calls :func:`save_model`, so this module must not import
    it (no import circle). Its class's hooks: ``_state()`` (its part of the file), ``_restore(mf)`` (that part
    back), ``_param_names()`` (the constructor's settings); learned attributes every model has are declared below,
    the others (``gain_choice_``, ``variability_``, …) are read where a class has them.
    """

    plant: LinearSystem
    target_: np.ndarray
    noise_rho_: np.ndarray
    noise_scale_: np.ndarray
    noise_band_factor_: float
    noise_band_coverage_: float
    n_demos_: int
    n_samples_: int
    labels_: tuple[str, ...]

    def _check_fitted(self, where: str) -> None: ...

    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]: ...

    def _restore(self, mf: ModelFile) -> None: ...

    def get_params(self) -> dict[str, Any]: ...

    @classmethod
    def _param_names(cls) -> list[str]: ...


def save_model(model: StoredModel, path: str | os.PathLike) -> Path:
    """Write the fitted ``model`` to one ``.npz`` file (see :mod:`workbench.models.files`), atomically:
    what every model shares (plant, target, noise, training record, settings) and its class's ``_state()``."""
    model._check_fitted("save")
    header, arrays = model._state()
    sys_ = model.plant
    arrays = {"system/A": sys_.A, "system/B": sys_.B, "target": model.target_, "noise_rho": model.noise_rho_,
              "noise_scale": model.noise_scale_, **arrays}
    if getattr(model, "goal_offset_", None) is not None:
        arrays["goal_offset"] = model.goal_offset_
    if getattr(model, "state_envelope_", None) is not None:
        arrays["state_envelope"] = model.state_envelope_
    if sys_.u_min is not None:
        arrays["system/u_min"] = sys_.u_min
    if sys_.u_max is not None:
        arrays["system/u_max"] = sys_.u_max
    header = {
        "settings": settings_json(model),
        "system": {
            "dt": sys_.dt,
            "state_names": list(sys_.state_names),
            "input_names": list(sys_.input_names),
            "fit_residual": sys_.fit_residual,
            "roles": sys_.roles.to_json(),
            "plant_group": sys_.plant_group,
        },
        "fit": {
            "n_demos": model.n_demos_,
            "n_samples": model.n_samples_,
            "labels": list(model.labels_),
            # None (unknown) for a model restored from a file written before these were recorded
            "trial_ids": None if getattr(model, "train_ids_", None) is None else list(model.train_ids_),
            "trial_digests": (None if getattr(model, "train_digests_", None) is None
                              else list(model.train_digests_)),
            "data_digest": getattr(model, "data_digest_", None),
            "goal_relative": bool(getattr(model, "goal_relative_", False)),
            # the pilot's task (regulated states, relative to what, reference speed, timing) and the gain's
            # stability judgement; absent from files written before them
            "task": None if getattr(model, "task_", None) is None else model.task_.to_dict(),
            "stability": None if getattr(model, "stability_", None) is None else model.stability_.to_dict(),
            "noise_band_factor": float(model.noise_band_factor_),
            "noise_band_coverage": None if math.isnan(model.noise_band_coverage_) else model.noise_band_coverage_,
            # the pilot's timing the model applies (None: none; files written before it existed have none)
            "timing": None if getattr(model, "timing_", None) is None else model.timing_.as_json(),
            "pilot_timing": getattr(model, "pilot_timing_", None),
        },
        **header,
    }
    return write_model_file(path, type(model).__name__, header, arrays)


def settings_json(model: StoredModel) -> dict[str, Any]:
    """The constructor's settings as JSON (a seed as an integer or None, frames by their kinds)."""
    out = {}
    for k, v in model.get_params().items():
        if k == "random_state":
            v = json_seed(v)
        elif isinstance(v, FrameSpec):
            v = list(v.kinds)
        elif isinstance(v, tuple):
            v = list(v)
        elif isinstance(v, np.generic):
            v = v.item()
        elif isinstance(v, PilotTask):  # a settled task (a fold's): kept whole, marked as such
            v = {"pilot_task": v.to_dict()}
        out[k] = v
    return out


def gain_choice_state(model: Any) -> dict[str, str] | None:
    """The model file's record of :class:`GainChoice` (None for a model without one)."""
    c = getattr(model, "gain_choice_", None)
    return None if c is None else {"requested": c.requested, "method": c.method, "reason": c.reason}


def gain_choice_restore(model: Any, header: dict[str, Any]) -> None:
    """``gain_choice_`` and ``gain_method_`` from a model file; files written before the record say only what
    was requested, which was then the estimator used."""
    rec = header.get("gain_choice")
    if isinstance(rec, dict) and {"requested", "method", "reason"} <= set(rec):
        model.gain_choice_ = GainChoice(str(rec["requested"]), str(rec["method"]), str(rec["reason"]))
    else:
        model.gain_choice_ = GainChoice(model.gain_method, model.gain_method, "as requested")
    model.gain_method_ = model.gain_choice_.method


def objective_state(obj: TaskObjective | None) -> tuple[dict[str, Any] | None, dict[str, np.ndarray]]:
    if obj is None:
        return None, {}
    header, arrays = {}, {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            arrays[f"objective/{f.name}"] = v
        elif isinstance(v, float) and not math.isfinite(v):
            header[f.name] = None
        else:
            header[f.name] = v.item() if isinstance(v, np.generic) else v
    return header, arrays


def objective_restore(mf: ModelFile) -> TaskObjective | None:
    info = mf.header.get("objective")
    if info is None:
        return None
    kwargs = {}
    for f in dataclasses.fields(TaskObjective):
        key = f"objective/{f.name}"
        if key in mf.arrays:
            a = np.array(mf.array(key), dtype=float)
            a.setflags(write=False)
            kwargs[f.name] = a
        elif f.name in info:
            v = info[f.name]
            kwargs[f.name] = float("nan") if v is None and f.type in ("float", float) else v
        else:
            raise ModelFileError(f"{mf.path}: damaged model file: the task objective lacks {f.name!r}")
    return TaskObjective(**kwargs)


def gmr_state(model: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The file's record of a TP-GMM model's mixture (:class:`~workbench.models.taskgmr.TaskGMRModel`)."""
    tp = model.variability_.tpgmm_
    spec = model.frame_spec_
    header = {
        "frames": {
            "kinds": list(spec.kinds),
            "angle_index": spec.angle_index,
            "position_idx": list(spec.position_idx),
        },
        "tpgmm": {
            "n_iter": int(getattr(tp, "n_iter_", 0)),
            "converged": bool(getattr(tp, "converged_", True)),
            "lower_bound": float(getattr(tp, "lower_bound_", float("nan")))
            if math.isfinite(float(getattr(tp, "lower_bound_", float("nan"))))
            else None,
        },
    }
    arrays = {
        "tpgmm/weights": tp.weights_,
        "tpgmm/means": tp.means_,
        "tpgmm/covariances": tp.covariances_,
        "tpgmm/precisions_cholesky": tp.precisions_cholesky_,
        "scale": model.variability_.scale_,
    }
    return header, arrays


def gmr_restore(model: Any, mf: ModelFile, d_out: int) -> None:
    """A TP-GMM model's mixture from its file, checked against the plant and the settings."""
    n = len(getattr(model, "regulated_", None) or range(model.plant.n))  # the GMR's states: the regulated ones
    D = n + d_out
    fr = mf.header.get("frames")
    try:
        spec = FrameSpec(tuple(fr["kinds"]), fr["angle_index"], tuple(fr["position_idx"]))
    except (KeyError, TypeError, ValueError, ModelError) as exc:
        raise ModelFileError(f"{mf.path}: damaged model file: frame specification {fr!r} ({exc})") from None
    named = [*spec.position_idx, *([] if spec.angle_index is None else [spec.angle_index])]
    if any(not 0 <= i < n for i in named) or len(set(spec.position_idx)) != len(spec.position_idx):
        raise ModelFileError(f"{mf.path}: damaged model file: frame specification {fr!r} names states outside "
                             f"0…{n - 1} or one state twice")
    w = mf.array("tpgmm/weights", (None,))
    G = w.shape[0]
    means = mf.array("tpgmm/means", (spec.n_frames, G, D))
    covs = mf.array("tpgmm/covariances", (spec.n_frames, G, D, D))
    prec = mf.array("tpgmm/precisions_cholesky", (spec.n_frames, G, D, D))
    scale = mf.array("scale", (D,))
    wrong_G = model.n_components != "cv" and G != model.n_components
    if wrong_G or np.any(w < 0) or abs(w.sum() - 1) > 1e-6 or np.any(scale <= 0):
        raise ModelFileError(f"{mf.path}: damaged model file: inconsistent TP-GMM parameters")
    model.frame_spec_ = spec
    try:
        model.variability_ = TaskGMR.from_parameters(
            spec, w, means, covs, scale, n, precisions_cholesky=prec, n_components=G,
            reg_covar=getattr(model, "reg_covar_", model.reg_covar),
            standardize=model.standardize, random_state=model.random_state,
        )
    except ModelError as exc:
        raise ModelFileError(f"{mf.path}: damaged model file: {exc}") from None
    tp = model.variability_.tpgmm_
    info = mf.header.get("tpgmm", {}) or {}
    tp.n_iter_ = int(info.get("n_iter", 0))
    tp.converged_ = bool(info.get("converged", True))
    lb = info.get("lower_bound")
    tp.lower_bound_ = float("nan") if lb is None else float(lb)
    model.n_components_ = G


_RENAMED_SETTINGS = {"noise_horizon": "noise_horizon_s"}


def _restore_task(model: Any, fit: dict[str, Any], mf: ModelFile) -> None:
    """``task_``, ``regulated_``, ``regulator_plant_`` and ``stability_`` from a file; a file written before the task
    was recorded gets the task its linear term implies (every state; the goal or zero)."""
    from workbench.method.stability import Stability
    from workbench.models.regulator import legacy_task, regulator_plant

    rec = fit.get("task")
    try:
        task = (PilotTask.from_dict(rec) if isinstance(rec, dict)
                else legacy_task(bool(fit.get("goal_relative", False))))
        model.task_ = task
        model.regulated_ = task.regulated_indices(model.plant.state_names)
        stab = fit.get("stability")
        model.stability_ = Stability.from_dict(stab) if isinstance(stab, dict) else None
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelFileError(f"{mf.path}: damaged model file: the pilot's task ({exc})") from None
    if model.has_gain:
        model.regulator_plant_ = regulator_plant(model.plant, model.regulated_)


def _text_or_none(value: Any, where: str) -> str | None:
    """A header's optional text field: ``None`` where absent (files written before it), else the text itself."""
    if value is None:
        return None
    if not isinstance(value, str):
        raise ModelFileError(f"{where}: expected text, got {type(value).__name__}")
    return value


def load_model(path: str | os.PathLike) -> Any:
    """Read a model written by ``save`` (any registered method's class); never executes code from the file.

    The file names its class, not a module path, so files written before a module moved still load.

    Raises
    ------
    ModelFileError
        (a :class:`~workbench.errors.FormatError` and a :class:`~workbench.errors.ModelError`) for a missing,
        foreign, damaged or newer-version file; the message names the file and the cause.
    """
    return restore_model(read_model_file(path))


def restore_model(mf: ModelFile, classes: Mapping[str, type[StoredModel]] | None = None) -> Any:
    """The model a read model file holds, of the class it names among ``classes`` (default: the registered
    methods' classes, :func:`workbench.models.registry.model_classes`)."""
    classes = model_classes() if classes is None else classes
    cls = classes.get(mf.model_class)
    if cls is None:
        raise ModelFileError(f"{mf.path}: unknown model class {mf.model_class!r}; known: {sorted(classes)}")
    h = mf.header
    try:
        s = h["system"]
        A = mf.array("system/A", (None, None))
        B = mf.array("system/B", (A.shape[0], None))
        plant = LinearSystem(
            A, B, float(s["dt"]), tuple(s["state_names"]), tuple(s["input_names"]),
            u_min=mf.get("system/u_min"), u_max=mf.get("system/u_max"), fit_residual=s.get("fit_residual"),
            roles=Roles.from_json(s.get("roles"), f"{mf.path}: roles"),
            plant_group=_text_or_none(s.get("plant_group"), f"{mf.path}: system plant_group"),
        )
    except ModelFileError:
        raise
    except (DataError, ModelError) as exc:  # the plant's own checks, in its words
        raise ModelFileError(f"{mf.path}: damaged model file: system: {exc}") from None
    except KeyError as exc:
        raise ModelFileError(f"{mf.path}: damaged model file: system: its header has no {exc.args[0]!r}") from None
    except (TypeError, ValueError):  # numpy's broadcasting or a float() of text: said by the arrays' shapes
        shapes = ", ".join(f"{k} {tuple(v.shape)}" for k, v in mf.arrays.items() if k.startswith("system/"))
        raise ModelFileError(f"{mf.path}: damaged model file: system: its values do not fit together "
                             f"({shapes})") from None
    settings = h.get("settings") or {}
    if not isinstance(settings, dict):
        raise ModelFileError(f"{mf.path}: damaged model file: settings are a {type(settings).__name__}, not a table")
    # settings renamed since a file was written: the old name still loads (files outlive the code's names)
    settings = {_RENAMED_SETTINGS.get(k, k): v for k, v in settings.items()}
    unknown = sorted(set(settings) - set(cls._param_names()))
    if unknown:
        raise ModelFileError(f"{mf.path}: damaged model file: unknown {cls.__name__} settings {unknown}")
    for key in ("frames", "position_idx", "cv_components", "cv_reg_covars", "timing"):
        if isinstance(settings.get(key), list):
            settings[key] = tuple(settings[key])
    for key in ("n_components", "reg_covar"):  # files written before the rename said "auto" for "cv"
        if settings.get(key) == "auto":
            settings[key] = "cv"
    if isinstance(settings.get("task"), dict) and "pilot_task" in settings["task"]:
        try:
            settings["task"] = PilotTask.from_dict(settings["task"]["pilot_task"])
        except (TypeError, ValueError) as exc:
            raise ModelFileError(f"{mf.path}: damaged model file: task setting ({exc})") from None
    model = cls(plant, **settings)
    n, m = plant.n, plant.m
    try:
        model.target_ = np.array(mf.array("target", (n,)))
        model.goal_offset_ = np.array(mf.array("goal_offset", (n,))) if "goal_offset" in mf.arrays else None
        if "state_envelope" in mf.arrays:  # files written before the envelope existed predict without the flag
            model.state_envelope_ = np.array(mf.array("state_envelope", (2, n)))
        model.noise_rho_ = np.array(mf.array("noise_rho", (m,)))
        model.noise_scale_ = np.array(mf.array("noise_scale", (m,)))
        fit = h.get("fit") or {}
        model.n_features_in_, model.n_outputs_ = n, m
        model.n_demos_ = int(fit.get("n_demos", 0))
        model.n_samples_ = int(fit.get("n_samples", 0))
        model.labels_ = tuple(str(x) for x in fit.get("labels", []))
        # files written before the training data were recorded: unknown (None), not "no trials"
        ids, digests = fit.get("trial_ids"), fit.get("trial_digests")
        model.train_ids_ = None if ids is None else tuple(str(x) for x in ids)
        model.train_digests_ = None if digests is None else tuple(str(x) for x in digests)
        model.data_digest_ = None if fit.get("data_digest") is None else str(fit["data_digest"])
        model.noise_band_factor_ = float(fit.get("noise_band_factor", 1.0))
        cov = fit.get("noise_band_coverage")
        model.noise_band_coverage_ = float("nan") if cov is None else float(cov)
        if model.has_gain:  # the linear term's reference; a model without a gain has none
            model.goal_relative_ = bool(fit.get("goal_relative", False))
        timing = fit.get("timing")
        try:
            model.timing_ = None if timing is None else Timing.from_json(timing)
        except ModelError as exc:
            raise ModelFileError(f"{mf.path}: damaged model file: timing ({exc})") from None
        model.pilot_timing_ = fit.get("pilot_timing")
        _restore_task(model, fit, mf)
        model._restore(mf)
    except ModelFileError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError) as exc:  # AttributeError: a header entry not a table
        raise ModelFileError(f"{mf.path}: damaged model file ({type(exc).__name__}: {exc})") from None
    if np.any(model.noise_rho_ < 0) or np.any(model.noise_rho_ > RHO_MAX) or np.any(model.noise_scale_ < 0):
        raise ModelFileError(
            f"{mf.path}: damaged model file: noise scale {model.noise_scale_} or correlation {model.noise_rho_} "
            f"outside their ranges"
        )
    return model
