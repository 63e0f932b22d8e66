"""The layout of ../shared/DESIGN.md, checked: imports point down, and the core runs headless."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# floor 4: what a user touches; nothing below may import it
TOP = ("workbench.cli", "workbench.__main__", "workbench.viewer", "workbench.report", "workbench.sample_logs",
       "workbench.live")  # live joins the adapters' online path and a model, like the CLI joins them offline
# the common format: the only part of workbench the adapters may use
COMMON = ("workbench.demos", "workbench.dataset", "workbench.errors", "workbench.atomic", "workbench.roles")
# floor 1: the common format and the plant; it imports nothing above it
FLOOR1 = (*COMMON, "workbench.system", "workbench.identification", "workbench.frozen")
# floor 3: the pipelines over models; the method and the models (floor 2) never import them
FLOOR3 = ("workbench.study", "workbench.evaluate", "workbench.stats", "workbench.executor")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return {name for name in found if name.split(".")[0] in ("workbench", "adapters")}


def _under(name: str, prefixes) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


MODULES = {
    _module_name(p): _imports(p) for pkg in ("workbench", "adapters") for p in sorted((REPO / pkg).rglob("*.py"))
}


@pytest.mark.parametrize("module", sorted(m for m in MODULES if not _under(m, TOP)))
def test_nothing_below_the_top_floor_imports_it(module):
    assert not {i for i in MODULES[module] if _under(i, TOP)}, f"{module} imports the CLI, viewer or report"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _under(m, TOP) and m != "workbench.__main__"))
def test_nothing_imports_the_cli(module):
    assert not {i for i in MODULES[module] if _under(i, ("workbench.cli",))}


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _under(m, FLOOR1)))
def test_floor_one_imports_nothing_above_it(module):
    above = {i for i in MODULES[module] if i.startswith("workbench.") and not _under(i, FLOOR1)}
    assert not above, f"{module} imports {sorted(above)}"


@pytest.mark.parametrize(
    "module", sorted(m for m in MODULES if m.startswith("workbench.") and not _under(m, (*TOP, *FLOOR1, *FLOOR3)))
)
def test_the_method_and_models_never_import_the_pipelines(module):
    assert not {i for i in MODULES[module] if _under(i, FLOOR3)}, f"{module} imports a study pipeline"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m.startswith("adapters")))
def test_adapters_meet_the_core_only_in_the_common_format(module):
    other = {i for i in MODULES[module] if i.startswith("workbench") and not _under(i, COMMON)}
    assert not other, f"{module} imports {sorted(other)}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m.startswith("workbench") and not _under(m, TOP)))
def test_the_core_never_imports_adapters(module):
    assert not {i for i in MODULES[module] if i.startswith("adapters")}


def test_core_runs_headless_without_rerun_matplotlib_or_dask():
    # live.py is on the top floor but has no rerun inside; the executor imports Dask only when asked for workers
    code = (
        "import sys, adapters, workbench.model, workbench.evaluate, workbench.study, workbench.simulate\n"
        "import workbench.executor, workbench.dataset, workbench.weights, workbench.autoconfig, workbench.live\n"
        "print(sorted(m for m in ('rerun', 'matplotlib', 'dask', 'distributed') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"


HEAVY = ("pandas", "pyarrow", "cvxpy", "sklearn", "scipy", "numpy")


@pytest.mark.parametrize(
    "code",
    [
        "import adapters, workbench",
        "import sys; from workbench.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass",
        "import sys; from workbench.cli import main\ntry:\n    main(['fit', '--help'])\nexcept SystemExit:\n    pass",
    ],
    ids=["import adapters", "workbench --help", "workbench fit --help"],
)
def test_startup_imports_no_heavy_library(code):
    """Startup stays fast only while the heavy libraries load where they are used (issue 11: --help <= 0.25 s)."""
    probe = f"{code}\nimport sys\nprint(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r})))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip().splitlines()[-1] == "[]"
