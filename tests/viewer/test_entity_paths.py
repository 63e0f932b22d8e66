"""Entity paths are built in one place (workbench/viewer/entities.py): the loggers that write them and the
blueprints that show them call the same functions, so a tab is added by logging under a path made there and
showing that path, and the two cannot drift apart."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from workbench.viewer import entities

VIEWER = Path(__file__).resolve().parents[2] / "workbench" / "viewer"
#: the roots of the paths a session, a replay and a live link log and their blueprints show (the one-word ones,
#: ``key`` and ``scores``, are also view titles: entities.KEY and entities.SCORES, not checked here)
ROOTS = ("demos/", "models/", "label_scores/", "flight/mode")


def _strings(tree: ast.AST) -> list[str]:
    """Every string the code builds (literals and the leading text of f-strings), docstrings left out."""
    docs = {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef) and node.body
            and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    inside = {id(v) for node in ast.walk(tree) if isinstance(node, ast.JoinedStr) for v in node.values}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr) and node.values and isinstance(node.values[0], ast.Constant):
            out.append(str(node.values[0].value))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs | inside:
            out.append(node.value)
    return out


def _own_paths(source: str) -> list[str]:
    return [s for s in _strings(ast.parse(source)) if s.lstrip("+ /").startswith(ROOTS)]


#: every viewer module but the one that builds the paths: the loggers, the blueprints and every tab (a new tab's
#: module is checked the day it is added)
MODULES = sorted(str(p.relative_to(VIEWER)) for p in VIEWER.rglob("*.py") if p.name != "entities.py")


def test_the_modules_are_found():
    assert {"session.py", "blueprint.py", "heldout.py", "replaying.py", "live.py", "tabs/scene.py"} <= set(MODULES)


@pytest.mark.parametrize("module", MODULES)
def test_loggers_and_blueprints_build_no_entity_path_of_their_own(module):
    assert _own_paths((VIEWER / module).read_text(encoding="utf-8")) == []


def test_the_check_finds_a_path_built_by_hand():
    """The check itself can fail: a hand-built trial path, a model's, a mode lane's (not a docstring's)."""
    code = ('"""demos/<id> in a docstring"""\n'
            'a = f"demos/{i}/states/x"\nb = f"+ /models/{m}/summary"\nc = "/flight/mode"\n')
    assert sorted(_own_paths(code)) == ["+ /models/", "/flight/mode", "demos/"]


def test_paths_are_made_of_entity_parts():
    assert entities.series_path("s00 cs1/003", "states", "x dot") == "demos/s00_cs1_003/states/x_dot"
    assert entities.series_path("a", "online", "rollout_end", "phi") == "demos/a/online/rollout_end/phi"
    assert entities.prediction_path("a", 4, "ioc-only", "y", band=True) == "demos/a/predictions/from_4/ioc-only_band/y"
    assert entities.query(entities.mode_path("a")) == "+ /demos/a/mode"
    assert entities.query(entities.model_path("CS1", "heatmap"), recursive=True) == "+ /models/CS1/heatmap/**"
