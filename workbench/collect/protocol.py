"""The experiment as a file: a TOML protocol read with :mod:`tomllib`, checked, and laid out per subject.

A protocol says what a subject sees, in order: the consent text, the subject's metadata fields, an optional
practice (its duration, recorded or not), then blocks of trials (a strategy label, its instructions, the number of
trials, their role train/test or ``held_out`` of them drawn at random as test), breaks between blocks and every
``every_trials`` trials, and how the order of the conditions (the labels, in order of first appearance; a label's
blocks stay in their order) is counterbalanced across subjects::

    title = "Quadrotor landing"
    consent = "You will land a simulated quadrotor …"
    time_limit_s = 30.0

    [[fields]]                      # subject metadata asked once, after consent
    name = "age"
    label = "Age (years)"
    type = "number"                 # text | number | choice (with choices = [...])
    required = false

    [practice]
    duration_s = 600                # 0: none
    recorded = false                # true: kept in DIR/_practice/, outside the dataset

    [breaks]
    between_blocks_s = 60
    every_trials = 0                # also a break after every N trials of a block (0: none)
    duration_s = 60                 # the length of those

    counterbalance = "none"         # none | reverse (every other subject) | rotate (a Latin square's rows)

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

Assisted blocks need a fitted model of their label (``workbench collect --model CS1=cs1.npz``). ``show`` draws the
model's mean predicted path from the trial's start; ``blend`` gives the plant ``u = (1 − α) u_pilot + α
clip(K̂ (x − x_target))``, the pilot's calibrated input blended with the model's task-objective input (its IOC
part, bounded by the sticks' range), and the recording keeps ``u_pilot`` apart (:mod:`.task`, ``blend``).

Shipped: ``paper_single_subject`` and ``paper_multi_subject`` (:data:`SHIPPED`); ``--protocol`` takes one of
their names or a path. Every mistake is a :class:`~workbench.errors.DataError` of one line naming the file, the key
and the cause.
"""

from __future__ import annotations

import os
import tomllib
import zlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.data.pilot_task import REFERENCES
from workbench.errors import DataError

__all__ = ["Field", "Block", "Protocol", "Item", "load_protocol", "SHIPPED", "plan"]

PROTOCOL_DIR = Path(__file__).with_name("protocols")
SHIPPED = ("paper_single_subject", "paper_multi_subject")
COUNTERBALANCE = ("none", "reverse", "rotate")
ROLES = ("train", "test")
ASSISTS = ("none", "show", "blend")
FIELD_TYPES = ("text", "number", "choice")
MAX_TRIALS = 1000
#: A protocol file larger than this is not a protocol (and is not read whole into memory).
MAX_BYTES = 1 << 20


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
    #: The reference the instruction asks the pilot to follow (:data:`workbench.data.pilot_task.REFERENCES`), written
    #: into each trial's ``meta["reference"]``; a fit of the trials then regulates the deviation from it. None: the
    #: goal (the pad), as the paper's fits.
    reference: str | None = None


@dataclass(frozen=True)
class Protocol:
    """A checked protocol (see the module docstring); ``source`` is where it was read from."""

    name: str
    title: str
    consent: str
    fields: tuple[Field, ...]
    blocks: tuple[Block, ...]
    practice_s: float = 0.0
    practice_recorded: bool = False
    between_blocks_s: float = 0.0
    every_trials: int = 0
    break_s: float = 0.0
    counterbalance: str = "none"
    time_limit_s: float = 30.0
    source: str = ""

    @property
    def conditions(self) -> list[str]:
        """The labels in the file's order of first appearance: what counterbalancing reorders."""
        return list(dict.fromkeys(b.label for b in self.blocks))

    def shortened(self, max_trials: int | None = None, max_pause_s: float | None = None) -> Protocol:
        """The same protocol with at most ``max_trials`` per block and breaks and practice cut to ``max_pause_s``
        (for a scripted run, a demonstration or a test; a real session runs the file as written)."""
        blocks = self.blocks
        if max_trials is not None:
            blocks = tuple(replace(b, trials=min(b.trials, max_trials), held_out=min(b.held_out, max_trials - 1))
                           for b in blocks)
        out = replace(self, blocks=blocks)
        if max_pause_s is not None:
            cut = float(max_pause_s)
            out = replace(out, practice_s=min(self.practice_s, cut), between_blocks_s=min(self.between_blocks_s, cut),
                          break_s=min(self.break_s, cut))
        return out

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name, "title": self.title, "consent": self.consent,
            "fields": [f.__dict__ | {"choices": list(f.choices)} for f in self.fields],
            "practice": {"duration_s": self.practice_s, "recorded": self.practice_recorded},
            "time_limit_s": self.time_limit_s, "counterbalance": self.counterbalance,
        }


