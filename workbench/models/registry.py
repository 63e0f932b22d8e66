"""The methods a study compares, declared once: name, CLI spelling, title, colour and the class that builds it.

Every place that lists methods iterates :data:`REGISTRY`: the factory (:mod:`workbench.models.factory`), the
study's comparison and verdicts, ``workbench fit --method``'s choices, the viewer's colours and titles
(:mod:`workbench.viewer.style`) and the report's colours and tables. What a method's model *can do* (an input
distribution, Monte Carlo samples, a gain, cross-validated settings…) is declared by its class
(:class:`~workbench.models.behavior.BehaviorModel`'s capability flags), not here.

A method is declared where its class is: a module of ``workbench/models/`` lists its methods in
``DECLARED_METHODS``, a tuple of literal tables (name, title, class, order, colour, …; see :func:`_entry`), and
:data:`REGISTRY` is every such table, in ``order``. The tables are read from the modules' text, never by importing
them, so the registry (and ``workbench fit --help``, which shows the choices) loads without numpy; the class is
imported only when a model is built. Adding a baseline is its module (the class, with its
:meth:`~workbench.models.behavior.BehaviorModel.for_method`, and its ``DECLARED_METHODS``) and its test.
"""

from __future__ import annotations

import ast
import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from workbench.palette import METHOD_COLORS, SPARE_METHOD_COLORS

#: the colours a declaration's ``colour`` indexes: the registry's four, then the spare ones
_COLORS = METHOD_COLORS + SPARE_METHOD_COLORS

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


_MODELS = Path(__file__).resolve().parent
_KEYS = {"name", "title", "class", "order", "colour", "fit_command", "floor", "in_paper", "dash", "marker"}


def _entry(raw: Any, module: str, where: str) -> tuple[int, Method]:
    """One declared method: ``{"name", "title", "class", "order", "colour"}`` (``colour`` an index into the
    palette's method colours) and, optionally, ``fit_command``, ``floor``, ``in_paper``, ``dash`` and ``marker``."""
    if not isinstance(raw, dict) or not {"name", "title", "class", "order", "colour"} <= set(raw) \
            or set(raw) - _KEYS:
        raise TypeError(f"{where}: a declared method is a table of {sorted(_KEYS)} (name, title, class, order and "
                        f"colour required), got {raw!r}")
    if not isinstance(raw["colour"], int) or not 0 <= raw["colour"] < len(_COLORS):
        raise TypeError(f"{where}: colour is an index into the palette's {len(_COLORS)} method colours")
    options = {k: raw[k] for k in ("fit_command", "floor", "in_paper", "dash", "marker") if k in raw}
    return int(raw["order"]), Method(str(raw["name"]), str(raw["title"]), _COLORS[raw["colour"]],
                                     f"{module}:{raw['class']}", **options)


def _declared() -> tuple[Method, ...]:
    """Every ``DECLARED_METHODS`` of a module of ``workbench/models/``, read from its text, in ``order``."""
    found: list[tuple[int, Method]] = []
    for path in sorted(_MODELS.glob("*.py")):
        text = path.read_text(encoding="utf-8")
        if path.name == "registry.py" or "DECLARED_METHODS" not in text:
            continue
        for node in ast.parse(text).body:
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "DECLARED_METHODS"
                                                    for t in node.targets):
                where = f"workbench/models/{path.name}:{node.lineno}"
                try:
                    entries = ast.literal_eval(node.value)
                except ValueError:
                    raise TypeError(f"{where}: DECLARED_METHODS must be literal tables (read without importing)") \
                        from None
                found += [_entry(e, f"workbench.models.{path.stem}", where) for e in entries]
    names = [m.name for _, m in found]
    if len(set(names)) != len(names):
        raise TypeError(f"two declared methods share a name: {sorted(names)}")
    return tuple(m for _, m in sorted(found, key=lambda om: (om[0], om[1].name)))


#: Every method, in table order (the proposed model first, persistence, the floor every model must beat, last).
REGISTRY: tuple[Method, ...] = _declared()
METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY)
METHOD_TITLES: dict[str, str] = {m.name: m.title for m in REGISTRY}
_BY_NAME = {m.name: m for m in REGISTRY}


def method(name: str) -> Method:
    """The registered method ``name`` (CLI spellings with ``-`` accepted); KeyError for an unknown one."""
    return _BY_NAME[name.replace("-", "_")]


def model_classes() -> dict[str, type[Any]]:
    """Every registered method's model class by its class name (the name a model file records)."""
    return {cls.__name__: cls for cls in (m.load_class() for m in REGISTRY)}
