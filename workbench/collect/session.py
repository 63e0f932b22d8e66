"""The session folder: every finished trial written as it ends, in the workbench's dataset format, and the state
a closed tab or a killed server resumes from.

``DIR`` is a dataset that ``workbench fit/evaluate/report/view DIR`` read as they are (:mod:`workbench.data.dataset`):
one Parquet partition per trial, ``DIR/subject=<S>/<S>-<slot>-<label>-<role>.parquet``, each with its trial's
metadata (subject, label, trial, role, outcome, start, target, the device and its calibration, frame timing and
dropped steps). Everything else lives in the hidden folder ``DIR/_collect/`` that pandas, pyarrow and the workbench
skip: the protocol the session runs (``session.json``), each subject's metadata, calibrations and finished steps
(``subjects/<S>.json``), each trial's MCAP with the raw input events (``mcap/<S>/<id>.mcap``, JSON channels that
Foxglove and rerun open) and recorded practice (``practice/<S>/``).

Every file is written atomically (:mod:`workbench.atomic`): the MCAP first, then the Parquet file, whose existence
is what makes a trial finished. A server or browser killed mid-trial loses that trial and nothing else; what it
was writing is a hidden temp file that the next write removes. A trial is finished once its partition exists, so
resuming reads the disk, never a counter that a kill could leave behind.

The server never trusts the page's states: :meth:`Session.write_trial` replays the inputs through the plant
(:func:`workbench.collect.task.replay`) and refuses a trial whose states or outcome differ from the page's, or whose
pilot input is not the stated calibration of its raw stick readings (:func:`_device_input`).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import re
import threading
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from workbench.atomic import atomic_write_text
from workbench.collect.protocol import Item, Protocol, plan
from workbench.collect.task import OUTCOMES, blend, draw_start, replay, task_spec
from workbench.errors import DataError
from workbench.plant.system import LinearSystem, planar_quadrotor

__all__ = ["Session", "SUBJECT_PATTERN", "HIDDEN"]

HIDDEN = "_collect"
SESSION_FORMAT = "workbench.collect.session"
SUBJECT_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,39}$")
#: The page's states must equal the server's replay to this (they are computed in the same order: in practice 0).
STATE_TOLERANCE = 1e-9
MAX_EVENTS = 200_000


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _check_subject(subject: Any) -> str:
    if not isinstance(subject, str) or not SUBJECT_PATTERN.match(subject):
        raise DataError(f"subject {subject!r}: an ID is 1–40 letters, digits, '_' or '-', starting with a letter or "
                        "digit")
    return subject


def _array(payload: dict, key: str, width: int, n_max: int, where: str) -> np.ndarray:
    value = payload.get(key)
    if not isinstance(value, list) or not value:
        raise DataError(f"{where}: {key}: expected a non-empty list of samples")
    if len(value) > n_max:
        raise DataError(f"{where}: {key}: {len(value)} samples, more than the time limit allows ({n_max})")
    try:
        arr = np.array(value)
    except (TypeError, ValueError):
        raise DataError(f"{where}: {key}: not a list of number lists") from None
    if arr.dtype.kind not in "iuf":  # numpy would read "0.5" and true as numbers; the page sends numbers only
        raise DataError(f"{where}: {key}: not a list of number lists")
    arr = arr.astype(np.float64)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise DataError(f"{where}: {key}: expected samples of {width} numbers, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise DataError(f"{where}: {key}: non-finite value at sample {int(np.argwhere(~np.isfinite(arr))[0][0])}")
    return arr


class Session:
    """The session folder ``out`` of one protocol: subjects, their plans and their finished trials.

    Raises
    ------
    DataError
        ``out`` exists and is neither empty nor a session of the same protocol.
    """

    def __init__(self, out: str | os.PathLike, protocol: Protocol, *, system: LinearSystem | None = None,
                 seed: int = 0, models: dict[str, Any] | None = None) -> None:
        self.out = Path(out)
        self.protocol = protocol
        self.system = system or planar_quadrotor()
        self.spec = task_spec(self.system, protocol.time_limit_s)
        self.models = dict(models or {})
        for j, b in enumerate(protocol.blocks):
            if b.assist != "none" and b.label not in self.models:
                raise DataError(f"{protocol.source}: blocks[{j}].assist = {b.assist!r} needs a fitted model of label "
                                f"{b.label!r}: pass --model {b.label}=MODEL.npz")
        self.seed = int(seed)
        self._lock = threading.Lock()
        head = self.out / HIDDEN / "session.json"
        if self.out.exists():
            if not self.out.is_dir():
                raise DataError(f"{self.out}: not a folder; choose a new or empty folder for the session")
            if head.is_file():
                try:
                    doc = json.loads(head.read_text(encoding="utf-8"))
                    name, trials, seed_then = doc["protocol"], doc.get("trials"), doc.get("seed", 0)
                except (ValueError, KeyError, TypeError, AttributeError) as exc:
                    raise DataError(f"{head}: damaged session file ({exc})") from None
                if name != protocol.name:
                    raise DataError(f"{self.out}: a session of protocol {name!r}, not {protocol.name!r}; resume it "
                                    f"with --protocol {name} or choose another folder")
                if trials is not None and trials != [b.trials for b in protocol.blocks]:
                    raise DataError(f"{self.out}: a session with {trials} trials per block, not "
                                    f"{[b.trials for b in protocol.blocks]}; resume it with the same --max-trials")
                if seed_then != self.seed:
                    raise DataError(f"{self.out}: a session of --seed {seed_then}, not {self.seed}; resume it with "
                                    "the same seed (the start positions depend on it)")
            elif any(self.out.iterdir()):
                raise DataError(f"{self.out}: exists and is not a session folder; choose a new or empty folder")
        if not head.is_file():
            atomic_write_text(head, json.dumps({"format": SESSION_FORMAT, "version": 1, "protocol": protocol.name,
                                                "protocol_source": protocol.source, "seed": self.seed,
                                                "trials": [b.trials for b in protocol.blocks],
                                                "created": _now()}, indent=1))

    # -- subjects ----------------------------------------------------------------------------------------
    def _subject_file(self, subject: str) -> Path:
        return self.out / HIDDEN / "subjects" / f"{subject}.json"

    def subject_doc(self, subject: str) -> dict[str, Any] | None:
        """What the session knows of a subject (metadata, index, calibrations, finished steps), or ``None``."""
        path = self._subject_file(_check_subject(subject))
        if not path.is_file():
            return None
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except ValueError as exc:
            raise DataError(f"{path}: damaged subject file ({exc})") from None

    def subjects(self) -> list[str]:
        folder = self.out / HIDDEN / "subjects"
        return sorted(p.stem for p in folder.glob("*.json")) if folder.is_dir() else []

    def register(self, subject: str, fields: dict[str, Any]) -> dict[str, Any]:
        """Register a new subject with its metadata (checked against the protocol's fields), or return the
        existing one's status unchanged: a subject who comes back resumes."""
        subject = _check_subject(subject)
        with self._lock:
            if self.subject_doc(subject) is not None:
                return self.status(subject)
            meta = self._check_fields(fields)
            doc = {"subject": subject, "index": len(self.subjects()), "fields": meta, "registered": _now(),
                   "calibrations": [], "done": []}
            atomic_write_text(self._subject_file(subject), json.dumps(doc, indent=1))
        return self.status(subject)

    def _check_fields(self, fields: Any) -> dict[str, Any]:
        if not isinstance(fields, dict):
            raise DataError("subject fields: expected a table of name: value")
        known = {f.name: f for f in self.protocol.fields}
        if extra := sorted(set(fields) - set(known)):
            raise DataError(f"subject fields: {extra[0]!r} is not a field of this protocol")
        out: dict[str, Any] = {}
        for name, f in known.items():
            value = fields.get(name)
            if value in (None, ""):
                if f.required:
                    raise DataError(f"subject fields: {f.label} is required")
                continue
            if f.type == "number":
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    raise DataError(f"subject fields: {f.label}: {value!r} is not a number") from None
                if not math.isfinite(value):
                    raise DataError(f"subject fields: {f.label}: {value!r} is not a finite number")
            elif f.type == "choice" and value not in f.choices:
                raise DataError(f"subject fields: {f.label}: {value!r} is not one of {', '.join(f.choices)}")
            else:
                value = str(value)[:500]
            out[name] = value
        return out

    def _update(self, subject: str, change: Any) -> dict[str, Any]:
        with self._lock:
            doc = self.subject_doc(subject)
            if doc is None:
                raise DataError(f"subject {subject!r}: not registered in this session")
            change(doc)
            atomic_write_text(self._subject_file(subject), json.dumps(doc, indent=1))
            return doc

    def calibrate(self, subject: str, calibration: Any) -> None:
        """Record a device calibration (rest offsets, dead zone, axis assignment): every one is kept, in order."""
        if not isinstance(calibration, dict) or len(json.dumps(calibration)) > 20_000:
            raise DataError("calibration: expected a small table (device, offsets, dead zone, axes)")
        self._update(subject, lambda d: d["calibrations"].append({**calibration, "at": _now()}))

    def advance(self, subject: str, key: str) -> dict[str, Any]:
        """Mark a practice, break or instructions step finished (trials finish by being written)."""
        items = {i.key: i for i in self.plan(subject)}
        if key not in items or items[key].kind in ("trial", "end"):
            raise DataError(f"step {key!r}: not a practice, break or instructions step of this session")
        self._update(subject, lambda d: d["done"].append(key) if key not in d["done"] else None)
        return self.status(subject)

    # -- the plan ----------------------------------------------------------------------------------------
    def plan(self, subject: str) -> list[Item]:
        doc = self.subject_doc(subject)
        if doc is None:
            raise DataError(f"subject {subject!r}: not registered in this session")
        return plan(self.protocol, subject, int(doc["index"]))

    def trial_id(self, subject: str, item: Item) -> str:
        return f"{subject}-{item.slot:03d}-{item.label}-{item.role}"

    def _partition(self, subject: str, trial_id: str) -> Path:
        return self.out / f"subject={quote(subject, safe='')}" / f"{trial_id}.parquet"

    def finished(self, subject: str) -> set[int]:
        """The slots whose trial is on disk: the only record of a finished trial."""
        return {i.slot for i in self.plan(subject)
                if i.kind == "trial" and self._partition(subject, self.trial_id(subject, i)).is_file()}

    def status(self, subject: str) -> dict[str, Any]:
        """Where a subject is: the next step (with its start state for a trial), trials done and to do."""
        doc = self.subject_doc(subject)
        items = self.plan(subject)
        done_slots = self.finished(subject)
        done = set(doc["done"])
        trials = [i for i in items if i.kind == "trial"]
        finished = [j for j, i in enumerate(items) if (i.slot in done_slots if i.kind == "trial" else i.key in done)]
        # steps are taken in order: the next one follows the last finished one (instructions shown before a
        # block's trials are not asked for again when the tab closed after its first trial)
        nxt = items[finished[-1] + 1 if finished else 0]
        step = nxt.to_json()
        if nxt.kind == "trial":
            step["x0"] = self.start(subject, nxt.slot)
            step["id"] = self.trial_id(subject, nxt)
            if nxt.assist != "none":
                step["help"] = self.assistance(nxt, step["x0"])
        return {"subject": subject, "fields": doc["fields"], "calibrated": bool(doc["calibrations"]),
                "trials_done": len(done_slots), "trials_total": len(trials), "next": step,
                "summary": self.summary(subject) if nxt.kind == "end" else None}

    def summary(self, subject: str) -> list[dict[str, Any]]:
        """Per block label and role: trials finished and landed, from the trials' own files."""
        import pyarrow.parquet as pq

        rows: dict[tuple[str, str], dict[str, Any]] = {}
        for i in self.plan(subject):
            path = self._partition(subject, self.trial_id(subject, i)) if i.kind == "trial" else None
            if path is None or not path.is_file():
                continue
            header = json.loads((pq.read_metadata(path).metadata or {}).get(b"workbench", b"{}"))
            outcome = (header.get("demos") or [{}])[0].get("outcome")
            r = rows.setdefault((i.label, i.role), {"label": i.label, "role": i.role, "trials": 0, "landed": 0})
            r["trials"] += 1
            r["landed"] += outcome == "landed"
        return list(rows.values())

    def assistance(self, item: Item, x0: list[float]) -> dict[str, Any]:
        """What the page needs to assist a trial: the model's gain ``K`` (for ``blend``) and its mean predicted
        path from the start, as (across, height) points (for ``show``)."""
        model = self.models[item.label]
        i = self.spec["index"]
        pred = model.predict(np.asarray(x0), self.spec["max_steps"], np.asarray(self.spec["target"]), clip=True)
        path = pred.x[:, [i["x"], i["y"]]]
        ground = np.flatnonzero(path[:, 1] <= 0.0)
        path = path[: ground[0] + 1] if len(ground) else path  # drawn down to the ground, not beyond it
        return {"kind": item.assist, "alpha": item.blend, "K": np.asarray(model.K_, dtype=np.float64).tolist(),
                "path": path.tolist(), "law": "u = (1 - alpha) u_pilot + alpha clip(K (x - target))"}

    def start(self, subject: str, slot: int) -> list[float]:
        """The start state of a trial slot: drawn from the seed, the subject and the slot, so a resumed trial
        starts where it would have."""
        import zlib

        return draw_start(self.spec, [self.seed, zlib.crc32(subject.encode()), slot])

    # -- trials ------------------------------------------------------------------------------------------
    def write_trial(self, payload: Any) -> dict[str, Any]:
        """Check a finished trial from the page, replay it through the plant and write it (MCAP, then Parquet).

        Raises
        ------
        DataError
            One line: an unknown subject or slot, a slot already finished, malformed arrays, states or an
            outcome that the plant's replay does not reproduce.
        """
        if not isinstance(payload, dict):
            raise DataError("trial: expected a JSON object")
        subject = _check_subject(payload.get("subject"))
        slot = payload.get("slot")
        items = {i.slot: i for i in self.plan(subject) if i.kind == "trial"}
        if not isinstance(slot, int) or slot not in items:
            raise DataError(f"trial: slot {slot!r} is not a trial of subject {subject!r}'s plan")
        item = items[slot]
        trial_id = self.trial_id(subject, item)
        expected = min((j for j in items if j not in self.finished(subject)), default=None)
        if slot != expected and not self._partition(subject, trial_id).is_file():
            raise DataError(f"trial {trial_id}: out of order (the next trial of {subject!r} is slot {expected}); "
                            "reload the page to resume")
        where = f"trial {trial_id}"
        x0 = self.start(subject, slot)
        help_ = self.assistance(item, x0) if item.assist != "none" else None
        demo, streams = self._checked(payload, x0, where, help_)
        doc = self.subject_doc(subject)
        demo_meta = {
            "id": trial_id, "subject": subject, "label": item.label, "role": item.role, "trial": item.trial,
            "slot": slot, "block": item.block, "start": x0, "target": self.spec["target"],
            "outcome": demo["outcome"], "success": demo["outcome"] == "landed", "source": "workbench collect",
            "protocol": self.protocol.name, "subject_fields": doc["fields"],
            "device": demo["device"], "calibration": demo["calibration"], "timing": demo["timing"],
            "finished": _now(),
        }
        reference = self.protocol.blocks[item.block].reference
        if reference is not None:  # the path the block's instruction asks for: a fit regulates the deviation from it
            demo_meta["reference"] = reference
        if help_ is not None:
            demo_meta["assist"] = {k: help_[k] for k in ("kind", "alpha", "K", "law")}
            demo_meta["pilot_u"] = demo["pilot"].tolist()  # the pilot's own input; ``u`` is what the plant got
        with self._lock:
            if self._partition(subject, trial_id).is_file():
                raise DataError(f"{where}: already recorded; the page is behind (reload it to resume)")
            mcap = self.out / HIDDEN / "mcap" / subject / f"{trial_id}.mcap"
            _write_mcap(mcap, streams, demo_meta)
            _write_partition(self, subject, trial_id, demo["x"], demo["u"], demo_meta,
                             order=int(doc["index"]) * 100_000 + slot)
        return {"id": trial_id, "outcome": demo["outcome"], "samples": len(demo["u"]), "label": item.label,
                "role": item.role, "trial": item.trial, **self.status(subject)}

    def write_practice(self, payload: Any) -> dict[str, Any]:
        """A practice trial: checked like a trial; kept in ``_collect/practice/`` only if the protocol records
        practice, never in the dataset."""
        if not isinstance(payload, dict):
            raise DataError("practice: expected a JSON object")
        subject = _check_subject(payload.get("subject"))
        if self.subject_doc(subject) is None:
            raise DataError(f"subject {subject!r}: not registered in this session")
        x0 = payload.get("x0")
        if not (isinstance(x0, list) and len(x0) == len(self.spec["state_names"]) and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in x0)):
            raise DataError("practice: x0: expected the start state (a list of finite numbers)")
        demo, _ = self._checked(payload, [float(v) for v in x0], "practice trial")
        if not self.protocol.practice_recorded:
            return {"recorded": False, "outcome": demo["outcome"]}
        from workbench.data.demonstrations import Demonstration, DemonstrationSet

        folder = self.out / HIDDEN / "practice" / subject
        with self._lock:
            n = len(list(folder.glob("*.parquet"))) if folder.is_dir() else 0
            pid = f"{subject}-practice-{n:03d}"
            d = Demonstration(self.spec["dt"] * np.arange(len(demo["u"])), demo["x"], demo["u"],
                              {"id": pid, "subject": subject, "label": "practice", "role": "practice",
                               "outcome": demo["outcome"], "device": demo["device"], "timing": demo["timing"]})
            DemonstrationSet([d], self.spec["state_names"], self.spec["input_names"], self.spec["dt"]).save(
                folder / f"{pid}.parquet")
        return {"recorded": True, "outcome": demo["outcome"]}

    def _checked(self, payload: dict, x0: list[float], where: str,
                 help_: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        n, m = len(self.spec["state_names"]), len(self.spec["input_names"])
        n_max = self.spec["max_steps"] + 1
        u = _array(payload, "u", m, n_max, where)
        x = _array(payload, "x", n, n_max, where)
        raw = _array(payload, "raw", m, n_max, where)
        pilot = _array(payload, "pilot", m, n_max, where) if "pilot" in payload else u
        if not (len(u) == len(x) == len(raw) == len(pilot)):
            raise DataError(f"{where}: u, x, raw and pilot have {len(u)}, {len(x)}, {len(raw)} and {len(pilot)} "
                            "samples; one per step")
        if help_ is not None and help_["kind"] == "blend":
            law = np.array([blend(self.spec, help_["K"], help_["alpha"], xk, pk)
                            for xk, pk in zip(x.tolist(), pilot.tolist(), strict=True)])
            if np.max(np.abs(law - u)) > STATE_TOLERANCE:
                k = int(np.argmax(np.max(np.abs(law - u), axis=1) > STATE_TOLERANCE))
                raise DataError(f"{where}: the input at sample {k} is not the stated blend of the pilot's input and "
                                "the model's; nothing written")
        elif not np.array_equal(pilot, u):
            raise DataError(f"{where}: pilot input differs from the input in a trial without blending")
        stated = _device_input(raw, payload.get("calibration"), where)
        if stated is not None and not np.array_equal(stated, pilot):
            k = int(np.argmax(np.any(stated != pilot, axis=1)))
            raise DataError(f"{where}: the pilot's input at sample {k} is not the stated calibration of the raw stick "
                            f"reading ({raw[k].tolist()} gives {stated[k].tolist()}, the page says "
                            f"{pilot[k].tolist()}); nothing written")
        lo, hi = np.array(self.spec["u_min"]), np.array(self.spec["u_max"])
        if ((u < lo) | (u > hi)).any():
            raise DataError(f"{where}: u: an input outside the sticks' range [{lo.tolist()}, {hi.tolist()}]")
        if len(u) < 2:
            raise DataError(f"{where}: fewer than 2 samples; not a trial")
        xs, end, k = replay(self.spec, x0, u)
        if len(xs) != len(x) or np.max(np.abs(xs - x)) > STATE_TOLERANCE:
            bad = next((j for j in range(min(len(xs), len(x))) if np.max(np.abs(xs[j] - x[j])) > STATE_TOLERANCE),
                       min(len(xs), len(x)))
            raise DataError(f"{where}: the page's states differ from the plant's replay of its inputs from sample "
                            f"{bad} on (page {len(x)} samples, replay {len(xs)}); nothing written")
        claimed = payload.get("outcome")
        if claimed not in OUTCOMES or claimed != end:
            raise DataError(f"{where}: the page says {claimed!r}, the plant's replay says {end!r}; nothing written")
        t = self.spec["dt"] * np.arange(len(u))
        # when each step's sticks were read (s from the trial's start, on the page's clock): late steps show as
        # several read at one display frame, a stall as a gap
        sampled = payload.get("sampled")
        if sampled is not None and not (isinstance(sampled, list) and len(sampled) == len(u) and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in sampled)):
            raise DataError(f"{where}: sampled: expected one reading time (s) per sample")
        info = {}
        for key, limit in (("device", 4000), ("calibration", 20_000), ("timing", 20_000)):
            value = payload.get(key, {})
            if not isinstance(value, dict) or len(json.dumps(value)) > limit:
                raise DataError(f"{where}: {key}: expected a small table")
            info[key] = value
        streams: dict[str, Any] = {
            "/trial/state": {"t": t, **{s: xs[:, i] for i, s in enumerate(self.spec["state_names"])}},
            "/trial/input": {"t": t, **{s: u[:, i] for i, s in enumerate(self.spec["input_names"])},
                             **{f"raw_{s}": raw[:, i] for i, s in enumerate(self.spec["input_names"])},
                             **{f"pilot_{s}": pilot[:, i] for i, s in enumerate(self.spec["input_names"])},
                             **({} if sampled is None else {"sampled_s": np.array(sampled, dtype=np.float64)})},
        }
        streams.update(_events(payload, where))
        return {"x": xs, "u": u, "pilot": pilot, "outcome": end, **info}, streams


