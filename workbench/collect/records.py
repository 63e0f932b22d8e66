"""What a session leaves for the analyst beside its trials: ``trials.csv``, the data dictionary, exclusions.

* ``DIR/_collect/trials.csv`` — one line per finished trial (:data:`COLUMNS`), rewritten after every trial and
  every exclusion from the subjects' records (never from a counter a kill could leave behind).
* ``DIR/_collect/data_dictionary.md`` — every column of a trial's partition and of ``trials.csv``, every
  metadata key of a trial, and the subject fields the protocol asks for, with units.
* :func:`set_exclusion` — the experimenter's exclusion of a trial (``excluded``, ``exclusion_note`` in the trial's
  own metadata, its partition rewritten atomically): from ``workbench collect --out DIR --exclude ID`` or the
  experimenter's page. Every analysis leaves excluded trials out by default and says so.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

from workbench.atomic import atomic_write_text
from workbench.collect.subjects import now, read_json, write_json
from workbench.errors import DataError

__all__ = ["COLUMNS", "META_KEYS", "trial_row", "write_trials_csv", "write_data_dictionary", "set_exclusion",
           "find_trial", "MAX_NOTE"]

HIDDEN = "_collect"
MAX_NOTE = 1000

#: The columns of ``trials.csv``: name and meaning (with units).
COLUMNS: tuple[tuple[str, str], ...] = (
    ("subject", "the subject's ID"),
    ("id", "the trial's ID, `<subject>-<slot>-<label>-<role>`: its partition's file name and its `demo` column"),
    ("slot", "the trial's place in the subject's session (0-based, stable across resumes)"),
    ("label", "the strategy label of its block (CS1, CS2, landing …)"),
    ("role", "train or test (a held-out trial is test)"),
    ("trial", "its number within its block, from 1"),
    ("block", "its block's index in the protocol's [[blocks]] (0-based)"),
    ("outcome", "landed, crashed, left the domain or time limit"),
    ("outcome_reason", "why, with the numbers against the rules (e.g. crashed: 0.420 m/s ≥ 0.1 m/s)"),
    ("samples", "physics steps recorded (one per 0.05 s)"),
    ("duration_s", "simulated time flown, s"),
    ("started", "when the subject started it (server clock, UTC ISO 8601)"),
    ("finished", "when the server wrote it (UTC ISO 8601)"),
    ("attempts", "how many times it was started (more than 1: an earlier start was interrupted and lost)"),
    ("interruptions", "events during it (page hidden, focus lost, pad disconnected) and lost earlier starts"),
    ("device", "gamepad or keyboard"),
    ("deadzone", "the sticks' dead zone in use (fraction of full deflection)"),
    ("expo", "the expo in use: u = (1 − e) v + e v³"),
    ("gamepad_rule", "how a physics step took the pad's display-rate reads: latest or mean"),
    ("assist", "none, show (the model's path drawn) or blend"),
    ("blend", "the model's share α of the input in a blend trial"),
    ("model_source", "fit (this subject's fit step) or given (--model); empty without assistance"),
    ("model_digest", "SHA-256 of the model file that assisted it"),
    ("condition_order", "the subject's order of conditions and how it was chosen"),
    ("excluded", "true when the experimenter excluded the trial from the analysis"),
    ("exclusion_note", "the experimenter's reason"),
)

#: The metadata keys of a collected trial (``Demonstration.meta``; each partition's Parquet metadata).
META_KEYS: tuple[tuple[str, str], ...] = (
    ("id", "the trial's ID (as in trials.csv)"),
    ("subject", "the subject's ID"),
    ("label", "the block's strategy label"),
    ("role", "train, test"),
    ("trial", "number within the block, from 1"),
    ("slot", "place in the subject's session, 0-based"),
    ("block", "index of its block in the protocol's [[blocks]]"),
    ("start", "the start state x₀ (one value per state), drawn from the seed, subject and slot"),
    ("target", "the target state (the pad)"),
    ("outcome", "landed, crashed, left the domain, time limit"),
    ("outcome_reason", "why, with numbers"),
    ("success", "outcome == landed"),
    ("source", "workbench collect"),
    ("protocol", "the protocol's name"),
    ("protocol_fingerprint", "SHA-256 of the protocol as the session ran it (see _collect/session.json)"),
    ("subject_fields", "the subject's answers to the protocol's fields"),
    ("consent_sha256", "SHA-256 of the consent text the subject agreed to"),
    ("condition_order", "{conditions: [...], why: ...}: the subject's order of conditions"),
    ("device", "the input device as the page described it (kind, id, mapping)"),
    ("calibration", "rest offsets, axes, signs, dead zone, expo, rule (gamepad) or ramp (keyboard)"),
    ("input", "the protocol's input settings in force: device allowed, dead zone, expo, gamepad rule"),
    ("timing", "display frames, late and dropped physics steps, wall duration (s)"),
    ("started", "server time the subject started it (UTC ISO 8601), or null"),
    ("finished", "server time it was written"),
    ("attempts", "starts of this slot"),
    ("interruptions", "[{t_s, kind, duration_s}] from the page; {kind: restarted, at} for lost earlier starts"),
    ("assist", "assisted trials: {kind, alpha, K, law, model: {source, digest, data_digest}}"),
    ("pilot_u", "assisted trials: the pilot's own input per step; the `u` columns are what the plant received"),
    ("excluded", "true: left out of every analysis by default"),
    ("exclusion_note", "the experimenter's reason"),
)


def trial_row(meta: dict[str, Any], n_samples: int, dt: float) -> dict[str, Any]:
    """The ``trials.csv`` line of a trial, from its metadata."""
    cal, assist = meta.get("calibration") or {}, meta.get("assist") or {}
    model = assist.get("model") or {}
    order = meta.get("condition_order") or {}
    gaps = meta.get("interruptions") or []
    return {
        "subject": meta.get("subject"), "id": meta.get("id"), "slot": meta.get("slot"), "label": meta.get("label"),
        "role": meta.get("role"), "trial": meta.get("trial"), "block": meta.get("block"),
        "outcome": meta.get("outcome"), "outcome_reason": meta.get("outcome_reason", ""), "samples": n_samples,
        "duration_s": round((n_samples - 1) * dt, 6), "started": meta.get("started") or "",
        "finished": meta.get("finished", ""), "attempts": meta.get("attempts", 1),
        "interruptions": "; ".join(f"{g.get('kind')}" + (f" {g['duration_s']:.1f} s" if "duration_s" in g else "")
                                   for g in gaps),
        "device": (meta.get("device") or {}).get("kind", ""), "deadzone": cal.get("deadzone", ""),
        "expo": cal.get("expo", ""), "gamepad_rule": cal.get("rule", ""), "assist": assist.get("kind", "none"),
        "blend": assist.get("alpha", "") if assist.get("kind") == "blend" else "",
        "model_source": model.get("source", ""), "model_digest": model.get("digest", ""),
        "condition_order": " ".join(order.get("conditions", [])), "excluded": bool(meta.get("excluded", False)),
        "exclusion_note": meta.get("exclusion_note", ""),
    }


def write_trials_csv(out: Path) -> Path:
    """``DIR/_collect/trials.csv`` from every subject's record, subjects in registration order, trials by slot."""
    docs = []
    folder = out / HIDDEN / "subjects"
    for path in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        docs.append(read_json(path, "subject file"))
    docs.sort(key=lambda d: (d.get("index", 0), d.get("subject", "")))
    buf = io.StringIO()
    writer = csv.DictWriter(buf, [c for c, _ in COLUMNS], lineterminator="\n")
    writer.writeheader()
    for doc in docs:
        for _, row in sorted((doc.get("rows") or {}).items(), key=lambda kv: int(kv[0])):
            writer.writerow({c: row.get(c, "") for c, _ in COLUMNS})
    return atomic_write_text(out / HIDDEN / "trials.csv", buf.getvalue())


