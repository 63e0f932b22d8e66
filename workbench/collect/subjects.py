"""Subjects of a session: their IDs, their metadata, their consent, kept in ``DIR/_collect/``.

A subject ID is checked by an anchored pattern (the whole text, ``re.fullmatch``: ``"alice\\n"`` is refused, not
read as ``alice``), so an ID is always one safe file-name part. Each subject's record
(``_collect/subjects/<ID>.json``) holds their metadata, consent, order of conditions, calibrations, finished steps,
the starts of their trials and a row per finished trial (what ``trials.csv`` is made of). Every consent answer —
agreed or declined — is also one entry of ``_collect/consent.json`` (the text's SHA-256, the time, the subject).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import re
from pathlib import Path
from typing import Any

from workbench.atomic import atomic_write_text
from workbench.errors import DataError

__all__ = ["SUBJECT_PATTERN", "check_subject", "now", "read_json", "check_fields", "LIMITS"]

SUBJECT_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,39}")
LIMITS = {
    "subjects": 1000,  # registered subjects in one session
    "consent_records": 5000,  # consent answers (declines included) in one session
    "calibrations": 50,  # kept per subject (the newest)
    "starts": 20,  # starts recorded per trial slot
    "field_text": 500,  # characters of a text field's answer
}


def now() -> str:
    """The time now (UTC, ISO 8601 with milliseconds): every record's time stamp."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def check_subject(subject: Any) -> str:
    """``subject`` if it is a subject ID (the whole text matches :data:`SUBJECT_PATTERN`), else one line."""
    if not isinstance(subject, str) or not SUBJECT_PATTERN.fullmatch(subject):
        shown = repr(subject) if isinstance(subject, str | int | float | None) else type(subject).__name__
        raise DataError(f"subject {shown[:60]}: an ID is 1–40 letters, digits, '_' or '-', starting with a letter "
                        "or digit")
    return subject


def read_json(path: Path, what: str) -> Any:
    """A JSON record of the session, or a one-line error naming it when damaged."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: damaged {what} ({exc})") from None


def write_json(path: Path, doc: Any) -> None:
    atomic_write_text(path, json.dumps(doc, indent=1))


def check_fields(protocol: Any, fields: Any) -> dict[str, Any]:
    """A subject's metadata checked against the protocol's fields (types, choices, required, lengths)."""
    if not isinstance(fields, dict):
        raise DataError("subject fields: expected a table of name: value")
    known = {f.name: f for f in protocol.fields}
    if extra := sorted(str(k)[:40] for k in set(fields) - set(known)):
        raise DataError(f"subject fields: {extra[0]!r} is not a field of this protocol")
    out: dict[str, Any] = {}
    for name, f in known.items():
        value = fields.get(name)
        if value in (None, ""):
            if f.required:
                raise DataError(f"subject fields: {f.label} is required")
            continue
        if not isinstance(value, str | int | float) or isinstance(value, bool):
            raise DataError(f"subject fields: {f.label}: expected text or a number")
        if isinstance(value, str) and len(value) > LIMITS["field_text"]:
            raise DataError(f"subject fields: {f.label}: longer than {LIMITS['field_text']} characters")
        if f.type == "number":
            try:
                value = float(value)
            except (TypeError, ValueError, OverflowError):
                raise DataError(f"subject fields: {f.label}: {str(value)[:40]!r} is not a number") from None
            if not math.isfinite(value) or abs(value) > 1e12:
                raise DataError(f"subject fields: {f.label}: {str(value)[:40]!r} is not a number of sensible size")
        elif f.type == "choice" and value not in f.choices:
            raise DataError(f"subject fields: {f.label}: {str(value)[:40]!r} is not one of {', '.join(f.choices)}")
        else:
            value = str(value)
        out[name] = value
    return out
