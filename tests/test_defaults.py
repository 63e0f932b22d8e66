"""Every default of the shared table (workbench/defaults.py) is the one the library's signatures and the command
line use: a parameter named like an entry (``n_components``, ``n_steps``, ``horizon_s``) that has a number as its
default has the table's number, so changing the table cannot leave a copy behind unnoticed."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import workbench
from workbench import defaults
from workbench.cli.parser import build_parser

TABLE = {"n_components": defaults.N_COMPONENTS, "n_steps": defaults.N_STEPS, "horizon_s": defaults.HORIZON_S}
# the online views' rollout (live, replay) is the short one
ONLINE = {"horizon_s": defaults.ONLINE_HORIZON_S, "n_steps": round(defaults.ONLINE_HORIZON_S / defaults.DT_PAPER_S)}
ONLINE_MODULES = ("workbench.live", "workbench.viewer.replaying", "workbench.viewer.live")
ONLINE_COMMANDS = ("live", "replay")
# a number other than the table's, on purpose: (module, qualified name, parameter) → why
OTHER_ON_PURPOSE = {
    ("workbench.study.evaluate", "per_subject", "n_steps"): "the paper's multi-subject design predicts 5 s",
}


def expected(module: str, parameter: str) -> float:
    return (ONLINE if module.startswith(ONLINE_MODULES) else TABLE).get(parameter, TABLE[parameter])


def _signatures():
    """``(module, qualname, parameter, default)`` for every parameter named in TABLE with a numeric default."""
    skip = ("workbench.cli", "workbench.__main__")
    for info in pkgutil.walk_packages(workbench.__path__, "workbench."):
        if info.name.startswith(skip):
            continue
        module = importlib.import_module(info.name)
        for _, obj in inspect.getmembers(module):
            if getattr(obj, "__module__", None) != info.name:
                continue  # defined elsewhere, found there
            members = [obj] + ([m for _, m in inspect.getmembers(obj, inspect.isfunction)] if inspect.isclass(obj)
                               else [])
            for fn in members:
                try:
                    params = inspect.signature(fn).parameters.values()
                except (TypeError, ValueError):
                    continue
                for p in params:
                    if p.name in TABLE and isinstance(p.default, int | float) and not isinstance(p.default, bool):
                        yield info.name, getattr(fn, "__qualname__", str(fn)), p.name, p.default


def test_the_library_uses_the_tables_defaults():
    found = set(_signatures())
    assert len({(m, q) for m, q, _, _ in found}) >= 8  # the walk finds the signatures (else this checks nothing)
    names = {p for _, _, p, _ in found}
    assert {"n_components", "n_steps"} <= names
    wrong = sorted(f"{m}.{q}({p}={d}), the table says {expected(m, p)}" for m, q, p, d in found
                   if d != expected(m, p) and (m, q, p) not in OTHER_ON_PURPOSE)
    assert not wrong, "\n".join(wrong)


def test_the_command_line_uses_the_tables_defaults():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    seen = 0
    for name, p in sub.choices.items():
        for a in p._actions:
            if a.dest in TABLE and isinstance(a.default, int | float) and not isinstance(a.default, bool):
                seen += 1
                table = ONLINE if name in ONLINE_COMMANDS else TABLE
                assert a.default == table[a.dest], f"workbench {name} {a.option_strings}: {a.default}"
    assert seen >= 4


def test_every_command_resamples_the_objective_as_many_times_by_default():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    found = {name: a.default for name, p in sub.choices.items() for a in p._actions if a.dest == "bootstrap"}
    assert {"fit", "report", "demo"} <= set(found)
    assert set(found.values()) == {defaults.OBJECTIVE_RESAMPLES}, found


def test_the_documented_table_is_the_table():
    """docs/architecture.md's "Defaults" table has one row per entry of workbench/defaults.py, with its value."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## Defaults", 1)[1].split("\n## ", 1)[0]
    rows = dict(re.findall(r"^\| `(\w+)` \| ([^|]+?) \|", section, flags=re.M))
    assert set(rows) == set(defaults.__all__), set(rows) ^ set(defaults.__all__)
    for name, shown in rows.items():
        value = getattr(defaults, name)
        number = re.match(r"[-\d.]+", shown.strip("`\" "))
        if isinstance(value, str):
            assert shown.strip("`\" ") == value, (name, shown)
        elif isinstance(value, tuple):  # a set of choices: every one, in order
            assert [v.strip("`\" ") for v in shown.split(",")] == list(value), (name, shown)
        else:
            assert number and float(number.group()) == float(value), (name, shown)