def _state_words(name: str, roles: Any) -> str:
    """What a state is, by the plant's roles, with its unit (never by its name)."""
    if name in roles.position:
        what = "position, height above the pad" if name == roles.vertical else "position, across"
    elif name in roles.velocity:
        what = "velocity, " + ("vertical" if roles.position[roles.velocity.index(name)] == roles.vertical
                               else "across")
    elif name == roles.heading:
        what = "attitude"
    else:
        what = "state"
    unit = roles.unit(name)
    return f"{what} ({unit})" if unit else what


def write_data_dictionary(out: Path, protocol: Any, spec: dict[str, Any], roles: Any) -> Path:
    """``DIR/_collect/data_dictionary.md``: the partitions' columns, the trials' metadata keys, ``trials.csv``'s
    columns and the subject fields, with units (from the plant's ``roles``)."""
    lines = [f"# Data dictionary: session of protocol {protocol.name}", "",
             f"Protocol fingerprint (SHA-256): `{protocol.fingerprint}`; its text is in `_collect/session.json`.",
             "", "## Trial partitions: `subject=<ID>/<trial id>.parquet` (one row per physics step)", "",
             "| column | meaning |", "|---|---|",
             "| `demo` | the trial's ID |", f"| `t` | time since the trial's start, s (steps of {spec['dt']:g} s) |"]
    for name in spec["state_names"]:
        lines.append(f"| `{name}` | state: {_state_words(name, roles)} |")
    for name in spec["input_names"]:
        lines.append(f"| `{name}` | input the plant received, in [−1, 1] (after blending in an assisted trial) |")
    lines += ["", "## Trial metadata (each partition's `workbench` Parquet metadata; `Demonstration.meta`)", "",
              "| key | meaning |", "|---|---|", *(f"| `{k}` | {v} |" for k, v in META_KEYS),
              "", "## `_collect/trials.csv` (one line per finished trial)", "", "| column | meaning |", "|---|---|",
              *(f"| `{k}` | {v} |" for k, v in COLUMNS),
              "", "## Subject fields (asked after consent; in `subject_fields` and `_collect/subjects/<ID>.json`)", "",
              "| field | question | type |", "|---|---|---|",
              *(f"| `{f.name}` | {f.label} | {f.type}{' (' + ', '.join(f.choices) + ')' if f.choices else ''} |"
                for f in protocol.fields),
              "", "## Other records in `_collect/`", "",
              "| file | holds |", "|---|---|",
              "| `session.json` | the protocol's text, its SHA-256 and fingerprint, the seed, when the session began |",
              "| `consent.json` | every consent answer: subject, SHA-256 of the text shown, time, agreed or declined |",
              "| `subjects/<ID>.json` | a subject's fields, consent, order of conditions, calibrations, steps done |",
              "| `mcap/<ID>/<trial>.mcap` | a trial's raw stick reads, input events and display frames (Foxglove, "
              "`rerun FILE.mcap`) |",
              "| `models/<ID>/<label>.npz` | a subject's model fitted by a fit step, with `<label>.json`: its digest, "
              "the trials it was fitted on and its held-out error |", ""]
    return atomic_write_text(out / HIDDEN / "data_dictionary.md", "\n".join(lines))


