"""The session folder: every finished trial written as it ends, in the workbench's dataset format, and the state
a closed tab or a killed server resumes from.

``DIR`` is a dataset that ``workbench fit/evaluate/report/view DIR`` read as they are (:mod:`workbench.data.dataset`):
one Parquet partition per trial, ``DIR/subject=<S>/<S>-<slot>-<label>-<role>.parquet``, each with its trial's
metadata (``records.META_KEYS``: subject, label, trial, role, outcome and its reason, start, target, the device,
its calibration and the protocol's input settings, start time, interruptions, assistance and its model's digest,
exclusion). Everything else lives in the hidden folder ``DIR/_collect/`` that pandas, pyarrow and the workbench
skip: the protocol the session runs — its text, SHA-256 and fingerprint (``session.json``) —, consent answers
(``consent.json``), each subject's record (``subjects/<S>.json``), each trial's MCAP with the raw input events and
stick reads (``mcap/<S>/<id>.mcap``), fitted models (``models/<S>/``), recorded practice (``practice/<S>/``),
``trials.csv`` and ``data_dictionary.md`` (:mod:`.records`).

A session is pinned to its protocol: resuming the folder under a protocol whose fingerprint differs (another file,
an edited time limit or consent, other ``--max-trials``) is refused with one line naming the first difference,
unless a new session is asked for (``new_session``: the old one is moved whole into
``_collect/previous/<when it began>/``, nothing deleted).

Every file is written atomically (:mod:`workbench.atomic`): the MCAP first, then the Parquet file, whose existence
is what makes a trial finished. A server or browser killed mid-trial loses that trial and nothing else. The server
never trusts the page (:mod:`.checks`).
"""

from __future__ import annotations

import json
import math
import threading
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from workbench.collect import records
from workbench.collect.checks import checked_trial, measured_deadzone
from workbench.collect.fitting import FitJobs, Jobs, load_fitted
from workbench.collect.plan import Item, plan
from workbench.collect.protocol import Protocol, condition_order, first_difference
from workbench.collect.stopping import StopChecks
from workbench.collect.subjects import LIMITS, check_fields, check_subject, now, read_json, write_json
from workbench.collect.task import draw_start, task_spec
from workbench.errors import DataError, RequestError
from workbench.plant.system import LinearSystem, planar_quadrotor

__all__ = ["Session", "HIDDEN"]

HIDDEN = "_collect"
SESSION_FORMAT = "workbench.collect.session"
SESSION_VERSION = 2


