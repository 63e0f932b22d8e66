"""The README's Python examples: they import only public names, and the ones that need no network or files run."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(encoding="utf-8"), flags=re.S)
# examples that listen on a UDP port or read a user's folder: their imports are checked, they are not run
NEEDS_OUTSIDE = ("mavlink_connection", '"fleet/"')


def test_the_readme_has_examples():
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("block", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_examples_import_only_the_public_faces(block):
    """``from workbench import …`` or a subpackage's public face (``workbench.study``), never a module path."""
    for line in block.splitlines():
        m = re.match(r"\s*from (workbench[\w.]*) import ", line) or re.match(r"\s*import (workbench[\w.]*)", line)
        if m:
            assert m.group(1).count(".") <= 1, f"README imports a module path: {line.strip()}"


@pytest.mark.parametrize("block", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_examples_run(block, tmp_path):
    if any(s in block for s in NEEDS_OUTSIDE):
        code = "\n".join(line for line in block.splitlines() if re.match(r"\s*(from|import) ", line))
    else:
        code = block
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
