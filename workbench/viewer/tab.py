"""What a tab of a session recording is: a :class:`Tab` declares its name, its place, what it logs beyond the
session's trials and what it shows; each tab is one module in ``workbench/viewer/tabs/`` (as a log format is one
module in ``adapters/formats/declared/``), and :data:`workbench.viewer.tabs.TABS` holds them in order.

:func:`workbench.viewer.session.log_session` logs the trials (states, inputs, flight modes, tracks, ŵ) and the
verdicts, then calls every tab's :meth:`Tab.log` with the :class:`SessionRun`; the blueprint
(:func:`workbench.viewer.blueprint.session_blueprint`) asks every tab for its :meth:`Tab.views`. Neither lists the
tabs: a tab is added by adding its module (and its test).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

from workbench.defaults import N_STEPS
from workbench.viewer.entities import LoggedSession, model_for

if TYPE_CHECKING:
    from workbench.data.demonstrations import Demonstration, DemonstrationSet

__all__ = ["SessionRun", "Tab"]


@dataclass(frozen=True)
class SessionRun:
    """What one session recording shows, as :func:`~workbench.viewer.session.log_session` was asked: the trials,
    the models (one, or by strategy label), the baselines by label, the focus trials (chosen) and the prediction
    settings."""

    demos: DemonstrationSet
    models: Any = None
    named_models: Mapping[str, Any] = field(default_factory=dict)
    baselines: Mapping[Any, Mapping[str, Any]] = field(default_factory=dict)
    focus: tuple[str, ...] = ()
    n_steps: int = N_STEPS
    samples: int = 0
    starts: tuple[int, ...] = (0,)
    seed: int | None = 0
    source_dt: float | None = None
    scores: tuple[Any, Any] | None = None

    def model_for(self, demo: Demonstration) -> Any:
        """The model that explains ``demo`` (None without one)."""
        return model_for(self.models, demo)

    def methods_for(self, demo: Demonstration) -> dict[str, Any]:
        """Method name → model for a prediction of ``demo``: its proposed model and its label's baselines."""
        proposed = self.model_for(demo)
        if proposed is None:
            return {}
        extra = self.baselines.get(demo.label) or self.baselines.get(None) or {}
        return {"proposed": proposed, **extra}


class Tab(ABC):
    """A tab of a session recording.

    Attributes
    ----------
    name : str
        Its title (a tab shown once per focus trial adds `` · <trial>``); README's list of tabs names these.
    order : int
        Where it stands among the tabs, lower first; it is also the order tabs log in (every tab logs after the
        trials and the verdicts).
    description : str
        One line: what it shows.
    """

    name: ClassVar[str]
    order: ClassVar[int]
    description: ClassVar[str]

    def log(self, logger: Any, run: SessionRun) -> None:  # noqa: B027 - most tabs show the session's trials only
        """Log what this tab shows beyond the session's trials (a :class:`~workbench.viewer.session.SessionLogger`);
        nothing by default. A tab keeps what its views need in ``logger.session.tabs[self.name]``."""

    @abstractmethod
    def views(self, session: LoggedSession) -> list[Any]:
        """Its blueprint containers, each named (one tab each), or ``[]`` when it has nothing to show."""
