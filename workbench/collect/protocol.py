"""The experiment as a file: a TOML protocol read with :mod:`tomllib`, checked, bounded, and pinned by its digest.

A protocol says what a subject sees, in order: the consent text, the subject's metadata fields, an optional
practice, then the session's steps (``[[blocks]]``): blocks of trials (a strategy label, its instructions, the
number of trials, their role train/test or ``held_out`` of them drawn at random as test), messages (a briefing),
and ``fit`` steps (this subject's model fitted on their own trials during a break, for the assisted blocks after
it); breaks come between steps and every ``every_trials`` trials. The order of the conditions (the trial blocks'
labels, in order of first appearance; a label's blocks stay in their order) is counterbalanced across subjects,
by registration order or, better, by the experimenter's declared subject IDs::

    title = "Quadrotor landing"
    consent = "You will land a simulated quadrotor …"
    time_limit_s = 30.0

    counterbalance = "latin"        # none | reverse | rotate (by registration order) | latin | assigned
    subjects = ["s01", "s02"]       # the declared IDs: latin gives the i-th its row of a balanced Latin square;
    [orders]                        # assigned: each declared ID's order of the conditions
    s01 = ["CS2", "CS1"]

    [[fields]]                      # subject metadata asked once, after consent
    name = "age"
    label = "Age (years)"
    type = "number"                 # text | number | choice (with choices = [...])
    required = false

    [input]                         # what the sticks do, recorded with every trial
    device = "any"                  # any (a gamepad, or the keyboard) | gamepad (a gamepad only)
    deadzone = "measured"           # a number in [0, 0.5), or "measured": 3 × the sticks' noise at rest (≤ 0.3)
    expo = 0.0                      # [0, 1]: u = (1 − e) v + e v³ after the dead zone (finer small commands)
    gamepad_rule = "latest"         # the pad is read at the display rate; a physics step takes the latest read,
                                    # or the mean of the reads since the previous step ("mean")

    [practice]
    duration_s = 600                # 0: none
    recorded = false                # true: kept in DIR/_collect/practice/, outside the dataset

    [breaks]
    between_blocks_s = 60
    every_trials = 0                # also a break after every N trials of a block (0: none)
    duration_s = 60                 # the length of those

    [[blocks]]                      # a briefing: shown until Space, not before min_s
    message = { title = "Briefing", text = "…", min_s = 0 }

    [[blocks]]
    label = "CS1"
    instructions = "Centre horizontally first, then descend."
    trials = 30
    role = "train"                  # train | test
    held_out = 0                    # of the trials, this many (drawn per subject) are test trials instead
    assist = "none"                 # none | show (the model's predicted path) | blend (see below)
    blend = 0.3                     # with assist = "blend": the model's share α of the input
    reference = "horizontal-first"  # optional: the path the instruction asks for (line | horizontal-first); a fit
                                    # then regulates the deviation from it, with its feedforward
    stop = { landed = 10 }          # optional: the block ends once this many of its trials landed, or
                                    # once a contrast of the objective is identified (checked in a worker after
                                    # each landed trial from min_trials on; the weight ratios' bootstrap):
                                    # stop = { identified = "Q_phi / R_u1", min_trials = 5, landed = 30 }

    [[blocks]]                      # this subject's model of CS1, from their landed, not excluded train trials
    fit = { label = "CS1", from = "train", min_trials = 5, break_s = 60 }

An assisted block needs a model of its label: a ``fit`` step of that label before it (in every order the
counterbalancing gives), or ``workbench collect --model CS1=cs1.npz``. ``show`` draws the model's mean predicted
path from the trial's start; ``blend`` gives the plant ``u = (1 − α) u_pilot + α clip(K̂ (x − x_target))``, and
the recording keeps ``u_pilot`` apart (:mod:`.task`, ``blend``).

Every size is bounded (:data:`LIMITS`): a protocol is refused on its first count over a bound, before anything
is planned. :attr:`Protocol.fingerprint` is the SHA-256 of the checked protocol as the session runs it (after
``--max-trials``/``--max-pause``); a session stores it with the file's text and refuses to resume under another.

Shipped: :data:`SHIPPED`; ``--protocol`` takes one of their names or a path. Every mistake is a
:class:`~workbench.errors.DataError` of one line naming the file, the key and the cause.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.data.pilot_task import REFERENCES
from workbench.errors import DataError

__all__ = ["Field", "Block", "Message", "FitStep", "InputSettings", "Protocol", "load_protocol", "parse_protocol",
           "SHIPPED", "LIMITS", "LABEL_PATTERN", "condition_order", "step_order", "check_fits", "williams",
           "first_difference"]

PROTOCOL_DIR = Path(__file__).with_name("protocols")
SHIPPED = ("paper_single_subject", "paper_multi_subject", "assisted_single_subject")
COUNTERBALANCE = ("none", "reverse", "rotate", "latin", "assigned")
ROLES = ("train", "test")
ASSISTS = ("none", "show", "blend")
FIELD_TYPES = ("text", "number", "choice")
DEVICES = ("any", "gamepad")
GAMEPAD_RULES = ("latest", "mean")
#: A weight ratio of the objective, as :func:`workbench.method.ratio_profile.ratio_names` names them.
RATIO_PATTERN = re.compile(r"[QR]_\w{1,40} / R_\w{1,40}")
#: A label names files and folders: short, plain.
LABEL_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,31}")
#: Every bound a protocol is checked against (a protocol past one is refused on the first count over it).
LIMITS = {
    "bytes": 256 << 10,  # the file (not read whole when larger)
    "steps": 100,  # entries of [[blocks]]
    "trials_per_block": 1000,
    "trials": 2000,  # per subject, all blocks together
    "text": 20_000,  # characters of the consent, an instruction, a message
    "title": 200,
    "fields": 30,
    "choices": 50,
    "choice": 100,
    "subjects": 1000,  # declared subject IDs
}
DEADZONE_MAX = 0.5
MEASURED = "measured"


@dataclass(frozen=True)
class Field:
    """One subject metadata field asked on the page."""

    name: str
    label: str
    type: str = "text"
    required: bool = False
    choices: tuple[str, ...] = ()


@dataclass(frozen=True)
class Block:
    """Trials of one strategy label, with the instructions shown before them."""

    label: str
    instructions: str
    trials: int
    role: str = "train"
    held_out: int = 0
    assist: str = "none"
    blend: float = 0.0
    stop_landed: int = 0  # 0: no stopping rule; else the block ends once this many of its trials landed
    stop_identified: str = ""  # a weight ratio ("Q_phi / R_u1"): the block ends once its interval identifies it
    stop_min_trials: int = 0  # landed trials before the identification is first checked
    kind: str = "trials"
    #: The reference the instruction asks the pilot to follow (:data:`workbench.data.pilot_task.REFERENCES`), written
    #: into each trial's ``meta["reference"]``; a fit of the trials then regulates the deviation from it. None: the
    #: goal (the pad), as the paper's fits.
    reference: str | None = None


@dataclass(frozen=True)
class Message:
    """A page of text (a briefing): shown until the subject presses Space, and not before ``min_s``."""

    title: str
    text: str
    min_s: float = 0.0
    kind: str = "message"


@dataclass(frozen=True)
class FitStep:
    """This subject's model of ``label``, fitted on their own trials of role ``source`` (landed, not excluded)
    while they take a break of at least ``break_s``; checked on their held-out (role test) trials of the label."""

    label: str
    source: str = "train"
    min_trials: int = 3
    break_s: float = 0.0
    kind: str = "fit"


Step = Block | Message | FitStep


@dataclass(frozen=True)
class InputSettings:
    """What the sticks do: the device allowed, the dead zone (a number, or ``"measured"`` at rest), the expo and
    the rule by which a physics step takes the pad's display-rate reads."""

    device: str = "any"
    deadzone: float | str = MEASURED
    expo: float = 0.0
    gamepad_rule: str = "latest"

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Protocol:
    """A checked protocol (see the module docstring); ``source`` is where it was read from, ``text`` its file."""

    name: str
    title: str
    consent: str
    fields: tuple[Field, ...]
    steps: tuple[Step, ...]
    practice_s: float = 0.0
    practice_recorded: bool = False
    between_blocks_s: float = 0.0
    every_trials: int = 0
    break_s: float = 0.0
    counterbalance: str = "none"
    time_limit_s: float = 30.0
    input: InputSettings = field(default_factory=InputSettings)
    subjects: tuple[str, ...] = ()
    orders: tuple[tuple[str, tuple[str, ...]], ...] = ()
    source: str = ""
    text: str = ""

    @property
    def blocks(self) -> tuple[Block, ...]:
        """The blocks of trials, in the file's order."""
        return tuple(s for s in self.steps if isinstance(s, Block))

    @property
    def fits(self) -> tuple[FitStep, ...]:
        return tuple(s for s in self.steps if isinstance(s, FitStep))

    @property
    def conditions(self) -> list[str]:
        """The trial blocks' labels in the file's order of first appearance: what counterbalancing reorders."""
        return list(dict.fromkeys(b.label for b in self.blocks))

    @property
    def consent_sha256(self) -> str:
        """The SHA-256 of the consent text the page shows: what a subject's consent record names."""
        return hashlib.sha256(self.consent.encode("utf-8")).hexdigest()

    def content(self) -> dict[str, Any]:
        """The protocol as the session runs it, as plain JSON values (no file name, no file text)."""
        doc = asdict(self)
        for key in ("source", "text", "name"):
            doc.pop(key)
        doc["blocks"] = doc.pop("steps")  # the file's word, so a refusal names the key the experimenter edits
        return doc

    @property
    def fingerprint(self) -> str:
        """The SHA-256 of :meth:`content` (canonical JSON): equal for equal protocols wherever they were read."""
        return hashlib.sha256(json.dumps(self.content(), sort_keys=True).encode("utf-8")).hexdigest()

    def shortened(self, max_trials: int | None = None, max_pause_s: float | None = None) -> Protocol:
        """The same protocol with at most ``max_trials`` per block and breaks, practice, messages' minimum and fit
        breaks cut to ``max_pause_s`` (for a scripted run, a demonstration or a test; a real session runs the
        file as written)."""
        cut = None if max_pause_s is None else float(max_pause_s)
        steps = []
        for s in self.steps:
            if isinstance(s, Block) and max_trials is not None:
                s = replace(s, trials=min(s.trials, max_trials), held_out=min(s.held_out, max_trials - 1),
                            stop_landed=min(s.stop_landed, max_trials),
                            stop_min_trials=min(s.stop_min_trials, max_trials))
            elif isinstance(s, Message) and cut is not None:
                s = replace(s, min_s=min(s.min_s, cut))
            elif isinstance(s, FitStep) and cut is not None:
                s = replace(s, break_s=min(s.break_s, cut))
            steps.append(s)
        out = replace(self, steps=tuple(steps))
        if cut is not None:
            out = replace(out, practice_s=min(self.practice_s, cut), between_blocks_s=min(self.between_blocks_s, cut),
                          break_s=min(self.break_s, cut))
        return out

    def order_of(self, subject: str) -> tuple[str, ...] | None:
        """The experimenter's assigned order of conditions for ``subject`` (``counterbalance = "assigned"``)."""
        return dict(self.orders).get(subject)

    def to_json(self) -> dict[str, Any]:
        """What the page is told of the protocol (the rest it gets step by step)."""
        return {
            "name": self.name, "title": self.title, "consent": self.consent, "consent_sha256": self.consent_sha256,
            "fields": [f.__dict__ | {"choices": list(f.choices)} for f in self.fields],
            "practice": {"duration_s": self.practice_s, "recorded": self.practice_recorded},
            "time_limit_s": self.time_limit_s, "counterbalance": self.counterbalance, "input": self.input.to_json(),
        }


