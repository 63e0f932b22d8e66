"""MAVLink's enumerations are pymavlink's, never copied into adapters/ (adapters/modes.py): a copy goes stale when
the dialect grows, and two tables can disagree."""

from __future__ import annotations

import ast
from pathlib import Path

from pymavlink import mavutil

ADAPTERS = Path(__file__).resolve().parents[2] / "adapters"


def _code_strings(tree: ast.AST) -> list[str]:
    """The string constants of a module's code, without its docstrings (a bare string statement)."""
    docs = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)}
    return [n.value for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]


def test_no_module_of_adapters_spells_out_a_mavlink_enumeration_value():
    names = {e.name for values in mavutil.mavlink.enums.values() for e in values.values()}
    names = {n for n in names if not n.endswith("_ENUM_END")}
    copied = {}
    for path in ADAPTERS.rglob("*.py"):
        hits = sorted(names.intersection(_code_strings(ast.parse(path.read_text()))))
        if hits:
            copied[str(path.relative_to(ADAPTERS))] = hits
    assert not copied, copied


def test_the_landed_rule_names_heartbeat_states_by_pymavlink():
    from adapters.events import MAV_STATES, flag_value_name

    standby = mavutil.mavlink.MAV_STATE_STANDBY
    assert flag_value_name("HEARTBEAT.system_status", standby) == "MAV_STATE_STANDBY"
    assert MAV_STATES == {k: e.name for k, e in mavutil.mavlink.enums["MAV_STATE"].items() if k != max(
        mavutil.mavlink.enums["MAV_STATE"])}
