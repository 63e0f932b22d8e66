"""Every default of the table (workbench/defaults.py) by reference, never by copy (issue 39 §2): a signature
whose parameter is named like an entry and whose default is a number equal to the entry names the constant
(``n_steps: int = N_STEPS``), and no module keeps its own assignment of a table name. A copy would stay behind
when the table changes; tests/test_defaults.py checks the values, this checks they are not copied. Read from the
source (ast), so nested and private functions count too."""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

from workbench import defaults

REPO = Path(__file__).resolve().parents[1]
# parameter -> the table's entries a default of it may copy
PARAMETERS = {
    "n_components": ("N_COMPONENTS", "PAPER_N_COMPONENTS"),
    "n_steps": ("N_STEPS", "ONLINE_N_STEPS"),
    "horizon_s": ("HORIZON_S", "ONLINE_HORIZON_S"),
    "noise_horizon_s": ("NOISE_HORIZON_S",),
    "reg_covar": ("REG_COVAR",),
    "samples": ("STUDY_SAMPLES",),
    "n_boot": ("PAIRED_RESAMPLES", "GAIN_RESAMPLES", "OBJECTIVE_RESAMPLES"),
    "bootstrap": ("OBJECTIVE_RESAMPLES",),
    "dt": ("DT_PAPER_S",),
}


def copies(source: str, where: str) -> list[str]:
    values = {p: {getattr(defaults, c) for c in cs} for p, cs in PARAMETERS.items()}
    found = []
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        a = node.args
        pos = a.posonlyargs + a.args
        pairs = list(zip(pos[len(pos) - len(a.defaults):], a.defaults, strict=True))
        pairs += [(k, d) for k, d in zip(a.kwonlyargs, a.kw_defaults, strict=True) if d is not None]
        for arg, d in pairs:
            if (isinstance(d, ast.Constant) and type(d.value) in (int, float) and arg.arg in values
                    and d.value in values[arg.arg]):
                found.append(f"{where}:{d.lineno}: {node.name}({arg.arg}={d.value!r}) copies the table: name "
                             f"{' or '.join(PARAMETERS[arg.arg])}")
    for node in tree.body:
        if isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                if isinstance(t, ast.Name) and t.id in defaults.__all__:
                    found.append(f"{where}:{node.lineno}: {t.id} is the table's; import it from workbench.defaults")
    return found


def test_no_signature_copies_a_table_value():
    found, seen = [], 0
    for path in sorted((REPO / "workbench").rglob("*.py")):
        if path.name == "defaults.py" and path.parent.name == "workbench":
            continue
        seen += 1
        found += copies(path.read_text(encoding="utf-8"), path.relative_to(REPO).as_posix())
    assert seen > 100
    assert not found, "\n".join(found)


def test_the_check_finds_a_copy():
    planted = ("N_COMPONENTS = 5\n"
               "def f(n_steps=60, horizon_s=HORIZON_S, samples=0, n_boot=4000, other=60):\n    pass\n")
    hits = copies(planted, "x.py")
    assert len(hits) == 3, hits
    assert "f(n_steps=60)" in hits[0] or any("f(n_steps=60)" in h for h in hits)
    assert any("n_boot=4000" in h for h in hits) and any("N_COMPONENTS is the table's" in h for h in hits)


DEFAULT_SAID = re.compile(r"\(default (-?\d+(?:\.\d+)?)")


def _options():
    """(command, option, help, default) of every option of every command."""
    from workbench.cli.parser import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for command, p in sub.choices.items():
        for action in p._actions:
            for option in action.option_strings:
                yield command, option, action.help or "", action.default


def test_help_says_the_defaults_it_has():
    """Every ``(default N)`` in ``--help`` is the option's default (test_defaults.py checks those defaults against
    the table)."""
    seen, wrong = 0, []
    for command, option, text, default in _options():
        said = DEFAULT_SAID.search(text)
        if said and isinstance(default, int | float) and not isinstance(default, bool):
            seen += 1
            if float(said.group(1)) != float(default):
                wrong.append(f"{command} {option}: its help says {said.group(1)}, its default is {default}")
    assert seen >= 10
    assert not wrong, "\n".join(wrong)


def readme_defaults(text: str) -> list[tuple[str, float]]:
    """(option, N) for every README phrase naming an option and, before the sentence ends, ``(default N)``."""
    return [(m.group(1), float(said.group(1)))
            for m in re.finditer(r"`(--[a-z][a-z-]*)[^`]*`([^.|`]{0,80})", text)
            if (said := DEFAULT_SAID.search(m.group(2)))]


def test_the_readme_says_the_defaults_the_command_line_has():
    """A README sentence naming an option with ``(default N)`` states the option's default (the README once said
    ``collect --horizon`` was 5 s where the code used 3)."""
    defaults_of: dict[str, set[float]] = {}
    for _, option, _, default in _options():
        if isinstance(default, int | float) and not isinstance(default, bool):
            defaults_of.setdefault(option, set()).add(float(default))
    said = readme_defaults((REPO / "README.md").read_text(encoding="utf-8"))
    assert said, "the README states no default of an option (else this checks nothing)"
    wrong = [f"README: {o} (default {n:g}); the command line's is {sorted(defaults_of[o])}" for o, n in said
             if o in defaults_of and n not in defaults_of[o]]
    assert not wrong, "\n".join(wrong)
    assert readme_defaults("`--stride` seconds (default 2) of each") == [("--stride", 2.0)]