def _where(source: str, key: str) -> str:
    return f"{source}: {key}"


def _get(table: dict, key: str, kind: type | tuple, source: str, where: str, default: Any = ...) -> Any:
    if key not in table:
        if default is ...:
            raise DataError(f"{_where(source, where + key)}: missing")
        return default
    value = table[key]
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if isinstance(value, bool) and bool not in kinds:
        raise DataError(f"{_where(source, where + key)}: expected {_kind_name(kinds)}, got {value!r}")
    if not isinstance(value, kinds):
        raise DataError(f"{_where(source, where + key)}: expected {_kind_name(kinds)}, got {type(value).__name__} "
                        f"{value!r}")
    return value


def _kind_name(kinds: tuple) -> str:
    names = {str: "text", int: "an integer", float: "a number", bool: "true or false", dict: "a table",
             list: "a list"}
    return " or ".join(dict.fromkeys(names.get(k, k.__name__) for k in kinds))


def _seconds(table: dict, key: str, source: str, where: str) -> float:
    value = float(_get(table, key, (int, float), source, where, 0))
    if not (np.isfinite(value) and 0 <= value <= 24 * 3600):
        raise DataError(f"{_where(source, where + key)}: must be between 0 and 86400 seconds, got {value!r}")
    return value


def _unknown(table: dict, known: set[str], source: str, where: str) -> None:
    extra = sorted(set(table) - known)
    if extra:
        raise DataError(f"{_where(source, where + extra[0])}: unknown key (known: {', '.join(sorted(known))})")


