"""The layout of docs/architecture.md, checked: floors by subpackage prefix, imports point down, no cycles.

The rules name prefixes, not modules, so a module is checked the day it is added; a module under no floor's
prefix fails :func:`test_every_module_is_on_a_floor` until the architecture says where it belongs.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# floor -> the prefixes on it; a module may import its own floor and the floors below, never above
FLOORS: dict[int, tuple[str, ...]] = {
    0: ("workbench.errors", "workbench.atomic", "workbench.frozen", "workbench.threads", "workbench.exports",
        "workbench.interrupts", "workbench.defaults", "workbench.palette"),
    1: ("workbench.data",),
    2: ("workbench.plant", "workbench.method", "workbench.sim", "adapters"),
    3: ("workbench.models",),
    4: ("workbench.study",),
    5: ("workbench.viewer", "workbench.report", "workbench.live", "workbench.collect"),
    6: ("workbench.cli", "workbench.__main__"),
}
ROOT = "workbench"  # the package's public face (floor 0: it imports only the errors; the rest lazily)
# on one floor, peers meet only where these allow: (importer, imported)
PEERS_ALLOWED: tuple[tuple[str, str], ...] = (
    ("workbench.method", "workbench.plant"),
    ("workbench.sim", "workbench.plant"),
    ("workbench.sim", "workbench.method"),
    ("workbench.viewer", "workbench.live"),  # the live view draws the online predictor's output
    ("workbench.__main__", "workbench.cli"),
)
# the method and the models know arrays and DemonstrationSets, never files or links
NEVER: tuple[tuple[str, str], ...] = (
    ("workbench.plant", "adapters"),
    ("workbench.method", "adapters"),
    ("workbench.sim", "adapters"),
    ("workbench.models", "adapters"),
    ("workbench.study", "adapters"),
    ("workbench.report", "adapters"),
    ("adapters", "workbench.plant"),
    ("adapters", "workbench.method"),
    ("adapters", "workbench.sim"),
)


def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(source: str, name: str) -> set[str]:
    """Every workbench/adapters module ``source`` imports, at module level, inside functions (a lazy import is
    still an arrow) or under ``if TYPE_CHECKING:`` (a type named from above is knowledge of it: two modules that
    name each other's types are one room in two files); ``from pkg import mod`` counts as ``pkg.mod``."""
    found: set[str] = set()
    package = name if name in PACKAGES else name.rpartition(".")[0]

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            # ``from pkg import mod`` is an arrow to pkg.mod; to pkg itself only for a name its __init__ defines
            for alias in node.names:
                found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in ALL_MODULES else base)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(source))
    found.discard(name)
    return {i for i in found if i.split(".")[0] in ("workbench", "adapters")}


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def floor_of(name: str) -> tuple[int, str] | None:
    if name == ROOT:
        return 0, ROOT
    hits = [(f, p) for f, ps in FLOORS.items() for p in ps if _under(name, p)]
    return max(hits, key=lambda h: len(h[1])) if hits else None


def violations(graph: Mapping[str, set[str]]) -> list[str]:
    """Every import in ``graph`` (module -> modules it imports) that breaks a rule, as one line each."""
    out = []
    for module, imported in sorted(graph.items()):
        mine = floor_of(module)
        for target in sorted(imported):
            theirs = floor_of(target)
            if mine is None or theirs is None:
                continue  # reported by test_every_module_is_on_a_floor
            if theirs[0] > mine[0]:
                out.append(f"{module} (floor {mine[0]}) imports {target} (floor {theirs[0]}): an arrow back up")
            elif theirs[0] == mine[0] > 0 and theirs[1] != mine[1] and (mine[1], theirs[1]) not in PEERS_ALLOWED:
                out.append(f"{module} imports its peer {target} on floor {mine[0]} (not in PEERS_ALLOWED)")
            if any(_under(module, a) and _under(target, b) for a, b in NEVER):
                out.append(f"{module} imports {target}: never allowed")
    return out


def cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """The import cycles of ``graph`` (strongly connected components of more than one module, or a self-loop)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    sys.setrecursionlimit(10_000)

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in graph:
        if v not in index:
            strong(v)
    return found


PATHS = {module_name(p): p for pkg in ("workbench", "adapters") for p in sorted((REPO / pkg).rglob("*.py"))}
ALL_MODULES = set(PATHS)
PACKAGES = {module_name(p) for p in PATHS.values() if p.name == "__init__.py"}
GRAPH = {name: imports_of(p.read_text(encoding="utf-8"), name) for name, p in PATHS.items()}


def test_every_module_is_on_a_floor():
    lost = sorted(m for m in GRAPH if floor_of(m) is None)
    assert not lost, f"modules on no floor (add their subpackage to FLOORS and docs/architecture.md): {lost}"


def test_imports_point_down():
    found = violations(GRAPH)
    assert not found, "\n".join(found)


def test_no_import_cycles():
    assert not cycles(GRAPH)


def test_the_rules_catch_a_back_import_and_a_cycle():
    """The checker itself can fail: a deliberately added arrow back up, a forbidden peer and a cycle."""
    graph = {k: set(v) for k, v in GRAPH.items()}
    graph["workbench.data.new_module"] = {"workbench.models.proposed"}
    graph["workbench.method.gmr"] = graph["workbench.method.gmr"] | {"adapters.mapping"}
    found = violations(graph)
    assert any("workbench.data.new_module (floor 1) imports workbench.models.proposed" in f for f in found)
    assert any("workbench.method.gmr imports adapters.mapping" in f for f in found)
    graph["workbench.data.roles"] = graph["workbench.data.roles"] | {"workbench.data.new_module"}
    graph["workbench.data.new_module"] = {"workbench.data.roles"}
    assert ["workbench.data.new_module", "workbench.data.roles"] in cycles(graph)
    # a type imported only for annotations is an arrow too (the circles issue 39 found hid there)
    hidden = "if TYPE_CHECKING:\n    from workbench.models.behavior import BehaviorModel\n"
    assert imports_of(hidden, "workbench.models.storage") == {"workbench.models.behavior"}


def test_the_tree_and_the_architecture_page_agree():
    """docs/architecture.md names every floor's prefixes; every subpackage of workbench/ is on it."""
    page = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    for prefixes in FLOORS.values():
        for prefix in prefixes:
            shown = prefix.replace(".", "/") + ("/" if (REPO / prefix.replace(".", "/")).is_dir() else ".py")
            assert f"`{shown}`" in page, f"docs/architecture.md does not show {shown}"
    for sub in (REPO / "workbench").iterdir():
        if (sub / "__init__.py").exists():
            assert floor_of(f"workbench.{sub.name}") is not None, f"workbench/{sub.name}/ is on no floor"


def test_workbench_has_few_modules_at_its_top_and_none_too_long():
    top = sorted(p.name for p in (REPO / "workbench").glob("*.py"))
    assert len(top) <= 10, top  # the tenth: palette.py, the one palette the viewer and the report share
    long = {str(p.relative_to(REPO)): n for p in PATHS.values() if (n := len(p.read_text().splitlines())) > 800}
    assert not long, long


def test_core_runs_headless_without_rerun_matplotlib_or_dask():
    # live is on the top floor but has no rerun inside; the executor imports Dask only when asked for workers
    code = (
        "import sys, adapters, workbench.models.proposed, workbench.study.evaluate, workbench.study.pipeline\n"
        "import workbench.sim.landing, workbench.study.executor, workbench.data.dataset, workbench.study.weights\n"
        "import workbench.models.autoconfig, workbench.live.predictor\n"
        "print(sorted(m for m in ('rerun', 'matplotlib', 'dask', 'distributed') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"


HEAVY = ("pandas", "pyarrow", "cvxpy", "sklearn", "scipy", "numpy")


@pytest.mark.parametrize(
    "code",
    [
        "import adapters, workbench",
        "import workbench.data, workbench.plant, workbench.method, workbench.models, workbench.study",
        "import sys; from workbench.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass",
        "import sys; from workbench.cli import main\ntry:\n    main(['fit', '--help'])\nexcept SystemExit:\n    pass",
    ],
    ids=["import adapters", "import the subpackages", "workbench --help", "workbench fit --help"],
)
def test_startup_imports_no_heavy_library(code):
    """Startup stays fast only while the heavy libraries load where they are used (issue 11: --help <= 0.25 s)."""
    probe = f"{code}\nimport sys\nprint(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r})))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_no_public_name_shadows_a_submodule():
    """``from workbench.method import inverse_lqr`` must give the function, not a module of the same name."""
    import importlib

    for package in sorted(PACKAGES):
        if not package.startswith("workbench.") or package.count(".") != 1:
            continue
        exports = set(getattr(importlib.import_module(package), "__all__", ()))
        submodules = {p.stem for p in (REPO / package.replace(".", "/")).glob("*.py")}
        assert not set(exports) & submodules, f"{package}: {sorted(set(exports) & submodules)}"


#: Folders whose modules a registry finds (adapters.formats imports every declared format, workbench.viewer.tabs every
#: tab): the tree names the folder and the registry lists its members (adapters.formats.describe()); a list in the tree
#: too would be one more place a new format or tab must be added.
REGISTRY_FOLDERS = ("adapters/formats/declared", "workbench/viewer/tabs")


def test_the_architecture_page_lists_every_module():
    """The tree in docs/architecture.md names every module, so the record of the floors stays the tree's."""
    page = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    tree = page.split("## The tree", 1)[1]
    registered = {REPO / f for f in REGISTRY_FOLDERS}
    missing = sorted(str(p.relative_to(REPO)) for p in PATHS.values()
                     if p.name != "__init__.py" and p.parent not in registered
                     and not re.search(rf"(?<![\w.]){re.escape(p.name)}\b", tree))
    assert not missing, f"docs/architecture.md's tree lacks {missing}"
    for folder in REGISTRY_FOLDERS:
        assert f"{Path(folder).name}/" in tree, f"docs/architecture.md's tree lacks {folder}/"
