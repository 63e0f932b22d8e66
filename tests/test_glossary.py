"""The glossary's words in the code (docs/architecture.md, Glossary), held as tests/models/test_registry.py holds
the method lists: no identifier says ``system`` for the plant (the word is plant) nor ``noise_horizon`` without
its unit. ``system`` stays where it is a MAVLink system id: adapters/ (and its tests) and the ``system=`` that
OnlinePredictor (workbench/live/predictor.py) hands to the link reader. Class names (``LinearSystem``, Python's
``SystemExit``) are the type's own and are not read here."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TREES = ("workbench", "bench", "tests")
# a word of a snake_case identifier -> the glossary's word
BANNED = {"system": "plant", "systems": "plants"}
# whole identifiers -> the glossary's
BANNED_WHOLE = {"noise_horizon": "noise_horizon_s"}
# (file, identifier): the word means something else there, with why
ALLOWED = {
    ("workbench/live/predictor.py", "system"): "OnlinePredictor(system=): the MAVLink system id to follow",
}
# other libraries' names, spelled as they spell them
THEIRS = {
    "system_status": "MAVLink HEARTBEAT's field",
    "target_system": "MAVLink's addressed system id",
    "color_system": "rich.Console's keyword",
}
# calls whose keyword ``system=`` is a MAVLink system id
MAVLINK_CALLS = {"OnlinePredictor", "MavlinkReader"}


def _called(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def identifiers(source: str) -> list[tuple[int, str]]:
    """(line, identifier) for every name the code defines or uses: names, arguments, attributes, keywords,
    functions and classes, imported names; the module ``workbench.plant.system`` is a path, not a word."""
    tree = ast.parse(source)
    mavlink = {id(k) for n in ast.walk(tree) if isinstance(n, ast.Call) and _called(n) in MAVLINK_CALLS
               for k in n.keywords}
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Name):
            out.append((n.lineno, n.id))
        elif isinstance(n, ast.arg):
            out.append((n.lineno, n.arg))
        elif isinstance(n, ast.Attribute):
            path = isinstance(n.value, ast.Attribute | ast.Name) and getattr(n.value, "attr", getattr(n.value, "id",
                                                                                                    "")) == "plant"
            if not (path and n.attr == "system"):
                out.append((n.lineno, n.attr))
        elif isinstance(n, ast.keyword) and n.arg is not None and id(n) not in mavlink:
            out.append((n.lineno, n.arg))
        elif isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            out.append((n.lineno, n.name))
        elif isinstance(n, ast.ImportFrom):
            out += [(n.lineno, a.asname or a.name) for a in n.names
                    if not ((n.module or "").endswith("plant") and a.name == "system" and a.asname is None)]
    return out


def off_glossary(name: str) -> str | None:
    """The glossary's word for ``name``, or None when ``name`` follows it."""
    if name in THEIRS:
        return None
    if name in BANNED_WHOLE:
        return BANNED_WHOLE[name]
    words = name.strip("_").split("_")
    if name != name.lower() or not any(w in BANNED for w in words):
        return None
    return "_".join(BANNED.get(w, w) for w in words)


def findings(source: str, where: str) -> list[str]:
    return [f"{where}:{line}: {name} (the glossary's word: {word})" for line, name in identifiers(source)
            if (word := off_glossary(name)) is not None and (where, name) not in ALLOWED]


def test_no_identifier_leaves_the_glossary():
    found, seen = [], 0
    for tree in TREES:
        for path in sorted((REPO / tree).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            if "adapters" in path.relative_to(REPO).parts[:-1]:
                continue  # MAVLink's system ids
            seen += 1
            found += findings(path.read_text(encoding="utf-8"), rel)
    assert seen > 100  # the walk reads the tree (else this checks nothing)
    assert not found, "\n".join(sorted(set(found)))


def test_the_check_finds_what_it_bans_and_leaves_the_rest():
    planted = ("def fit(system, noise_horizon=3.0):\n"
               "    systems = [system]\n"
               "    return model.system_for(systems)\n")
    hits = findings(planted, "x.py")
    assert [h.split(": ")[1].split(" ")[0] for h in hits].count("system") == 2, hits
    assert any("noise_horizon (the glossary's word: noise_horizon_s)" in h for h in hits)
    assert any("system_for (the glossary's word: plant_for)" in h for h in hits)
    assert any("systems (the glossary's word: plants)" in h for h in hits)
    fine = ("from workbench.plant.system import LinearSystem\n"
            "import workbench.plant.system\n"
            "p = OnlinePredictor(model, 'planar_quadrotor', system=1)\n"
            "x = workbench.plant.system.planar_quadrotor()\n"
            "raise SystemExit(plant.A)\n")
    assert findings(fine, "x.py") == []
