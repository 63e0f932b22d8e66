"""Names shared by every recording's logging and its blueprint: entity-path parts, and what a session logged.

The blueprint reads :class:`LoggedSession` to find what the logger wrote; keeping both here lets the session
logger import the blueprint without the blueprint importing the logger (no import cycle).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from workbench.viewer import style

__all__ = ["LoggedSession", "entity_part", "model_for"]


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


@dataclass
class LoggedSession:
    """What was logged, so a blueprint (and a user) can find it.

    ``focus`` are the trials with variability and predictions, the ones the detail tabs show. ``ranges`` are
    y-ranges of plots set by the data (key: the plot's entity base path), ``windows`` the time span of each focus
    trial's predictions, ``bounds`` the scene's visual bounds, ``scales`` the shared color scale of each
    objective block.
    """

    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    demo_ids: list[str] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    focus: list[str] = field(default_factory=list)
    variability: list[str] = field(default_factory=list)
    predictions: dict[str, list[tuple[int, list[str]]]] = field(default_factory=dict)
    models: list[str] = field(default_factory=list)
    modes: list[str] = field(default_factory=list)
    scene: bool = False
    entities: list[str] = field(default_factory=list)
    units: dict[str, str] = field(default_factory=dict)
    methods: list[str] = field(default_factory=list)
    bands: list[str] = field(default_factory=list)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    windows: dict[str, tuple[float, float]] = field(default_factory=dict)
    bounds: tuple[list[float], list[float]] | None = None
    heatmaps: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    scales: dict[str, float] = field(default_factory=dict)
    clock: str = "trial"
    plane_names: tuple[str, str] | None = None
    span: tuple[float, float] | None = None
    heatmap_shapes: dict[tuple[str, str], tuple[int, int]] = field(default_factory=dict)
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

    def title(self, name: str) -> str:
        """``name [unit]`` for a state or input."""
        return style.with_unit(name, self.units.get(name, ""))