def parse_protocol(doc: dict, source: str, name: str) -> Protocol:
    """A :class:`Protocol` from a parsed TOML document; every mistake is one :class:`DataError` line."""
    _unknown(doc, {"title", "consent", "fields", "practice", "breaks", "counterbalance", "blocks", "time_limit_s"},
             source, "")
    title = _get(doc, "title", str, source, "", name)
    consent = _get(doc, "consent", str, source, "")
    if not consent.strip():
        raise DataError(f"{source}: consent: empty; a subject must be told what the experiment is")
    fields = []
    for j, f in enumerate(_get(doc, "fields", list, source, "", [])):
        where = f"fields[{j}]."
        if not isinstance(f, dict):
            raise DataError(f"{source}: fields[{j}]: expected a table ([[fields]])")
        _unknown(f, {"name", "label", "type", "required", "choices"}, source, where)
        fname = _get(f, "name", str, source, where)
        if not fname.isidentifier() or fname in ("subject", "id"):
            raise DataError(f"{source}: {where}name: {fname!r} is not a plain identifier other than subject and id")
        ftype = _get(f, "type", str, source, where, "text")
        if ftype not in FIELD_TYPES:
            raise DataError(f"{source}: {where}type: {ftype!r} is not one of {', '.join(FIELD_TYPES)}")
        choices = tuple(str(c) for c in _get(f, "choices", list, source, where, []))
        if (ftype == "choice") != bool(choices):
            raise DataError(f"{source}: {where}choices: a choice field needs choices, other fields take none")
        fields.append(Field(fname, _get(f, "label", str, source, where, fname), ftype,
                            _get(f, "required", bool, source, where, False), choices))
    if len({f.name for f in fields}) != len(fields):
        raise DataError(f"{source}: fields: two fields have the same name")
    practice = _get(doc, "practice", dict, source, "", {})
    _unknown(practice, {"duration_s", "recorded"}, source, "practice.")
    breaks = _get(doc, "breaks", dict, source, "", {})
    _unknown(breaks, {"between_blocks_s", "every_trials", "duration_s"}, source, "breaks.")
    every = _get(breaks, "every_trials", int, source, "breaks.", 0)
    if every < 0:
        raise DataError(f"{source}: breaks.every_trials: must be 0 (none) or more, got {every}")
    counter = _get(doc, "counterbalance", str, source, "", "none")
    if counter not in COUNTERBALANCE:
        raise DataError(f"{source}: counterbalance: {counter!r} is not one of {', '.join(COUNTERBALANCE)}")
    limit = float(_get(doc, "time_limit_s", (int, float), source, "", 30.0))
    if not (np.isfinite(limit) and 1.0 <= limit <= 600.0):
        raise DataError(f"{source}: time_limit_s: must be between 1 and 600 seconds, got {limit!r}")
    raw_blocks = _get(doc, "blocks", list, source, "")
    if not raw_blocks:
        raise DataError(f"{source}: blocks: none; a protocol needs at least one [[blocks]] of trials")
    blocks = []
    for j, b in enumerate(raw_blocks):
        where = f"blocks[{j}]."
        if not isinstance(b, dict):
            raise DataError(f"{source}: blocks[{j}]: expected a table ([[blocks]])")
        _unknown(b, {"label", "instructions", "trials", "role", "held_out", "assist", "blend", "reference"}, source,
                 where)
        label = _get(b, "label", str, source, where)
        if not label or not all(c.isalnum() or c in "_-" for c in label):
            raise DataError(f"{source}: {where}label: {label!r} must be letters, digits, '_' or '-'")
        trials = _get(b, "trials", int, source, where)
        if not 1 <= trials <= MAX_TRIALS:
            raise DataError(f"{source}: {where}trials: must be between 1 and {MAX_TRIALS}, got {trials}")
        role = _get(b, "role", str, source, where, "train")
        if role not in ROLES:
            raise DataError(f"{source}: {where}role: {role!r} is not one of {', '.join(ROLES)}")
        held = _get(b, "held_out", int, source, where, 0)
        if not 0 <= held < trials or (held and role != "train"):
            raise DataError(f"{source}: {where}held_out: must be 0 or fewer than the block's {trials} trials, and "
                            f"only in a train block (got {held} in a {role} block)")
        assist = _get(b, "assist", str, source, where, "none")
        if assist not in ASSISTS:
            raise DataError(f"{source}: {where}assist: {assist!r} is not one of {', '.join(ASSISTS)}")
        alpha = float(_get(b, "blend", (int, float), source, where, 0.3 if assist == "blend" else 0.0))
        if assist == "blend" and not 0 < alpha <= 1 or assist != "blend" and "blend" in b:
            raise DataError(f"{source}: {where}blend: the model's share must be in (0, 1], and only with "
                            f"assist = \"blend\" (got {alpha!r} with assist = {assist!r})")
        reference = _get(b, "reference", str, source, where, None)
        if reference is not None and reference not in REFERENCES:
            raise DataError(f"{source}: {where}reference: {reference!r} is not one of {', '.join(REFERENCES)}")
        blocks.append(Block(label, _get(b, "instructions", str, source, where), trials, role, held, assist, alpha,
                            reference))
    return Protocol(
        name=name, title=title, consent=consent, fields=tuple(fields), blocks=tuple(blocks),
        practice_s=_seconds(practice, "duration_s", source, "practice."),
        practice_recorded=_get(practice, "recorded", bool, source, "practice.", False),
        between_blocks_s=_seconds(breaks, "between_blocks_s", source, "breaks."), every_trials=every,
        break_s=_seconds(breaks, "duration_s", source, "breaks."), counterbalance=counter, time_limit_s=limit,
        source=source,
    )