class Session:
    """The session folder ``out`` of one protocol: subjects, their plans and their finished trials.

    Parameters
    ----------
    models : mapping label → fitted model, optional
        Models given when the server starts (``--model``), for assisted blocks without a fit step of their label;
        ``model_digests`` their files' SHA-256.
    new_session : bool
        Start a new session in a folder that holds one of another protocol (the old one is kept aside).
    on_event : callable(kind, text), optional
        Told of what the experimenter should see at once: ``warning`` (an unknown or repeated subject ID),
        ``fit`` (a fit step's result), ``consent`` (a subject declined), ``exclusion`` (the experimenter excluded
        a trial, or included it again), ``stop`` (a stopping rule's check).
    runner : callable(fn, task), optional
        How fit steps and stopping checks run (:class:`~workbench.collect.fitting.Jobs`; default: in a worker
        process; :func:`~workbench.collect.fitting.in_process` runs them here).

    Raises
    ------
    DataError
        ``out`` exists and is neither empty nor a session of the same protocol.
    """

    def __init__(self, out: str | Path, protocol: Protocol, *, plant: LinearSystem | None = None, seed: int = 0,
                 models: dict[str, Any] | None = None, model_digests: dict[str, str] | None = None,
                 new_session: bool = False, on_event: Callable[[str, str], None] | None = None,
                 runner: Callable[[Callable, tuple], dict[str, Any]] | None = None) -> None:
        self.out = Path(out)
        self.protocol = protocol
        self.plant = plant or planar_quadrotor()
        self.spec = task_spec(self.plant, protocol.time_limit_s)
        self.models = dict(models or {})
        self.model_digests = dict(model_digests or {})
        self.seed = int(seed)
        self.on_event = on_event
        self.on_fit: Callable[[dict[str, Any]], None] | None = None  # told of every fit's record (the view)
        fitted = {f.label for f in protocol.fits}
        for j, b in enumerate(protocol.steps):
            if getattr(b, "assist", "none") != "none" and b.label not in self.models and b.label not in fitted:
                raise DataError(f"{protocol.source}: blocks[{j}].assist = {b.assist!r} needs a model of label "
                                f"{b.label!r}: a fit step of {b.label} before it, or --model {b.label}=MODEL.npz")
        self._lock = threading.Lock()
        self._fitted_cache: dict = {}
        self._open(new_session)
        self.jobs = Jobs(on_done=self._job_done, runner=runner)
        self.fits = FitJobs(self.out, self.seed, self.jobs)
        self.stops = StopChecks(self.out, self.seed, self.jobs)
        records.write_data_dictionary(self.out, protocol, self.spec, self.plant.roles)

    # -- the folder --------------------------------------------------------------------------------------
    @property
    def head(self) -> Path:
        return self.out / HIDDEN / "session.json"

    def _open(self, new_session: bool) -> None:
        p = self.protocol
        if self.out.exists():
            if not self.out.is_dir():
                raise DataError(f"{self.out}: not a folder; choose a new or empty folder for the session")
            if self.head.is_file():
                refusal = self._refusal(read_json(self.head, "session file"))
                if refusal and not new_session:
                    raise DataError(f"{self.out}: {refusal}; resume it with the same protocol and options, or start "
                                    "a new session here with --new-session (the old one is kept in "
                                    f"{self.out / HIDDEN / 'previous'}/)")
                if refusal:
                    self._set_aside()
            elif any(self.out.iterdir()):
                raise DataError(f"{self.out}: exists and is not a session folder; choose a new or empty folder")
        if not self.head.is_file():
            write_json(self.head, {
                "format": SESSION_FORMAT, "version": SESSION_VERSION, "protocol": p.name, "protocol_source": p.source,
                "protocol_sha256": _sha256(p.text), "protocol_fingerprint": p.fingerprint,
                "protocol_content": json.loads(json.dumps(p.content())), "protocol_text": p.text, "seed": self.seed,
                "created": now()})

    def _refusal(self, doc: Any) -> str:
        """Why this protocol may not resume the session ``doc`` describes ("" if it may)."""
        try:
            name, seed_then = doc["protocol"], doc.get("seed", 0)
        except (KeyError, TypeError):
            raise DataError(f"{self.head}: damaged session file (no protocol)") from None
        if doc.get("version", 1) < 2:  # a session before protocols were pinned: its name and trial counts
            trials = doc.get("trials")
            if name != self.protocol.name or trials not in (None, [b.trials for b in self.protocol.blocks]):
                return f"a session of protocol {name!r} with {trials} trials per block"
        elif doc.get("protocol_fingerprint") != self.protocol.fingerprint:
            change = first_difference(doc.get("protocol_content") or {},
                                      json.loads(json.dumps(self.protocol.content())))
            then = str(doc.get("protocol_fingerprint"))[:12]
            return (f"a session of another protocol: {name!r} (fingerprint {then}), not this {self.protocol.name!r} "
                    f"({self.protocol.fingerprint[:12]}; first difference {change})")
        if seed_then != self.seed:
            return f"a session of --seed {seed_then}, not {self.seed} (the start positions depend on it)"
        return ""

    def _set_aside(self) -> None:
        created = read_json(self.head, "session file").get("created", now())
        stamp = "".join(c if c.isalnum() else "-" for c in str(created))[:40]
        dest = self.out / HIDDEN / "previous" / stamp
        (dest / HIDDEN).mkdir(parents=True, exist_ok=False)
        for entry in self.out.iterdir():
            if entry.name != HIDDEN:
                entry.rename(dest / entry.name)
        for entry in (self.out / HIDDEN).iterdir():
            if entry.name != "previous":
                entry.rename(dest / HIDDEN / entry.name)
        self._event("warning", f"the session of another protocol in {self.out} was moved to {dest}")

    def _event(self, kind: str, text: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, text)

    # -- subjects ----------------------------------------------------------------------------------------
    def _subject_file(self, subject: str) -> Path:
        return self.out / HIDDEN / "subjects" / f"{subject}.json"

    def subject_doc(self, subject: str) -> dict[str, Any] | None:
        """What the session knows of a subject (metadata, consent, order, calibrations, steps, trials), or None."""
        path = self._subject_file(check_subject(subject))
        return read_json(path, "subject file") if path.is_file() else None

    def subjects(self) -> list[str]:
        folder = self.out / HIDDEN / "subjects"
        return sorted(p.stem for p in folder.glob("*.json")) if folder.is_dir() else []

    def _consent_record(self, entry: dict[str, Any]) -> None:
        path = self.out / HIDDEN / "consent.json"
        entries = read_json(path, "consent record") if path.is_file() else []
        if len(entries) >= LIMITS["consent_records"]:
            raise RequestError(f"{path}: {len(entries)} consent answers already; no more are recorded", 507)
        write_json(path, [*entries, entry])

    def _check_consent(self, consent: Any) -> str:
        sha = consent.get("sha256") if isinstance(consent, dict) else None
        if sha != self.protocol.consent_sha256:
            raise RequestError("consent: not the consent text of this session (it may have changed: reload the page)")
        return sha

    def decline(self, subject: Any, consent: Any) -> dict[str, Any]:
        """A subject declined the consent text: recorded (who, when, which text), and nothing else is."""
        sha = self._check_consent(consent)
        who = None if subject in (None, "") else check_subject(subject)
        with self._lock:
            self._consent_record({"subject": who, "consent_sha256": sha, "agreed": False, "at": now()})
        self._event("consent", f"{who or 'a subject without an ID'} declined the consent")
        return {"recorded": True, "agreed": False}

    def register(self, subject: str, fields: Any, consent: Any = None, confirm: bool = False) -> dict[str, Any]:
        """Register a subject who agreed to the consent text (its SHA-256 recorded with the time), with their
        metadata. A known ID, or one that is not among the declared subjects, is asked to be confirmed first
        (a 409 the page shows) and then recorded as a warning."""
        subject = check_subject(subject)
        sha = self._check_consent(consent)
        with self._lock:
            doc = self.subject_doc(subject)
            if doc is not None:
                done = len(self.finished(subject))
                if not confirm:
                    raise RequestError(f"subject {subject} is already registered ({done} trials done); continue "
                                       "only if you are that subject", 409, confirm="repeated")
                self._warn(subject, doc, f"ID {subject} entered again in a new page and confirmed ({done} trials "
                                         "done): resumed")
                write_json(self._subject_file(subject), doc)
                return self.status(subject)
            declared = self.protocol.subjects
            warnings = []
            if declared and subject not in declared:
                if not confirm:
                    raise RequestError(f"{subject} is not one of this session's declared subject IDs; check it with "
                                       "the experimenter", 409, confirm="unknown")
                warnings.append(f"ID {subject} is not one of the declared subjects (confirmed on the page)")
            if len(self.subjects()) >= LIMITS["subjects"]:
                raise RequestError(f"{LIMITS['subjects']} subjects already registered in this session", 507)
            meta = check_fields(self.protocol, fields)
            index = len(self.subjects())
            conditions, why = condition_order(self.protocol, subject, index)
            at = now()
            self._consent_record({"subject": subject, "consent_sha256": sha, "agreed": True, "at": at})
            doc = {"subject": subject, "index": index, "fields": meta, "registered": at,
                   "consent": {"sha256": sha, "agreed": True, "at": at},
                   "order": {"conditions": conditions, "why": why}, "calibrations": [], "done": [], "starts": {},
                   "rows": {}, "warnings": []}
            for w in warnings:
                self._warn(subject, doc, w)
            write_json(self._subject_file(subject), doc)
        return self.status(subject)

    def _warn(self, subject: str, doc: dict[str, Any], text: str) -> None:
        doc.setdefault("warnings", []).append({"at": now(), "text": text})
        doc["warnings"] = doc["warnings"][-50:]
        self._event("warning", f"{subject}: {text}")

    def _update(self, subject: str, change: Callable[[dict[str, Any]], Any]) -> dict[str, Any]:
        with self._lock:
            doc = self.subject_doc(subject)
            if doc is None:
                raise DataError(f"subject {subject!r}: not registered in this session")
            change(doc)
            write_json(self._subject_file(subject), doc)
            return doc

    def calibrate(self, subject: str, calibration: Any) -> dict[str, Any]:
        """Record a device calibration; it must be complete (rest measured and both axes confirmed on a gamepad,
        every key tried on the keyboard) and follow the protocol's input settings. The newest are kept."""
        cal = self._checked_calibration(calibration)
        self._update(subject, lambda d: d.__setitem__(
            "calibrations", [*d["calibrations"], {**cal, "at": now()}][-LIMITS["calibrations"]:]))
        return self.status(subject)

    def _checked_calibration(self, cal: Any) -> dict[str, Any]:
        settings = self.protocol.input
        if not isinstance(cal, dict) or len(json.dumps(cal)) > 20_000:
            raise DataError("calibration: expected a small table (device, offsets, dead zone, axes)")
        kind = cal.get("kind")
        if kind == "keyboard":
            if settings.device == "gamepad":
                raise DataError("calibration: this protocol needs a gamepad; the keyboard is not allowed")
            if cal.get("confirmed") is not True:
                raise DataError("calibration: every key must be tried before the trials (a tap each)")
            return cal
        if kind != "gamepad":
            raise DataError("calibration: kind must be gamepad or keyboard")
        confirmed, axes = cal.get("confirmed"), cal.get("axes")
        if not (isinstance(confirmed, list) and confirmed == [True, True]):
            raise DataError("calibration: each stick's assignment must be confirmed")
        if not (isinstance(axes, list) and len(axes) == 2 and axes[0] != axes[1]):
            raise DataError("calibration: two different axes must be assigned")
        noise = cal.get("rest_noise")
        if measured_deadzone(noise) is None:
            raise DataError("calibration: the sticks' rest must be measured")
        want = measured_deadzone(noise) if isinstance(settings.deadzone, str) else settings.deadzone
        if cal.get("deadzone") != want or cal.get("expo") != settings.expo or cal.get("rule") != settings.gamepad_rule:
            raise DataError(f"calibration: dead zone, expo and rule must be the protocol's ({want!r}, "
                            f"{settings.expo!r}, {settings.gamepad_rule!r})")
        return cal

    def start_trial(self, subject: str, slot: Any) -> dict[str, Any]:
        """The subject started a trial (Space): its start time, and every earlier start of the same slot that never
        finished (an interruption), are recorded."""
        items = {i.slot: i for i in self.plan(subject) if i.kind == "trial"}
        if not isinstance(slot, int) or isinstance(slot, bool) or slot not in items:
            raise DataError(f"start: slot {str(slot)[:20]} is not a trial of subject {subject!r}'s plan")

        def record(doc: dict[str, Any]) -> None:
            starts = doc.setdefault("starts", {}).setdefault(str(slot), [])
            starts.append(now())
            del starts[: -LIMITS["starts"]]

        self._update(subject, record)
        return {"started": True}

    def advance(self, subject: str, key: str) -> dict[str, Any]:
        """Mark a practice, break, message, instructions or (once its model is ready) fit step finished."""
        items = {i.key: i for i in self.plan(subject)}
        if key not in items or items[key].kind in ("trial", "end"):
            raise DataError(f"step {str(key)[:40]!r}: not a practice, break, message, instructions or fit step")
        item = items[key]
        if item.kind == "fit" and (state := self.fits.state(subject, item.label))["state"] != "ready":
            raise RequestError(f"step {key}: the model of {item.label} is {state['state']}"
                               + (f" ({state['reason']})" if "reason" in state else ""), 409)
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

    def _row(self, subject: str, doc: dict[str, Any], item: Item) -> dict[str, Any]:
        row = (doc.get("rows") or {}).get(str(item.slot))
        if row is not None:
            return row
        import pyarrow.parquet as pq  # a kill between the partition and the subject's record: the file says

        header = json.loads((pq.read_metadata(self._partition(subject, self.trial_id(subject, item))).metadata
                             or {}).get(b"workbench", b"{}"))
        meta = (header.get("demos") or [{}])[0]
        return {"outcome": meta.get("outcome"), "excluded": bool(meta.get("excluded", False))}

    def _progress(self, subject: str) -> tuple[list[Item], list[int], set[int], set[int], dict[str, list[str]]]:
        """The plan, the indices of its finished steps, the finished and the skipped trial slots, and per block
        (by its instructions' key) the IDs of its landed, not excluded trials."""
        doc = self.subject_doc(subject)
        items = plan(self.protocol, subject, int(doc["index"]))
        done_slots = {i.slot for i in items if i.kind == "trial"
                      and self._partition(subject, self.trial_id(subject, i)).is_file()}
        landed: dict[str, int] = {}
        usable: dict[str, list[str]] = {}
        identified: dict[str, bool] = {}
        skipped: set[int] = set()
        finished = []
        for j, i in enumerate(items):
            if i.kind == "trial":
                if i.slot in done_slots:
                    row = self._row(subject, doc, i)
                    landed[i.group] = landed.get(i.group, 0) + (row.get("outcome") == "landed")
                    if row.get("outcome") == "landed" and not row.get("excluded"):
                        usable.setdefault(i.group, []).append(self.trial_id(subject, i))
                    finished.append(j)
                    continue
                if i.stop_identified and i.group not in identified:
                    identified[i.group] = self.stops.identified(subject, i.group) is not None
                if (i.stop_landed and landed.get(i.group, 0) >= i.stop_landed) or identified.get(i.group):
                    skipped.add(i.slot)  # the block's stopping rule is met: its other trials are not flown
                    finished.append(j)
            elif i.key in doc["done"]:
                finished.append(j)
        return items, finished, done_slots, skipped, usable

    def status(self, subject: str) -> dict[str, Any]:
        """Where a subject is: the next step (with its start state for a trial, its model's state for a fit),
        trials done, skipped and to do."""
        doc = self.subject_doc(subject)
        items, finished, done_slots, skipped, usable = self._progress(subject)
        trials = [i for i in items if i.kind == "trial"]
        for i in trials:  # a block stopping on identification: its check, on its landed trials so far
            if i.stop_identified and i.slot not in done_slots and i.slot not in skipped:
                self.stops.poll(subject, i.group, usable.get(i.group, []), i.stop_identified, i.min_trials)
                break
        # steps are taken in order: the next one follows the last finished one (instructions shown before a
        # block's trials are not asked for again when the tab closed after its first trial)
        nxt = items[finished[-1] + 1 if finished else 0]
        step = nxt.to_json()
        if nxt.kind == "trial":
            step["x0"] = self.start(subject, nxt.slot)
            step["id"] = self.trial_id(subject, nxt)
            if nxt.assist != "none":
                step["help"] = self.assistance(subject, nxt, step["x0"])
        elif nxt.kind == "fit":
            self.fits.start(subject, nxt.label, nxt.role, nxt.min_trials)
            step["fit"] = self.fits.state(subject, nxt.label)
        last = max(((int(s), r) for s, r in (doc.get("rows") or {}).items()), default=(None, None))[1]
        return {"subject": subject, "fields": doc["fields"], "calibrated": bool(doc["calibrations"]),
                "trials_done": len(done_slots), "trials_skipped": len(skipped),
                "trials_total": len(trials) - len(skipped), "next": step, "order": doc.get("order"),
                "last": None if last is None else {k: last[k] for k in ("id", "outcome", "outcome_reason")},
                "summary": self.summary(subject) if nxt.kind == "end" else None}

    def summary(self, subject: str) -> list[dict[str, Any]]:
        """Per block label, role and assistance: trials finished and landed, from the subject's trial records."""
        doc = self.subject_doc(subject)
        rows: dict[tuple[str, str], dict[str, Any]] = {}
        for _, r in sorted((doc.get("rows") or {}).items(), key=lambda kv: int(kv[0])):
            key = (r["label"], r["role"], r.get("assist", "none"))
            s = rows.setdefault(key, {"label": r["label"], "role": r["role"], "assist": key[2], "trials": 0,
                                      "landed": 0})
            s["trials"] += 1
            s["landed"] += r["outcome"] == "landed"
        return list(rows.values())

    def model_for(self, subject: str, item: Item) -> tuple[Any, dict[str, Any]]:
        """The model assisting an item and what identifies it: ``{source, digest, data_digest}``."""
        if item.model == "fit":
            model, record = load_fitted(self.out, subject, item.label, self._fitted_cache)
            return model, {"source": "fit", "digest": record["digest"], "data_digest": record["data_digest"]}
        model = self.models[item.label]
        return model, {"source": "given", "digest": self.model_digests.get(item.label),
                       "data_digest": getattr(model, "data_digest_", None)}

    def assistance(self, subject: str, item: Item, x0: list[float]) -> dict[str, Any]:
        """What the page needs to assist a trial: the model's gain ``K`` (for ``blend``) and its mean predicted
        path from the start, as (across, height) points (for ``show``)."""
        model, which = self.model_for(subject, item)
        i = self.spec["index"]
        pred = model.predict(np.asarray(x0), self.spec["max_steps"], np.asarray(self.spec["target"]), clip=True)
        path = pred.x[:, [i["x"], i["y"]]]
        ground = np.flatnonzero(path[:, 1] <= 0.0)
        path = path[: ground[0] + 1] if len(ground) else path  # drawn down to the ground, not beyond it
        return {"kind": item.assist, "alpha": item.blend, "K": np.asarray(model.K_, dtype=np.float64).tolist(),
                "path": path.tolist(), "law": "u = (1 - alpha) u_pilot + alpha clip(K (x - target))",
                "model": which}

    def start(self, subject: str, slot: int) -> list[float]:
        """The start state of a trial slot: drawn from the seed, the subject and the slot, so a resumed trial
        starts where it would have."""
        return draw_start(self.spec, [self.seed, zlib.crc32(subject.encode()), slot])

    def _job_done(self, result: dict[str, Any]) -> None:
        if result.get("kind") == "stop":
            if result.get("state") == "failed":
                text = f"{result['subject']}: stopping rule's check on {result['n']} trials failed: {result['reason']}"
            else:
                text = (f"{result['subject']}: stopping rule after {result['n']} landed trials: {result['interval']}"
                        + ("; identified, the block ends" if result["identified"] else "; the block goes on"))
            self._event("stop", text)
            return
        if result.get("state") == "ready":
            err = result.get("held_out_error")
            text = (f"{result['subject']}: model of {result['label']} fitted on {result['n_train']} landed trials in "
                    f"{result['seconds']:.1f} s (digest {result['digest'][:12]}); {_chosen(result)}; "
                    f"held-out {result['metric']} "
                    + (f"{err:.3g} over {len(result['held_out'])} trial(s)" if err is not None else "not checked: "
                       "no held-out trials"))
        else:
            text = f"{result['subject']}: model of {result['label']} NOT fitted: {result['reason']}"
        self._event("fit", text)
        if self.on_fit is not None:
            self.on_fit(result)

    # -- trials ------------------------------------------------------------------------------------------
    def write_trial(self, payload: Any) -> dict[str, Any]:
        """Check a finished trial from the page, replay it through the plant and write it (MCAP, then Parquet).

        Raises
        ------
        DataError
            One line: an unknown subject or slot, a slot already finished, malformed arrays, states or an
            outcome that the plant's replay does not reproduce, a calibration that is not the subject's.
        """
        if not isinstance(payload, dict):
            raise DataError("trial: expected a JSON object")
        subject = check_subject(payload.get("subject"))
        slot = payload.get("slot")
        if self.subject_doc(subject) is None:
            raise DataError(f"subject {subject!r}: not registered in this session")
        _, _, done, skipped, _ = self._progress(subject)
        items = {i.slot: i for i in self.plan(subject) if i.kind == "trial"}
        if not isinstance(slot, int) or isinstance(slot, bool) or slot not in items:
            raise DataError(f"trial: slot {str(slot)[:20]} is not a trial of subject {subject!r}'s plan")
        item = items[slot]
        trial_id = self.trial_id(subject, item)
        expected = min((j for j in items if j not in done and j not in skipped), default=None)
        if slot != expected and slot not in done:
            raise DataError(f"trial {trial_id}: out of order (the next trial of {subject!r} is slot {expected}); "
                            "reload the page to resume")
        where = f"trial {trial_id}"
        doc = self.subject_doc(subject)
        cal = payload.get("calibration")
        if isinstance(cal, dict) and cal.get("kind") in ("gamepad", "keyboard"):
            latest = {k: v for k, v in (doc["calibrations"] or [{}])[-1].items() if k != "at"}
            if cal != latest:
                raise DataError(f"{where}: calibration: not the subject's recorded calibration (calibrate again)")
        x0 = self.start(subject, slot)
        help_ = self.assistance(subject, item, x0) if item.assist != "none" else None
        demo, streams = checked_trial(self.spec, payload, x0, where, help_, self.protocol.input)
        starts = (doc.get("starts") or {}).get(str(slot), [])
        lost = [{"kind": "restarted", "at": s} for s in starts[:-1]]
        demo_meta = {
            "id": trial_id, "subject": subject, "label": item.label, "role": item.role, "trial": item.trial,
            "slot": slot, "block": item.block, "start": x0, "target": self.spec["target"],
            "outcome": demo["outcome"], "outcome_reason": demo["reason"], "success": demo["outcome"] == "landed",
            "source": "workbench collect", "protocol": self.protocol.name,
            "protocol_fingerprint": self.protocol.fingerprint, "subject_fields": doc["fields"],
            "consent_sha256": (doc.get("consent") or {}).get("sha256"), "condition_order": doc.get("order"),
            "device": demo["device"], "calibration": demo["calibration"], "input": self.protocol.input.to_json(),
            "timing": demo["timing"], "started": starts[-1] if starts else None, "finished": now(),
            "attempts": max(1, len(starts)), "interruptions": lost + demo["interruptions"],
            "excluded": False, "exclusion_note": "",
        }
        reference = getattr(self.protocol.steps[item.block], "reference", None)
        if reference is not None:  # the path the block's instruction asks for: a fit regulates the deviation from it
            demo_meta["reference"] = reference
        if help_ is not None:
            demo_meta["assist"] = {k: help_[k] for k in ("kind", "alpha", "K", "law", "model")}
            demo_meta["pilot_u"] = demo["pilot"].tolist()  # the pilot's own input; ``u`` is what the plant got
        with self._lock:
            if self._partition(subject, trial_id).is_file():
                raise DataError(f"{where}: already recorded; the page is behind (reload it to resume)")
            mcap = self.out / HIDDEN / "mcap" / subject / f"{trial_id}.mcap"
            try:
                _write_mcap(mcap, streams, demo_meta)
                _write_partition(self, subject, trial_id, demo["x"], demo["u"], demo_meta,
                                 order=int(doc["index"]) * 100_000 + slot)
            except BaseException:
                mcap.unlink(missing_ok=True)  # a disk that filled up between the two: no MCAP of an unwritten trial
                raise
            row = records.trial_row(demo_meta, len(demo["u"]), self.spec["dt"])
            fresh = self.subject_doc(subject)
            fresh.setdefault("rows", {})[str(slot)] = row
            write_json(self._subject_file(subject), fresh)
            records.write_trials_csv(self.out)
        return {"id": trial_id, "outcome": demo["outcome"], "outcome_reason": demo["reason"],
                "samples": len(demo["u"]), "label": item.label, "role": item.role, "trial": item.trial,
                **self.status(subject)}

    def write_practice(self, payload: Any) -> dict[str, Any]:
        """A practice trial: checked like a trial; kept in ``_collect/practice/`` only if the protocol records
        practice, never in the dataset."""
        if not isinstance(payload, dict):
            raise DataError("practice: expected a JSON object")
        subject = check_subject(payload.get("subject"))
        if self.subject_doc(subject) is None:
            raise DataError(f"subject {subject!r}: not registered in this session")
        x0 = payload.get("x0")
        if not (isinstance(x0, list) and len(x0) == len(self.spec["state_names"]) and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and abs(v) < 100
                for v in x0)):
            raise DataError("practice: x0: expected the start state (a list of finite numbers)")
        demo, _ = checked_trial(self.spec, payload, [float(v) for v in x0], "practice trial", None,
                                self.protocol.input)
        if not self.protocol.practice_recorded:
            return {"recorded": False, "outcome": demo["outcome"], "outcome_reason": demo["reason"]}
        from workbench.data.demonstrations import Demonstration, DemonstrationSet

        folder = self.out / HIDDEN / "practice" / subject
        with self._lock:
            n = len(list(folder.glob("*.parquet"))) if folder.is_dir() else 0
            if n >= 1000:
                raise RequestError(f"{folder}: 1000 practice trials recorded already", 507)
            pid = f"{subject}-practice-{n:03d}"
            d = Demonstration(self.spec["dt"] * np.arange(len(demo["u"])), demo["x"], demo["u"],
                              {"id": pid, "subject": subject, "label": "practice", "role": "practice",
                               "outcome": demo["outcome"], "outcome_reason": demo["reason"],
                               "device": demo["device"], "timing": demo["timing"]})
            DemonstrationSet([d], self.spec["state_names"], self.spec["input_names"], self.spec["dt"]).save(
                folder / f"{pid}.parquet")
        return {"recorded": True, "outcome": demo["outcome"], "outcome_reason": demo["reason"]}

    def exclude(self, trial_id: str, excluded: bool = True, note: str = "") -> dict[str, Any]:
        """The experimenter excludes a trial from the analysis (or includes it again), with a note."""
        with self._lock:
            row = records.set_exclusion(self.out, trial_id, excluded, note)
        self._event("exclusion", f"{trial_id} " + (f"excluded ({row['exclusion_note']})" if row["excluded"]
                                                    else "included again"))
        return row

    def _fit_waits_for(self, subject: str, label: str) -> str:
        """A waiting fit step of ``label`` in words: the trials of its label before it in this subject's plan, how
        many of them are flown (a block with a stopping rule may end early: "up to")."""
        items, _, done_slots, skipped, _ = self._progress(subject)
        at = next((j for j, i in enumerate(items) if i.kind == "fit" and i.label == label), len(items))
        before = [i for i in items[:at] if i.kind == "trial" and i.label == label and i.slot not in skipped]
        variable = any((i.stop_landed or i.stop_identified) and i.slot not in done_slots for i in before)
        return _waiting_words(label, sum(i.slot in done_slots for i in before), len(before), variable)

    def overview(self) -> dict[str, Any]:
        """The whole session for the experimenter's page: every subject's progress, trials and fits."""
        subjects = []
        for s in self.subjects():
            doc = self.subject_doc(s)
            st = self.status(s)
            fits = {f.label: self.fits.state(s, f.label) for f in self.protocol.fits}
            for label, state in fits.items():
                if state["state"] == "waiting":
                    state["waiting_for"] = self._fit_waits_for(s, label)
            subjects.append({"subject": s, "index": doc["index"], "order": doc.get("order"),
                             "consent": doc.get("consent"), "warnings": doc.get("warnings", []),
                             "trials_done": st["trials_done"], "trials_total": st["trials_total"],
                             "next": {k: st["next"][k] for k in ("kind", "key", "label", "trial") if k in st["next"]},
                             "rows": [r for _, r in sorted((doc.get("rows") or {}).items(), key=lambda kv: int(kv[0]))],
                             "fits": fits})
        return {"protocol": self.protocol.name, "fingerprint": self.protocol.fingerprint, "out": str(self.out),
                "subjects": subjects}