def find_trial(out: Path, trial_id: str) -> Path:
    """The partition of a trial by its ID (one line naming the folder when there is none)."""
    if not isinstance(trial_id, str) or not 0 < len(trial_id) <= 120 or "/" in trial_id or trial_id.startswith("."):
        raise DataError(f"{out}: {str(trial_id)[:60]!r} is not a trial ID")
    hits = [p for p in out.glob("subject=*/*.parquet") if p.stem == trial_id]
    if len(hits) != 1:
        raise DataError(f"{out}: no trial {trial_id!r} (the IDs are in {out / HIDDEN / 'trials.csv'})")
    return hits[0]


def set_exclusion(out: str | Path, trial_id: str, excluded: bool, note: str) -> dict[str, Any]:
    """Mark a trial excluded (or included again) with the experimenter's note, in its own metadata (the partition
    rewritten atomically), the subject's record and ``trials.csv``; returns the trial's new row."""
    import pyarrow.parquet as pq

    from workbench.data.demonstrations import DemonstrationSet

    out = Path(out)
    if not isinstance(note, str) or len(note) > MAX_NOTE:
        raise DataError(f"exclusion note: expected text of at most {MAX_NOTE} characters")
    if not isinstance(excluded, bool):
        raise DataError("excluded: expected true or false")
    path = find_trial(out, trial_id)
    header = json.loads((pq.read_metadata(path).metadata or {}).get(b"workbench", b"{}"))
    ds = DemonstrationSet.load(path)
    ds = ds.with_demos([d.with_meta(excluded=excluded, exclusion_note=note.strip()) if d.id == trial_id else d
                        for d in ds])
    ds.save(path, dataset=header.get("dataset"))
    d = next(d for d in ds if d.id == trial_id)
    row = trial_row(d.meta, len(d), ds.dt)
    subject_file = out / HIDDEN / "subjects" / f"{d.meta.get('subject')}.json"
    if subject_file.is_file():
        doc = read_json(subject_file, "subject file")
        doc.setdefault("rows", {})[str(d.meta.get("slot"))] = row
        doc.setdefault("exclusions", []).append({"trial": trial_id, "excluded": excluded, "note": note.strip(),
                                                 "at": now()})
        doc["exclusions"] = doc["exclusions"][-200:]
        write_json(subject_file, doc)
    write_trials_csv(out)
    return row