# -- reading ------------------------------------------------------------------------------------------------
class _Reader:
    """Checks of one file's values; every failure is one line naming the file and the key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, cause: str) -> DataError:
        return DataError(f"{self.source}: {where}: {cause}" if where else f"{self.source}: {cause}")

    def get(self, table: dict, key: str, kind: type | tuple, where: str, default: Any = ...) -> Any:
        if key not in table:
            if default is ...:
                raise self.fail(where + key, "missing")
            return default
        value = table[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if (isinstance(value, bool) and bool not in kinds) or not isinstance(value, kinds):
            raise self.fail(where + key, f"expected {_kind_name(kinds)}, got {type(value).__name__} "
                                         f"{_short(value)}")
        return value

    def text(self, table: dict, key: str, where: str, default: Any = ..., limit: int = LIMITS["text"]) -> str:
        value = self.get(table, key, str, where, default)
        if len(value) > limit:
            raise self.fail(where + key, f"{len(value)} characters; at most {limit}")
        return value

    def number(self, table: dict, key: str, where: str, default: float, lo: float, hi: float) -> float:
        value = float(self.get(table, key, (int, float), where, default))
        if not (np.isfinite(value) and lo <= value <= hi):
            raise self.fail(where + key, f"must be between {lo:g} and {hi:g}, got {_short(value)}")
        return value

    def integer(self, table: dict, key: str, where: str, default: int, lo: int, hi: int) -> int:
        value = self.get(table, key, int, where, default)
        if not lo <= value <= hi:
            raise self.fail(where + key, f"must be between {lo} and {hi}, got {_short(value)}")
        return value

    def seconds(self, table: dict, key: str, where: str) -> float:
        return self.number(table, key, where, 0, 0, 24 * 3600)

    def known(self, table: dict, known: set[str], where: str) -> None:
        extra = sorted(set(table) - known)
        if extra:
            raise self.fail(where + extra[0][:40], f"unknown key (known: {', '.join(sorted(known))})")

    def label(self, value: str, where: str) -> str:
        if not LABEL_PATTERN.fullmatch(value):
            raise self.fail(where, f"{_short(value)} must be 1–32 letters, digits, '_' or '-', starting with a "
                                   "letter or digit")
        return value


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "…"


def _kind_name(kinds: tuple) -> str:
    names = {str: "text", int: "an integer", float: "a number", bool: "true or false", dict: "a table",
             list: "a list"}
    return " or ".join(dict.fromkeys(names.get(k, k.__name__) for k in kinds))


def _fields(r: _Reader, doc: dict) -> tuple[Field, ...]:
    raw = r.get(doc, "fields", list, "", [])
    if len(raw) > LIMITS["fields"]:
        raise r.fail("fields", f"{len(raw)} fields; at most {LIMITS['fields']}")
    fields = []
    for j, f in enumerate(raw):
        where = f"fields[{j}]."
        if not isinstance(f, dict):
            raise r.fail(f"fields[{j}]", "expected a table ([[fields]])")
        r.known(f, {"name", "label", "type", "required", "choices"}, where)
        name = r.text(f, "name", where, limit=40)
        if not name.isidentifier() or not name.isascii() or name in ("subject", "id"):
            raise r.fail(where + "name", f"{_short(name)} is not a plain identifier other than subject and id")
        kind = r.get(f, "type", str, where, "text")
        if kind not in FIELD_TYPES:
            raise r.fail(where + "type", f"{_short(kind)} is not one of {', '.join(FIELD_TYPES)}")
        choices = r.get(f, "choices", list, where, [])
        if len(choices) > LIMITS["choices"] or not all(isinstance(c, str) and 0 < len(c) <= LIMITS["choice"]
                                                       for c in choices):
            raise r.fail(where + "choices", f"at most {LIMITS['choices']} texts of 1–{LIMITS['choice']} characters")
        if (kind == "choice") != bool(choices):
            raise r.fail(where + "choices", "a choice field needs choices, other fields take none")
        fields.append(Field(name, r.text(f, "label", where, name, limit=LIMITS["title"]), kind,
                            r.get(f, "required", bool, where, False), tuple(choices)))
    if len({f.name for f in fields}) != len(fields):
        raise r.fail("fields", "two fields have the same name")
    return tuple(fields)


def _input(r: _Reader, doc: dict) -> InputSettings:
    table = r.get(doc, "input", dict, "", {})
    r.known(table, {"device", "deadzone", "expo", "gamepad_rule"}, "input.")
    device = r.get(table, "device", str, "input.", "any")
    if device not in DEVICES:
        raise r.fail("input.device", f"{_short(device)} is not one of {', '.join(DEVICES)}")
    rule = r.get(table, "gamepad_rule", str, "input.", "latest")
    if rule not in GAMEPAD_RULES:
        raise r.fail("input.gamepad_rule", f"{_short(rule)} is not one of {', '.join(GAMEPAD_RULES)}")
    dz = r.get(table, "deadzone", (str, int, float), "input.", MEASURED)
    if isinstance(dz, str):
        if dz != MEASURED:
            raise r.fail("input.deadzone", f"a number in [0, {DEADZONE_MAX}) or \"{MEASURED}\", got {_short(dz)}")
    else:
        dz = float(dz)
        if not (np.isfinite(dz) and 0 <= dz < DEADZONE_MAX):
            raise r.fail("input.deadzone", f"a number in [0, {DEADZONE_MAX}) or \"{MEASURED}\", got {_short(dz)}")
    return InputSettings(device, dz, r.number(table, "expo", "input.", 0.0, 0.0, 1.0), rule)


def _block(r: _Reader, b: dict, where: str) -> Block:
    r.known(b, {"label", "instructions", "trials", "role", "held_out", "assist", "blend", "stop", "reference"}, where)
    label = r.label(r.get(b, "label", str, where), where + "label")
    trials = r.integer(b, "trials", where, ..., 1, LIMITS["trials_per_block"])
    role = r.get(b, "role", str, where, "train")
    if role not in ROLES:
        raise r.fail(where + "role", f"{_short(role)} is not one of {', '.join(ROLES)}")
    held = r.get(b, "held_out", int, where, 0)
    if not 0 <= held < trials or (held and role != "train"):
        raise r.fail(where + "held_out", f"must be 0 or fewer than the block's {trials} trials, and only in a train "
                                         f"block (got {_short(held)} in a {role} block)")
    assist = r.get(b, "assist", str, where, "none")
    if assist not in ASSISTS:
        raise r.fail(where + "assist", f"{_short(assist)} is not one of {', '.join(ASSISTS)}")
    alpha = float(r.get(b, "blend", (int, float), where, 0.3 if assist == "blend" else 0.0))
    if assist == "blend" and not (np.isfinite(alpha) and 0 < alpha <= 1) or assist != "blend" and "blend" in b:
        raise r.fail(where + "blend", f"the model's share must be in (0, 1], and only with assist = \"blend\" (got "
                                      f"{_short(alpha)} with assist = {_short(assist)})")
    stop = r.get(b, "stop", dict, where, {})
    r.known(stop, {"landed", "identified", "min_trials"}, where + "stop.")
    landed = r.integer(stop, "landed", where + "stop.", 0, 1, trials) if "landed" in stop else 0
    identified = r.text(stop, "identified", where + "stop.", "", limit=80)
    if identified and not RATIO_PATTERN.fullmatch(identified):
        raise r.fail(where + "stop.identified", f"{_short(identified)} is not a weight ratio such as "
                                                "\"Q_phi / R_u1\" or \"R_u2 / R_u1\"")
    least = r.integer(stop, "min_trials", where + "stop.", 5, 3, trials) if identified else 0
    if "min_trials" in stop and not identified:
        raise r.fail(where + "stop.min_trials", "goes with stop.identified")
    reference = r.get(b, "reference", str, where, None)
    if reference is not None and reference not in REFERENCES:
        raise r.fail(where + "reference", f"{_short(reference)} is not one of {', '.join(REFERENCES)}")
    return Block(label, r.text(b, "instructions", where), trials, role, held, assist, alpha, landed, identified,
                 least, reference=reference)


def _step(r: _Reader, b: Any, j: int) -> Step:
    where = f"blocks[{j}]."
    if not isinstance(b, dict):
        raise r.fail(f"blocks[{j}]", "expected a table ([[blocks]])")
    if "message" in b:
        r.known(b, {"message"}, where)
        m = r.get(b, "message", dict, where)
        r.known(m, {"title", "text", "min_s"}, where + "message.")
        return Message(r.text(m, "title", where + "message.", "", limit=LIMITS["title"]),
                       r.text(m, "text", where + "message."), r.seconds(m, "min_s", where + "message."))
    if "fit" in b:
        r.known(b, {"fit"}, where)
        f = r.get(b, "fit", dict, where)
        w = where + "fit."
        r.known(f, {"label", "from", "min_trials", "break_s"}, w)
        source = r.get(f, "from", str, w, "train")
        if source != "train":
            raise r.fail(w + "from", f"{_short(source)}: a model is fitted on the subject's train trials (\"train\")")
        return FitStep(r.label(r.get(f, "label", str, w), w + "label"), source,
                       r.integer(f, "min_trials", w, 3, 2, LIMITS["trials_per_block"]), r.seconds(f, "break_s", w))
    return _block(r, b, where)


def _conditions(r: _Reader, doc: dict, blocks: list[Block]) -> tuple[str, tuple[str, ...], tuple]:
    counter = r.get(doc, "counterbalance", str, "", "none")
    if counter not in COUNTERBALANCE:
        raise r.fail("counterbalance", f"{_short(counter)} is not one of {', '.join(COUNTERBALANCE)}")
    subjects = r.get(doc, "subjects", list, "", [])
    if len(subjects) > LIMITS["subjects"]:
        raise r.fail("subjects", f"{len(subjects)} IDs; at most {LIMITS['subjects']}")
    from workbench.collect.subjects import SUBJECT_PATTERN

    for j, s in enumerate(subjects):
        if not isinstance(s, str) or not SUBJECT_PATTERN.fullmatch(s):
            raise r.fail(f"subjects[{j}]", f"{_short(s)} is not a subject ID (1–40 letters, digits, '_' or '-')")
    if len(set(subjects)) != len(subjects):
        raise r.fail("subjects", "an ID is declared twice")
    conditions = list(dict.fromkeys(b.label for b in blocks))
    orders = r.get(doc, "orders", dict, "", {})
    if counter in ("latin", "assigned") and not subjects:
        raise r.fail("subjects", f"counterbalance = \"{counter}\" needs the declared subject IDs (subjects = [...])")
    if bool(orders) != (counter == "assigned"):
        raise r.fail("orders", "an order per subject goes with counterbalance = \"assigned\" (and only with it)")
    out = []
    for s, order in orders.items():
        if s not in subjects:
            raise r.fail(f"orders.{s[:40]}", "not one of the declared subjects")
        if not isinstance(order, list) or sorted(map(str, order)) != sorted(conditions):
            raise r.fail(f"orders.{s}", f"must list each condition once ({', '.join(conditions)})")
        out.append((s, tuple(order)))
    if counter == "assigned" and (missing := [s for s in subjects if s not in orders]):
        raise r.fail("orders", f"no order for the declared subject {missing[0]!r}")
    return counter, tuple(subjects), tuple(out)


def parse_protocol(doc: dict, source: str, name: str, text: str = "") -> Protocol:
    """A :class:`Protocol` from a parsed TOML document; every mistake is one :class:`DataError` line."""
    r = _Reader(source)
    r.known(doc, {"title", "consent", "fields", "practice", "breaks", "counterbalance", "blocks", "time_limit_s",
                  "input", "subjects", "orders"}, "")
    title = r.text(doc, "title", "", name, limit=LIMITS["title"])
    consent = r.text(doc, "consent", "")
    if not consent.strip():
        raise r.fail("consent", "empty; a subject must be told what the experiment is")
    practice = r.get(doc, "practice", dict, "", {})
    r.known(practice, {"duration_s", "recorded"}, "practice.")
    breaks = r.get(doc, "breaks", dict, "", {})
    r.known(breaks, {"between_blocks_s", "every_trials", "duration_s"}, "breaks.")
    every = r.integer(breaks, "every_trials", "breaks.", 0, 0, LIMITS["trials_per_block"])
    limit = r.number(doc, "time_limit_s", "", 30.0, 1.0, 600.0)
    raw = r.get(doc, "blocks", list, "")
    if not raw:
        raise r.fail("blocks", "none; a protocol needs at least one [[blocks]] of trials")
    if len(raw) > LIMITS["steps"]:
        raise r.fail("blocks", f"{len(raw)} entries; at most {LIMITS['steps']}")
    steps: list[Step] = []
    total = 0
    for j, b in enumerate(raw):
        # the count first: a protocol of 1000 blocks of 1000 trials stops here, before anything is built from it
        n = b.get("trials") if isinstance(b, dict) else None
        if isinstance(n, int) and not isinstance(n, bool) and n > 0:
            total += n
            if total > LIMITS["trials"]:
                raise r.fail(f"blocks[{j}].trials", f"{total} trials per subject so far; at most {LIMITS['trials']}")
        steps.append(_step(r, b, j))
    blocks = [s for s in steps if isinstance(s, Block)]
    if not blocks:
        raise r.fail("blocks", "no block of trials; a protocol needs at least one")
    counter, subjects, orders = _conditions(r, doc, blocks)
    protocol = Protocol(
        name=name, title=title, consent=consent, fields=_fields(r, doc), steps=tuple(steps),
        practice_s=r.seconds(practice, "duration_s", "practice."),
        practice_recorded=r.get(practice, "recorded", bool, "practice.", False),
        between_blocks_s=r.seconds(breaks, "between_blocks_s", "breaks."), every_trials=every,
        break_s=r.seconds(breaks, "duration_s", "breaks."), counterbalance=counter, time_limit_s=limit,
        input=_input(r, doc), subjects=subjects, orders=orders, source=source, text=text,
    )
    check_fits(protocol)
    return protocol


def load_protocol(spec: str | os.PathLike) -> Protocol:
    """A shipped protocol by name (:data:`SHIPPED`) or a TOML file by path."""
    text = str(spec)
    path = PROTOCOL_DIR / f"{text}.toml" if text in SHIPPED else Path(spec)
    if not path.is_file():
        raise DataError(f"{text}: no such protocol file (shipped protocols: {', '.join(SHIPPED)})")
    size = path.stat().st_size
    if size > LIMITS["bytes"]:
        raise DataError(f"{path}: {size} bytes: too large for a protocol (at most {LIMITS['bytes']})")
    try:
        body = path.read_bytes()[: LIMITS["bytes"] + 1].decode("utf-8")
        doc = tomllib.loads(body)
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:  # tomllib recurses into nested arrays and inline tables
        raise DataError(f"{path}: not a protocol (values nested too deeply)") from None
    except ValueError:  # Python's limit on an integer's digits (4300): a number no protocol holds
        raise DataError(f"{path}: not a protocol (a number too long to read)") from None
    return parse_protocol(doc, str(path), path.stem, body)


# -- orders of conditions -----------------------------------------------------------------------------------
# Which order of the conditions a subject gets and why: the file's order, reversed or rotated by registration
# order, a row of a balanced Latin square (Williams 1949) chosen by the subject's place among the declared IDs, or
# the experimenter's assigned order; a subject who is not among the declared IDs gets a stated fallback (the server
# reports it as a warning). Trial blocks are reordered among the places trial blocks hold in the file; messages and
# fit steps keep their places. check_fits refuses a protocol where, in some order it can give, a fit step comes
# before any training trials of its label or an assisted block of a fitted label comes before its fit.

def williams(n: int) -> list[list[int]]:
    """The rows of a balanced Latin square of ``n`` conditions (Williams 1949): every condition once in each place,
    and every condition follows every other equally often (``2n`` rows for odd ``n``, else ``n``)."""
    first, lo, hi = [0], 1, n - 1
    while len(first) < n:
        first.append(lo)
        lo += 1
        if len(first) < n:
            first.append(hi)
            hi -= 1
    rows = [[(c + r) % n for c in first] for r in range(n)]
    return rows + [row[::-1] for row in rows] if n % 2 else rows


def condition_order(protocol: Protocol, subject: str, index: int) -> tuple[list[str], str]:
    """The order of the conditions for ``subject`` (the ``index``-th registered), and how it was chosen."""
    conditions, mode = protocol.conditions, protocol.counterbalance
    if mode == "none" or len(conditions) < 2:
        return conditions, "the file's order"
    if mode == "reverse":
        return (conditions[::-1], "reversed (an odd registration)") if index % 2 else (conditions, "the file's order")
    if mode == "rotate":
        shift = index % len(conditions)
        return conditions[shift:] + conditions[:shift], f"rotated by {shift} (registration {index + 1})"
    declared = list(protocol.subjects)
    if mode == "assigned":
        order = protocol.order_of(subject)
        if order is not None:
            return list(order), "assigned by the experimenter"
        return conditions, "the file's order (not a declared subject, so no assigned order)"
    square = williams(len(conditions))
    if subject in declared:
        row = declared.index(subject) % len(square)
        why = (f"row {row + 1} of {len(square)} of a balanced Latin square (declared subject "
               f"{declared.index(subject) + 1})")
    else:
        row = index % len(square)
        why = (f"row {row + 1} of {len(square)} of a balanced Latin square by registration order (not a declared "
               "subject)")
    return [conditions[k] for k in square[row]], why


def step_order(protocol: Protocol, conditions: list[str]) -> list[int]:
    """Indices into ``protocol.steps``: trial blocks reordered by ``conditions`` among the trial blocks' places
    (each condition's blocks in their order; the rounds — the paper's train blocks before its test blocks — kept
    by sorting on (round, condition rank)), every other step at its place."""
    steps = protocol.steps
    places = [j for j, s in enumerate(steps) if isinstance(s, Block)]
    if conditions != protocol.conditions or protocol.counterbalance != "none":
        rank = {c: i for i, c in enumerate(conditions)}
        rounds: dict[str, int] = {}
        keyed = []
        for j in places:
            label = steps[j].label
            keyed.append(((rounds.get(label, 0), rank[label]), j))
            rounds[label] = rounds.get(label, 0) + 1
        places_in_order = [j for _, j in sorted(keyed)]
    else:
        places_in_order = places
    fill = iter(places_in_order)
    return [next(fill) if isinstance(s, Block) else j for j, s in enumerate(steps)]


def _orders(protocol: Protocol) -> list[list[str]]:
    """Every order of the conditions the protocol can give a subject."""
    c = protocol.conditions
    if len(c) < 2 or protocol.counterbalance == "none":
        return [c]
    if protocol.counterbalance == "reverse":
        return [c, c[::-1]]
    if protocol.counterbalance == "rotate":
        return [c[k:] + c[:k] for k in range(len(c))]
    if protocol.counterbalance == "latin":
        return [[c[k] for k in row] for row in williams(len(c))]
    return [c] + [list(order) for _, order in protocol.orders]


def check_fits(protocol: Protocol) -> None:
    """Refuse a protocol whose fit steps or assisted blocks cannot work in some order it gives (one line)."""
    fitted_labels = {f.label for f in protocol.fits}
    for order in _orders(protocol):
        trained: set[str] = set()
        fitted: set[str] = set()
        for j in step_order(protocol, order):
            s = protocol.steps[j]
            where = f"{protocol.source}: blocks[{j}]"
            order_text = " in the order " + ", ".join(order) if len(order) > 1 else ""
            if isinstance(s, FitStep):
                if s.label not in trained:
                    raise DataError(f"{where}.fit: no train block of label {s.label!r} before it{order_text}")
                fitted.add(s.label)
            elif isinstance(s, Block):
                if s.role == "train":
                    trained.add(s.label)
                if s.assist != "none" and s.label in fitted_labels and s.label not in fitted:
                    raise DataError(f"{where}.assist: the block needs the model of {s.label!r} fitted before it"
                                    f"{order_text}; its fit step comes later")


def first_difference(a: Any, b: Any, where: str = "") -> str:
    """Where two protocols' :meth:`Protocol.content` first differ, as ``key: old → new`` (for a refusal)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in list(a) + [k for k in b if k not in a]:
            if a.get(k) != b.get(k):
                return first_difference(a.get(k), b.get(k), f"{where}.{k}" if where else str(k))
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        if len(a) != len(b):
            return f"{where}: {len(a)} → {len(b)} entries"
        for j, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return first_difference(x, y, f"{where}[{j}]")
    return f"{where}: {_short(a)} → {_short(b)}"
