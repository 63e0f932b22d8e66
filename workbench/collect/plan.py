"""A subject's session, step by step: the protocol laid out in the order of conditions this subject gets
(:func:`workbench.collect.protocol.condition_order`). :func:`plan` lays out every step; the same subject and index
give the same plan, so a resumed session continues where it stopped.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.collect.protocol import Block, FitStep, Message, Protocol, condition_order, step_order

__all__ = ["Item", "plan", "block_order"]


@dataclass(frozen=True)
class Item:
    """One step of a subject's session: ``kind`` is practice, break, message, instructions, trial, fit or end.

    A trial item has its ``slot`` (the trial's place in the session, 0-based and stable across resumes), the
    block's label, its role, and ``trial`` (its number within the block, from 1). ``block`` is the step's index in
    the protocol's ``[[blocks]]``; ``group`` the key of its block's instructions (what a stopping rule counts in).
    ``model`` says where an assisted trial's model comes from: ``"fit"`` (this subject's fit step) or
    ``"given"`` (``--model``).
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
    title: str = ""
    text: str = ""
    group: str = ""
    stop_landed: int = 0
    stop_identified: str = ""
    min_trials: int = 0
    model: str = ""

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def block_order(protocol: Protocol, subject_index: int, subject: str = "") -> list[int]:
    """The order of the protocol's trial blocks (indices into :attr:`Protocol.blocks`) for a subject."""
    conditions, _ = condition_order(protocol, subject, subject_index)
    trial_index = {j: k for k, j in enumerate(j for j, s in enumerate(protocol.steps) if isinstance(s, Block))}
    return [trial_index[j] for j in step_order(protocol, conditions) if j in trial_index]


def plan(protocol: Protocol, subject: str, subject_index: int) -> list[Item]:
    """Every step of one subject's session, in order; the same for the same subject and index (so a resumed
    session continues the same plan)."""
    items: list[Item] = []
    conditions, _ = condition_order(protocol, subject, subject_index)
    order = step_order(protocol, conditions)
    # the messages before the first block of trials (a briefing) come before practice
    lead = next((n for n, j in enumerate(order) if not isinstance(protocol.steps[j], Message)), len(order))
    for n, j in enumerate(order[:lead]):
        s = protocol.steps[j]
        items.append(Item(f"message{n}", "message", s.min_s, block=j, title=s.title, text=s.text))
    if protocol.practice_s > 0:
        items.append(Item("practice", "practice", protocol.practice_s))
        if protocol.between_blocks_s > 0:
            items.append(Item("break-practice", "break", protocol.between_blocks_s))
    slot = 0
    fitted: set[str] = set()
    previous: Any = None
    for n, j in enumerate(order):
        if n < lead:
            continue
        s = protocol.steps[j]
        if isinstance(previous, Block) and not isinstance(s, FitStep) and protocol.between_blocks_s > 0:
            items.append(Item(f"break-block{n}", "break", protocol.between_blocks_s))
        previous = s
        if isinstance(s, Message):
            items.append(Item(f"message{n}", "message", s.min_s, block=j, title=s.title, text=s.text))
            continue
        if isinstance(s, FitStep):
            items.append(Item(f"fit{n}", "fit", s.break_s or protocol.between_blocks_s, block=j, label=s.label,
                              role=s.source, min_trials=s.min_trials))
            fitted.add(s.label)
            continue
        group = f"instructions{n}"
        items.append(Item(group, "instructions", block=j, label=s.label, role=s.role, instructions=s.instructions,
                          n_trials=s.trials, assist=s.assist, blend=s.blend, group=group, stop_landed=s.stop_landed,
                          stop_identified=s.stop_identified, min_trials=s.stop_min_trials))
        test = set()
        if s.held_out:
            rng = np.random.default_rng([zlib.crc32(f"{subject}/held_out/{j}".encode())])
            test = set(rng.choice(s.trials, size=s.held_out, replace=False).tolist())
        model = ("fit" if s.label in fitted else "given") if s.assist != "none" else ""
        for t in range(s.trials):
            if t > 0 and protocol.every_trials and t % protocol.every_trials == 0 and protocol.break_s > 0:
                items.append(Item(f"break-block{n}-{t}", "break", protocol.break_s, group=group))
            items.append(Item(f"trial{slot}", "trial", block=j, label=s.label, role="test" if t in test else s.role,
                              instructions=s.instructions, slot=slot, trial=t + 1, n_trials=s.trials,
                              assist=s.assist, blend=s.blend, group=group, stop_landed=s.stop_landed,
                              stop_identified=s.stop_identified, min_trials=s.stop_min_trials, model=model))
            slot += 1
    items.append(Item("end", "end"))
    return items