def _waiting_words(label: str, flown: int, total: int, variable: bool) -> str:
    """What a fit step that has not started waits for, in words: "after block CS1 (2 of 10 trials flown)"."""
    of = f"up to {total}" if variable else str(total)
    if flown < total:
        return f"after block {label} ({flown} of {of} trials flown)"
    return f"after block {label} (all {flown} trials flown): starts when the subject reaches the fit step"


def _chosen(record: dict[str, Any]) -> str:
    """What a fit step's default model chose, in a few words (its record's ``settings`` has the whole line)."""
    G, reg = record.get("n_components"), record.get("reg_covar")
    if record.get("settings") is None:  # too few trials to cross-validate: the defaults, capped by the samples
        return f"G = {G}, reg_covar = {reg:g} (too few trials to cross-validate)"
    return f"G = {G}, reg_covar = {reg:g} by cross-validation" + (
        ", predicting with K̂x alone (its variability model did not lower the held-out error)"
        if record.get("fallback") else "")


def _sha256(text: str) -> str:
    import hashlib

    return hashlib.sha256(text.encode("utf-8")).hexdigest()


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
    roles = session.plant.roles
    write_partitions(DemonstrationSet([d], spec["state_names"], spec["input_names"], spec["dt"], roles=roles),
                     session.out, trial_id, source="workbench collect", order=order)
