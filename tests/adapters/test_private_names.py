"""The pipeline's steps other modules share (the raw view's segment lane walks them: :mod:`adapters.explain`; the
live link checks targets by its rule) are public names of it: a private name (``_spans``) may change with its
module and says nothing of being shared. (The format modules' shared byte layouts are a package's own matter.)"""

from __future__ import annotations

import ast
from pathlib import Path

ADAPTERS = Path(__file__).resolve().parents[2] / "adapters"


def test_no_module_imports_a_private_name_of_the_pipeline():
    private = []
    for path in ADAPTERS.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == "adapters.pipeline":
                private += [f"{path.relative_to(ADAPTERS)}: {node.module}.{a.name}" for a in node.names
                            if a.name.startswith("_") and not a.name.startswith("__")]
    assert not private, private