def _device_input(raw: np.ndarray, cal: Any, where: str) -> np.ndarray | None:
    """The pilot's input the page's device code (``static/input.js``) gives for the raw readings under a stated
    calibration, in the page's arithmetic (bit-equal): a gamepad's offsets, signs and dead zone, or the keyboard's
    ramp. ``None`` for another kind of device (a scripted one), which states no rule to check."""
    kind = cal.get("kind") if isinstance(cal, dict) else None
    if kind == "keyboard":
        n = cal.get("ramp_steps")
        if not isinstance(n, int) or isinstance(n, bool) or n < 1:
            raise DataError(f"{where}: calibration: a keyboard needs ramp_steps, a whole number of steps")
        level, out = [0, 0], []
        for r in raw.tolist():
            level = [lv + int(np.sign(ri * n - lv)) for lv, ri in zip(level, r, strict=True)]
            out.append([lv / n for lv in level])
        return np.array(out)
    if kind != "gamepad":
        return None
    try:
        axes, signs, offsets, dz = cal["axes"], cal["signs"], cal["offsets"], float(cal["deadzone"])
        if not all(isinstance(a, int) and 0 <= a < len(offsets) for a in axes):
            raise ValueError
        offs = [float(offsets[a]) for a in axes]
        signs = [float(v) for v in signs]
        if len(offs) != raw.shape[1] or len(signs) != raw.shape[1] or not 0 <= dz < 1:
            raise ValueError
    except (KeyError, IndexError, TypeError, ValueError):
        raise DataError(f"{where}: calibration: a gamepad needs axes, signs, offsets and a dead zone in "
                        "[0, 1)") from None
    out = np.zeros_like(raw)
    for k, row in enumerate(raw.tolist()):
        for i, r in enumerate(row):
            d = r - offs[i]
            travel = 1 - offs[i] if d >= 0 else 1 + offs[i]
            v = signs[i] * (d / travel if travel > 0 else 0.0)
            a = abs(v)
            out[k, i] = 0.0 if a <= dz else min(1.0, max(-1.0, math.copysign(1.0, v) * (a - dz) / (1 - dz)))
    return out


