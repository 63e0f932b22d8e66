"""Names shared by every recording's logging and its blueprint: entity paths, and what a session logged.

Every entity path a blueprint shows is built here, by one function the logger that writes it and the blueprint
that shows it both call (rerun's examples write a path where they log it; here two modules need it): a tab is added
by logging under a path made here and showing that path. The blueprint reads :class:`LoggedSession` to find what
the logger wrote; keeping both here lets the session logger import the blueprint without the blueprint importing
the logger (no import cycle).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from workbench.viewer import style

__all__ = ["LoggedSession", "entity_part", "model_for", "KEY", "SCORES", "FLIGHT_MODE", "demo_path", "series_path",
           "mode_path", "prediction_path", "prediction_plot", "overlay_plot", "scene_demo_path",
           "scene_prediction_path", "model_path", "label_scores_path", "query", "origin"]


def model_for(models: Any, demo: Any) -> Any:
    """The model that explains ``demo``: one model for every trial, or a mapping by strategy label."""
    if models is None:
        return None
    if not isinstance(models, Mapping):
        return models
    return models.get(demo.label)


def entity_part(name: str) -> str:
    """An entity-path part: rerun splits on '/', and spaces or odd characters make paths hard to type."""
    out = "".join(c if c.isalnum() or c in "-_." else "_" for c in str(name))
    return out or "_"


# -- entity paths (relative: rerun roots them at "/"; :func:`query` and :func:`origin` for a blueprint) ----------
#: the small text naming what each color means
KEY = "key"
#: every label's held-out scores as text
SCORES = "scores"
#: a flight's one mode lane on the log's clock (overlaid trials get one each: :func:`mode_path`)
FLIGHT_MODE = "flight/mode"


def demo_path(demo_id: str) -> str:
    """``demos/<id>``: everything logged of one trial."""
    return f"demos/{entity_part(demo_id)}"


def series_path(demo_id: str, kind: str, *names: str) -> str:
    """``demos/<id>/<kind>/<name>…``: a trial's ``states``, ``inputs``, ``variability`` (ŵ and its bands) or
    ``online`` (a replay's or live link's overlay) of one state or input; each name one entity part
    (``series_path(id, "online", "rollout_end", state)``)."""
    return "/".join([demo_path(demo_id), kind, *(entity_part(n) for n in names)])


def mode_path(demo_id: str) -> str:
    """``demos/<id>/mode``: a trial's flight-mode lane."""
    return f"{demo_path(demo_id)}/mode"


def prediction_path(demo_id: str, start: int, method: str | None = None, name: str | None = None, *,
                    band: bool = False) -> str:
    """``demos/<id>/predictions/from_<start>[/<method>[_band][/<state>]]``: one method's prediction (or its Monte
    Carlo band) of one state from step ``start``."""
    out = f"{demo_path(demo_id)}/predictions/from_{start}"
    if method is not None:
        out += f"/{entity_part(method)}" + ("_band" if band else "")
        if name is not None:
            out += f"/{entity_part(name)}"
    return out


def prediction_plot(demo_id: str, name: str) -> str:
    """``demos/<id>/predictions/<state>``: the key of one trial's prediction plot of a state (its y-range, its
    legend's corner), not an entity."""
    return f"{demo_path(demo_id)}/predictions/{entity_part(name)}"


def overlay_plot(kind: str, name: str) -> str:
    """``<kind>/<name>``: the key of the plot overlaying every trial's state or input (its y-range), not an entity."""
    return f"{kind}/{entity_part(name)}"


def scene_demo_path(demo_id: str) -> str:
    """``scene/demos/<id>``: a trial's track, start and vehicle in the plane of flight."""
    return f"scene/demos/{entity_part(demo_id)}"


def scene_prediction_path(demo_id: str, start: int, method: str, *, band: bool = False) -> str:
    """``scene/predictions/<id>/from_<start>/<method>[_band]``: a predicted path (or its band) in the scene."""
    return f"scene/predictions/{entity_part(demo_id)}/from_{start}/{entity_part(method)}" + ("_band" if band else "")


def model_path(model: str, part: str = "") -> str:
    """``models/<name>[/<part>]``: a model's blocks (``K``, ``heatmap/K``, …), ``summary`` and ``verdict``."""
    return f"models/{entity_part(model)}" + (f"/{part}" if part else "")


def label_scores_path(label: str) -> str:
    """``label_scores/<label>``: one label's held-out scores, under its prediction tabs."""
    return f"label_scores/{entity_part(label)}"


def query(path: str, recursive: bool = False) -> str:
    """A blueprint's content expression that includes ``path`` (and what is under it with ``recursive``)."""
    return f"+ /{path}" + ("/**" if recursive else "")


def origin(path: str) -> str:
    """A view's origin at ``path``."""
    return f"/{path}"


@dataclass
class LoggedSession:
    """What was logged, so a blueprint (and a user) can find it.

    ``focus`` are the trials with variability and predictions, the ones the detail tabs show. ``ranges`` are
    y-ranges of plots set by the data (key: the plot's entity base path), ``windows`` the time span of each focus
    trial's predictions, ``bounds`` the scene's visual bounds. The fields are what several tabs read (the trials,
    the predictions, the verdicts); a tab keeps what only it reads in ``tabs[its name]``.
    """

    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    demo_ids: list[str] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    focus: list[str] = field(default_factory=list)
    variability: list[str] = field(default_factory=list)
    predictions: dict[str, list[tuple[int, list[str]]]] = field(default_factory=dict)
    modes: list[str] = field(default_factory=list)
    scene: bool = False
    entities: list[str] = field(default_factory=list)
    units: dict[str, str] = field(default_factory=dict)
    methods: list[str] = field(default_factory=list)
    bands: list[str] = field(default_factory=list)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    windows: dict[str, tuple[float, float]] = field(default_factory=dict)
    bounds: tuple[list[float], list[float]] | None = None
    clock: str = "trial"
    plane_names: tuple[str, str] | None = None
    span: tuple[float, float] | None = None
    corners: dict[str, str] = field(default_factory=dict)
    trial_windows: dict[str, tuple[float, float]] = field(default_factory=dict)  # trial → its time span
    fit_titles: dict[str, str] = field(default_factory=dict)  # ŵ plot → its band coverage against nominal
    verdicts: dict[str, Any] = field(default_factory=dict)  # model name → workbench.viewer.verdict.Verdict
    warnings: list[str] = field(default_factory=list)  # what the recording and the terminal warn of
    colors: dict[str, tuple[int, int, int]] = field(default_factory=dict)  # trial → its color, for the key
    label_colors: dict[str, tuple[int, int, int]] = field(default_factory=dict)  # strategy → its color
    in_sample: list[str] = field(default_factory=list)  # trials a model shown was fitted on
    scores: Any = None  # held-out scores (workbench.study.scores.heldout_scores rows), logged under /scores
    score_note: str = ""  # where the scores come from (the split, the horizon), or why there are none
    trial_labels: dict[str, str] = field(default_factory=dict)  # trial → its strategy label ("" without)
    #: what a tab logged for its own views alone, by tab name (workbench.viewer.tabs: e.g. the objective's heatmaps)
    tabs: dict[str, Any] = field(default_factory=dict)

    def title(self, name: str) -> str:
        """``name [unit]`` for a state or input."""
        return style.with_unit(name, self.units.get(name, ""))
