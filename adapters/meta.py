"""Per-demonstration metadata carried by a log: id, label (strategy), subject, target, success, outcome.

Two carriers, named by a mapping's ``[meta]`` table:

* a **table** stream (``source``): one row per demonstration (an MCAP ``/workbench/demo`` topic), or rows
  repeating it (a CSV's sidecar columns); the ``key`` column holds the demonstration's demo-field value and
  the first row per key counts. Array columns ``target[0]``, ``target[1]``, … become a list.
* **text markers** (``text``), for logs that carry only text (a tlog's ``STATUSTEXT``): messages of the form
  ``"wb demo=3 label=CS1 subject=s00 target[0]=0.5"`` (prefix ``wb``, then ``key=value`` pairs, several
  messages per demonstration allowed). A marker without ``demo=`` applies to the demonstration that contains
  it or, failing that, the next one to start.

Values are typed on the way in: ``True``/``False`` → bool, numbers → int or float, anything else text.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from typing import Any

import numpy as np
import pandas as pd

from adapters.segment import demo_key

__all__ = ["table_meta", "text_meta", "parse_marker", "format_markers", "typed"]

_INDEXED = re.compile(r"^(.*)\[(\d+)\]$")


def typed(value: Any) -> Any:
    """A metadata value as a plain Python value (text parsed to bool / int / float where it is one)."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if not isinstance(value, str):
        return value
    text = value.strip()
    if text in ("True", "true"):
        return True
    if text in ("False", "false"):
        return False
    try:
        return int(text)
    except ValueError:
        pass
    try:
        number = float(text)
    except ValueError:
        return text
    return number if math.isfinite(number) else None


def _gather(items: Iterable[tuple[str, Any]], fields: tuple[str, ...]) -> dict[str, Any]:
    """Keep the wanted fields; fold ``name[i]`` entries into lists; drop missing values."""
    out: dict[str, Any] = {}
    arrays: dict[str, dict[int, Any]] = {}
    for key, value in items:
        value = typed(value)
        if value is None:
            continue
        m = _INDEXED.match(key)
        if m and m.group(1) in fields:
            arrays.setdefault(m.group(1), {})[int(m.group(2))] = value
        elif key in fields:
            out[key] = value
    for name, parts in arrays.items():
        if sorted(parts) == list(range(len(parts))):
            out[name] = [parts[i] for i in range(len(parts))]
    return out


def table_meta(frame: pd.DataFrame, rows: np.ndarray, key: str, fields: tuple[str, ...]) -> dict[str, dict]:
    """Metadata by demo key from a table stream (first row per key)."""
    if key not in frame.columns:
        return {}
    sub = frame.loc[rows] if rows is not None else frame
    out: dict[str, dict] = {}
    columns = [c for c in sub.columns if c not in ("t", key)]
    keys = sub[key].tolist()
    records = sub[columns].to_dict("records") if columns else [{} for _ in keys]
    for k, record in zip(keys, records, strict=True):
        dk = demo_key(k)
        if dk is not None and dk not in out:
            out[dk] = _gather(record.items(), fields)
    return out


def parse_marker(text: str, prefix: str = "wb") -> dict[str, str] | None:
    """The ``key=value`` pairs of a text marker, or ``None`` when the text is not one."""
    if not isinstance(text, str):
        return None
    parts = text.strip().split()
    if not parts or parts[0] != prefix:
        return None
    pairs = {}
    for part in parts[1:]:
        k, sep, v = part.partition("=")
        if sep and k:
            pairs[k] = v
    return pairs


def text_meta(
    t: np.ndarray, texts: list[Any], fields: tuple[str, ...], prefix: str = "wb"
) -> tuple[dict[str, dict], list[tuple[float, dict]]]:
    """Metadata from text markers: (by demo key, [(time, meta) of markers without a demo key])."""
    by_key: dict[str, list[tuple[str, str]]] = {}
    loose: list[tuple[float, dict]] = []
    for time, text in zip(t.tolist(), texts, strict=True):
        pairs = parse_marker(text, prefix)
        if pairs is None:
            continue
        dk = demo_key(typed(pairs.pop("demo"))) if "demo" in pairs else None
        if dk is None:
            loose.append((float(time), _gather(pairs.items(), fields)))
        else:
            by_key.setdefault(dk, []).extend(pairs.items())
    return {k: _gather(v, fields) for k, v in by_key.items()}, loose


def _text(value: Any) -> str:
    if isinstance(value, np.generic):
        value = value.item()
    return repr(value) if isinstance(value, float) else str(value)


def format_markers(demo: Any, meta: dict[str, Any], prefix: str = "wb", width: int = 50) -> list[str]:
    """Text markers carrying ``meta`` for demo ``demo``, each at most ``width`` characters (STATUSTEXT: 50).

    Values must not contain spaces; lists become ``name[i]=v`` pairs.
    """
    pairs = []
    for key, value in meta.items():
        if value is None:
            continue
        if isinstance(value, list | tuple):
            pairs += [f"{key}[{i}]={_text(v)}" for i, v in enumerate(value)]
        else:
            text = _text(value)
            if not text or any(c.isspace() for c in text):
                raise ValueError(f"metadata {key}={value!r} cannot be a text marker value (empty or has spaces)")
            pairs.append(f"{key}={text}")
    head = f"{prefix} demo={demo}"
    out, line = [], head
    for pair in pairs:
        if len(head) + 1 + len(pair) > width:
            raise ValueError(f"metadata pair {pair!r} does not fit a {width}-character marker")
        if len(line) + 1 + len(pair) > width:
            out.append(line)
            line = head
        line += " " + pair
    if line != head or not out:
        out.append(line)
    return out