def _events(payload: dict, where: str) -> dict[str, Any]:
    """The raw input events (``[t_s, kind, code, value]``: key downs and ups, stick readings) and the display
    frames' times as MCAP streams; times are seconds from the trial's start."""
    out: dict[str, Any] = {}
    events = payload.get("events", [])
    if not isinstance(events, list) or len(events) > MAX_EVENTS:
        raise DataError(f"{where}: events: expected a list of at most {MAX_EVENTS} events")
    rows = []
    for j, e in enumerate(events):
        if not (isinstance(e, list) and len(e) == 4 and isinstance(e[0], int | float) and isinstance(e[1], str)
                and isinstance(e[2], str | int) and isinstance(e[3], int | float | None)):
            raise DataError(f"{where}: events[{j}]: expected [t_s, kind, code, value]")
        rows.append((max(0.0, float(e[0])), e[1][:32], str(e[2])[:64], float("nan") if e[3] is None else float(e[3])))
    if rows:
        t, kind, code, value = zip(*rows, strict=True)
        out["/input/events"] = {"t": np.array(t), "kind": np.array(kind, dtype=object),
                                "code": np.array(code, dtype=object), "value": np.array(value)}
    frames = payload.get("frames", [])
    if not isinstance(frames, list) or len(frames) > MAX_EVENTS or not all(isinstance(f, int | float) for f in frames):
        raise DataError(f"{where}: frames: expected a list of display frame times (s)")
    if frames:
        ft = np.maximum(np.array(frames, dtype=np.float64), 0.0)
        out["/display/frames"] = {"t": ft, "interval_s": np.diff(ft, prepend=ft[0])}
    return out


def _write_mcap(path: Path, streams: dict[str, Any], meta: dict[str, Any]) -> None:
    from adapters.formats import mcap

    flat = {k: (v if isinstance(v, str) else json.dumps(v)) for k, v in meta.items()}
    mcap.write(path, streams, metadata={"trial": flat}, profile="")


def _write_partition(session: Session, subject: str, trial_id: str, x: np.ndarray, u: np.ndarray,
                     meta: dict[str, Any], order: int) -> None:
    from workbench.data.dataset import write_partitions
    from workbench.data.demonstrations import Demonstration, DemonstrationSet

    spec = session.spec
    d = Demonstration(spec["dt"] * np.arange(len(u)), x, u, meta)
    roles = session.system.roles
    write_partitions(DemonstrationSet([d], spec["state_names"], spec["input_names"], spec["dt"], roles=roles),
                     session.out, trial_id, source="workbench collect", order=order)
