"""The methods a study compares, declared once: name, CLI spelling, title, colour and the class that builds it.

Every place that lists methods iterates :data:`REGISTRY`: the factory (:mod:`workbench.models.factory`), the
study's comparison and verdicts, ``workbench fit --method``'s choices, the viewer's colours and titles
(:mod:`workbench.viewer.style`) and the report's colours and tables. What a method's model *can do* (an input
distribution, Monte Carlo samples, a gain, cross-validated settings…) is declared by its class
(:class:`~workbench.models.behavior.BehaviorModel`'s capability flags), not here.

Adding a baseline: its module (the class, with its :meth:`~workbench.models.behavior.BehaviorModel.for_method`)
and one :class:`Method` line below. The class is named by ``"module:Class"`` and imported only when a model is
built, so this table (and ``workbench fit --help``, which shows the choices) loads without numpy.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from workbench.palette import METHOD_COLORS as _COLORS

__all__ = ["Method", "REGISTRY", "METHODS", "METHOD_TITLES", "method", "model_classes"]


@dataclass(frozen=True)
class Method:
    """One method of the comparison.

    Attributes
    ----------
    name : str
        Its key in tables, scores and files (``"ioc_only"``); :attr:`cli_name` is the command line's spelling.
    title : str
        Its name in tables, figures and views (``"IOC-only"``).
    colour : (int, int, int)
        RGB from :data:`workbench.palette.METHOD_COLORS` (Okabe–Ito), the same in the viewer and the report.
    model_class : str
        ``"module:Class"`` of its model, a :class:`~workbench.models.behavior.BehaviorModel`.
    fit_command : bool
        ``workbench fit --method`` offers it (persistence learns nothing worth a file).
    floor : bool
        A baseline the proposed model must beat before a verdict calls it better (the study's verdicts).
    dash : str
        Its line style in every figure (matplotlib's ``"-"``, ``"--"``, ``"-."``, ``":"``): methods differ by more
        than hue, for colour-blind readers and grayscale prints.
    marker : str
        Its marker in every figure (matplotlib's ``"o"``, ``"s"``, …).
    in_paper : bool
        One of the methods the method paper compared (the groups of its multi-subject one-way ANOVA, which
        ``evaluate --per-subject`` runs beside its own analysis).
    """

    name: str
    title: str
    colour: tuple[int, int, int]
    model_class: str
    fit_command: bool = True
    floor: bool = False
    dash: str = "-"
    marker: str = "o"
    in_paper: bool = False

    @property
    def cli_name(self) -> str:
        return self.name.replace("_", "-")

    @property
    def colour_hex(self) -> str:
        return "#" + "".join(f"{c:02x}" for c in self.colour)

    def load_class(self) -> type[Any]:
        """The model class (imported here, so that naming the methods does not import the models)."""
        module, _, cls = self.model_class.partition(":")
        return getattr(importlib.import_module(module), cls)


# in table order: the proposed model first, persistence (the floor every model must beat) last
REGISTRY: tuple[Method, ...] = (
    Method("proposed", "proposed", _COLORS[0], "workbench.models.proposed:HumanBehaviorModel", dash="-", marker="o",
           in_paper=True),
    Method("ioc_only", "IOC-only", _COLORS[1], "workbench.models.baselines:IOCOnlyModel", floor=True, dash="--",
           marker="s", in_paper=True),
    Method("gmr_only", "GMR-only", _COLORS[2], "workbench.models.baselines:GMROnlyModel", dash="-.", marker="^",
           in_paper=True),
    Method("persistence", "persistence", _COLORS[3], "workbench.models.baselines:PersistenceModel",
           fit_command=False, floor=True, dash=":", marker="D"),
)
METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY)
METHOD_TITLES: dict[str, str] = {m.name: m.title for m in REGISTRY}
_BY_NAME = {m.name: m for m in REGISTRY}


def method(name: str) -> Method:
    """The registered method ``name`` (CLI spellings with ``-`` accepted); KeyError for an unknown one."""
    return _BY_NAME[name.replace("-", "_")]


def model_classes() -> dict[str, type[Any]]:
    """Every registered method's model class by its class name (the name a model file records)."""
    return {cls.__name__: cls for cls in (m.load_class() for m in REGISTRY)}
