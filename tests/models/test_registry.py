"""The method registry is the one list: every consumer shows every registered method, and no module keeps its own.

Each registered method must reach the CLI's choices, the factory and the study's comparison, the viewer's colours
and titles and the report's colours and tables; and no module under ``workbench/`` may spell out a method's
title or a hand-kept list or table of method names (the way titles, colours and lists drifted apart before the
registry: titles in two places, colours in three).
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

import pytest

from workbench.models.registry import METHOD_TITLES, METHODS, REGISTRY, method, model_classes

REPO = Path(__file__).resolve().parents[2]


def _subparser(name: str) -> argparse.ArgumentParser:
    from workbench.cli.parser import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


def test_the_registry_is_consistent():
    assert len(set(METHODS)) == len(METHODS) == len(REGISTRY)
    assert len({m.title for m in REGISTRY}) == len(REGISTRY)
    assert len({m.colour for m in REGISTRY}) == len(REGISTRY), "two methods share a colour"
    for m in REGISTRY:
        assert method(m.name) is m and method(m.cli_name) is m
        assert METHOD_TITLES[m.name] == m.title
        assert all(0 <= c <= 255 for c in m.colour) and len(m.colour) == 3
    classes = model_classes()
    assert len(classes) == len(REGISTRY), "two methods share a class"


@pytest.mark.parametrize("entry", REGISTRY, ids=lambda m: m.name)
def test_every_registered_method_reaches_every_consumer(entry, quadrotor):
    from workbench.models.behavior import BehaviorModel
    from workbench.models.factory import MODEL_CLASSES, make_model, make_models
    from workbench.report import markdown
    from workbench.report.tables import METHOD_TITLES as report_titles
    from workbench.study.method_level import FLOOR_METHODS
    from workbench.viewer import style

    choices = next(a for a in _subparser("fit")._actions if "--method" in a.option_strings).choices
    assert (entry.cli_name in choices) == entry.fit_command
    cls = entry.load_class()
    assert issubclass(cls, BehaviorModel) and MODEL_CLASSES[cls.__name__] is cls
    assert type(make_model(entry.cli_name, quadrotor)) is cls
    assert type(make_models(quadrotor)[entry.name]) is cls  # the study's comparison
    assert (entry.name in FLOOR_METHODS) == entry.floor
    assert style.method_color(entry.name) == entry.colour and style.method_title(entry.name) == entry.title
    assert markdown.METHOD_COLORS[entry.name] == entry.colour_hex
    assert report_titles[entry.name] == entry.title


# Literals naming methods on purpose (a choice among the methods, not a list of them), with why.
CHOSEN = {
    ("workbench/viewer/tabs/predictions.py", ("proposed", "persistence")):
        "the score title: the model against no operator",
}


def copies(source: str, where: str) -> list[str]:
    """Where ``source`` spells out a registered title that is not also a name, or a tuple / list / set / dict
    literal naming two or more methods (a per-method table or list): a copy of the registry that will drift."""
    names = set(METHODS) | {m.cli_name for m in REGISTRY}  # the command line's spellings too
    titles = {m.title for m in REGISTRY} - names
    found = []
    tree = ast.parse(source)
    declared = {id(n) for node in ast.walk(tree) if isinstance(node, ast.Assign)
                and any(isinstance(t, ast.Name) and t.id == "DECLARED_METHODS" for t in node.targets)
                for n in ast.walk(node)}  # a method's declaration beside its class is the registry's own source
    for node in ast.walk(tree):
        if id(node) in declared:
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in titles:
            found.append(f"{where}:{node.lineno}: {node.value!r}")
        items = (node.keys if isinstance(node, ast.Dict) else node.elts
                 if isinstance(node, ast.Tuple | ast.List | ast.Set) else [])
        named = tuple(k.value for k in items if isinstance(k, ast.Constant) and k.value in names)
        if len(named) >= 2 and (where, named) not in CHOSEN:
            found.append(f"{where}:{node.lineno}: a hand-kept list of methods {list(named)}")
    return found


def test_no_module_keeps_its_own_method_titles_colours_or_lists():
    """Anywhere in workbench/ but the registry (the previous main had nine, beside its names.py)."""
    found = [hit for path in sorted((REPO / "workbench").rglob("*.py"))
             if path != REPO / "workbench" / "models" / "registry.py"
             for hit in copies(path.read_text(encoding="utf-8"), str(path.relative_to(REPO)))]
    assert not found, "\n".join(found)


def test_the_drift_check_finds_a_copied_table():
    """The check can fail: the viewer's colour table and a title as they were before the registry."""
    source = 'COLORS = {"proposed": (44, 160, 44), "ioc_only": (214, 39, 40)}\nTITLE = "IOC-only"\n'
    assert len(copies(source, "old.py")) == 2


def test_methods_are_declared_beside_their_classes_and_read_without_importing_them():
    """The registry reads each module's DECLARED_METHODS from its text: no model module (nor numpy) is imported, and
    what it reads is what the module declares."""
    import importlib
    import subprocess
    import sys

    code = ("import sys, workbench.models.registry as r\n"
            "print(len(r.REGISTRY), sorted(m for m in sys.modules if m.startswith(('workbench.models.', 'numpy'))"
            " and m != 'workbench.models.registry'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.split(maxsplit=1) == [str(len(REGISTRY)), "[]\n"]
    for m in REGISTRY:
        module, _, cls = m.model_class.partition(":")
        declared = importlib.import_module(module).DECLARED_METHODS
        assert any(d["name"] == m.name and d["class"] == cls and d["title"] == m.title for d in declared)


def test_a_declaration_that_is_not_a_full_table_is_refused_naming_its_place():
    from workbench.models.registry import _entry
    from workbench.palette import METHOD_COLORS, SPARE_METHOD_COLORS

    with pytest.raises(TypeError, match="here.py:3: a declared method is a table"):
        _entry({"name": "toy", "title": "toy"}, "workbench.models.toy", "here.py:3")
    with pytest.raises(TypeError, match="colour is an index"):
        _entry({"name": "toy", "title": "toy", "class": "Toy", "order": 50, "colour": 99}, "m", "here.py:3")
    order, m = _entry({"name": "toy", "title": "toy", "class": "Toy", "order": 50, "colour": 4}, "pkg.mod", "x")
    assert (order, m.model_class) == (50, "pkg.mod:Toy")
    assert m.colour == SPARE_METHOD_COLORS[4 - len(METHOD_COLORS)]  # the colours after the four are the spare ones