def load_protocol(spec: str | os.PathLike) -> Protocol:
    """A shipped protocol by name (:data:`SHIPPED`) or a TOML file by path."""
    text = str(spec)
    path = PROTOCOL_DIR / f"{text}.toml" if text in SHIPPED else Path(spec)
    if not path.is_file():
        raise DataError(f"{text}: no such protocol file (shipped protocols: {', '.join(SHIPPED)})")
    if path.stat().st_size > MAX_BYTES:
        raise DataError(f"{path}: {path.stat().st_size} bytes: too large for a protocol (at most {MAX_BYTES})")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:  # tomllib recurses into nested arrays and inline tables
        raise DataError(f"{path}: not a protocol (values nested too deeply)") from None
    return parse_protocol(doc, str(path), path.stem)


@dataclass(frozen=True)
class Item:
    """One step of a subject's session: ``kind`` is practice, break, instructions or trial.

    A trial item has its ``slot`` (the trial's place in the session, 0-based and stable across resumes), the
    block's label, its role, and ``trial`` (its number within the block, from 1).
    """

    key: str
    kind: str
    duration_s: float = 0.0
    block: int = -1
    label: str = ""
    role: str = ""
    instructions: str = ""
    slot: int = -1
    trial: int = 0
    n_trials: int = 0
    assist: str = "none"
    blend: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def block_order(protocol: Protocol, subject_index: int) -> list[int]:
    """The order of the protocol's blocks for the ``subject_index``-th subject: conditions counterbalanced, each
    condition's blocks kept together in the file's order."""
    conditions = protocol.conditions
    if protocol.counterbalance == "reverse" and subject_index % 2 == 1:
        conditions = conditions[::-1]
    elif protocol.counterbalance == "rotate":
        shift = subject_index % len(conditions)
        conditions = conditions[shift:] + conditions[:shift]
    if protocol.counterbalance == "none":
        return list(range(len(protocol.blocks)))
    rank = {c: i for i, c in enumerate(conditions)}
    # stable: blocks keep their order within a condition and the interleaving between conditions' rounds
    # (the paper's train blocks before its test blocks) is kept by sorting on (round, condition rank)
    rounds: dict[str, int] = {}
    keyed = []
    for j, b in enumerate(protocol.blocks):
        r = rounds.get(b.label, 0)
        rounds[b.label] = r + 1
        keyed.append(((r, rank[b.label]), j))
    return [j for _, j in sorted(keyed)]


def plan(protocol: Protocol, subject: str, subject_index: int) -> list[Item]:
    """Every step of one subject's session, in order; the same for the same subject and index (so a resumed
    session continues the same plan)."""
    items: list[Item] = []
    if protocol.practice_s > 0:
        items.append(Item("practice", "practice", protocol.practice_s))
        if protocol.between_blocks_s > 0:
            items.append(Item("break-practice", "break", protocol.between_blocks_s))
    slot = 0
    order = block_order(protocol, subject_index)
    for n, j in enumerate(order):
        b = protocol.blocks[j]
        if n > 0 and protocol.between_blocks_s > 0:
            items.append(Item(f"break-block{n}", "break", protocol.between_blocks_s))
        items.append(Item(f"instructions{n}", "instructions", block=j, label=b.label, role=b.role,
                          instructions=b.instructions, n_trials=b.trials))
        test = set()
        if b.held_out:
            rng = np.random.default_rng([zlib.crc32(f"{subject}/held_out/{j}".encode())])
            test = set(rng.choice(b.trials, size=b.held_out, replace=False).tolist())
        for t in range(b.trials):
            if t > 0 and protocol.every_trials and t % protocol.every_trials == 0 and protocol.break_s > 0:
                items.append(Item(f"break-block{n}-{t}", "break", protocol.break_s))
            role = "test" if t in test else b.role
            items.append(Item(f"trial{slot}", "trial", block=j, label=b.label, role=role,
                              instructions=b.instructions, slot=slot, trial=t + 1, n_trials=b.trials,
                              assist=b.assist, blend=b.blend))
            slot += 1
    items.append(Item("end", "end"))
    return items
