"""The trials a study means: selection by the role and outcome a collected trial records, and its exclusion.

``workbench collect`` writes into every trial's metadata its ``role`` (``"train"``, ``"test"``, ``"practice"``), its
``outcome`` (``"landed"``, ``"crashed"``, ``"left the domain"``, ``"time limit"``) and, where the experimenter struck
it, ``excluded: true`` with an ``exclusion_note``. A study of such a session means its training trials that landed
(a fit), or its training and test trials that landed (a held-out comparison) — not its crashes, not its test trials
in a fit, not what the experimenter struck. :func:`select_trials` makes that choice once, for every caller (the
command line's ``--role``, ``--outcome`` and ``--include-excluded``, the testbed's adaptive fit step), and says
in one line what it left out.

Defaults apply to the trials that record a role (collected ones): trials without one (imported logs, simulated
landings) keep every outcome and are never dropped for a role they do not have. Excluded trials are left out
wherever they are marked, unless ``include_excluded``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from workbench.errors import DataError

if TYPE_CHECKING:  # for the hints only: `workbench --help` builds its --role/--outcome without numpy or pandas
    from workbench.data.demonstrations import Demonstration, DemonstrationSet

__all__ = ["ALL", "ROLES", "PURPOSES", "Selection", "Selected", "select_trials", "recorded_test_ids",
           "unrecorded_split", "is_excluded", "outcome_of", "parse_choice"]

#: The word for "every value" of a role or an outcome.
ALL = "all"
#: The roles a collected trial records (``workbench.collect``'s protocol blocks).
ROLES = ("train", "test", "practice")
#: What the trials are for, and so the default roles: a fit trains on the training trials; a study holds the
#: recorded test trials out and trains on the others; looking (a view, a prediction, a replay) takes them all.
PURPOSES = {"fit": ("train",), "study": ("train", "test"), "look": None}
#: The outcome a fit or a study takes by default, on collected trials.
DEFAULT_OUTCOMES = ("landed",)


def _word(value: Any) -> str:
    """A role or outcome as compared: lower case, ``-`` and ``_`` read as spaces (``time-limit`` = ``time limit``)."""
    return " ".join(str(value).lower().replace("-", " ").replace("_", " ").split())


def parse_choice(text: str | Sequence[str] | None) -> tuple[str, ...] | None:
    """``--role`` / ``--outcome`` as given: comma-separated words, ``all`` for every value; ``None`` for the default.

    Raises
    ------
    DataError
        An empty choice.
    """
    if text is None:
        return None
    words = [_word(w) for part in ([text] if isinstance(text, str) else text) for w in str(part).split(",")]
    words = [w for w in words if w]
    if not words:
        raise DataError(f"expected one or more comma-separated values or {ALL!r}, got {text!r}")
    return (ALL,) if ALL in words else tuple(dict.fromkeys(words))


def is_excluded(demo: Demonstration) -> bool:
    """Whether the trial's metadata mark it excluded (``excluded: true``; the text ``"true"`` too)."""
    value = demo.meta.get("excluded")
    return value is True or (isinstance(value, str) and value.strip().lower() == "true")


def outcome_of(demo: Demonstration) -> str | None:
    value = demo.meta.get("outcome")
    return None if value is None else _word(value)


def _role_of(demo: Demonstration) -> str | None:
    value = demo.meta.get("role")
    return None if value is None else _word(value)


@dataclass(frozen=True)
class Selection:
    """Which trials to take, by role and outcome (``None``: the default for the purpose; ``("all",)``: every one),
    and whether excluded trials count."""

    role: tuple[str, ...] | None = None
    outcome: tuple[str, ...] | None = None
    include_excluded: bool = False

    @classmethod
    def parse(cls, role: str | Sequence[str] | None = None, outcome: str | Sequence[str] | None = None,
              include_excluded: bool = False) -> Selection:
        """From the command line's words (``"train"``, ``"landed,crashed"``, ``"all"``)."""
        return cls(parse_choice(role), parse_choice(outcome), bool(include_excluded))


@dataclass(frozen=True)
class Selected:
    """What :func:`select_trials` kept and left out, and why.

    Attributes
    ----------
    demos : DemonstrationSet
        The trials kept.
    total : int
        The trials offered.
    roles, outcomes : tuple of str, or None
        The roles and outcomes taken from trials that record them (``None``: every one).
    left_out : tuple of (str, int)
        Per reason (``"role test"``, ``"crashed"``, ``"excluded"``), the trials left out for it.
    excluded_notes : tuple of str
        ``id: note`` of every excluded trial left out (its ``exclusion_note``).
    recorded : bool
        Whether any trial records a role (a collected session): the defaults applied to those.
    """

    demos: DemonstrationSet
    total: int
    roles: tuple[str, ...] | None
    outcomes: tuple[str, ...] | None
    left_out: tuple[tuple[str, int], ...]
    excluded_notes: tuple[str, ...] = ()
    recorded: bool = False
    reasons: tuple[tuple[str, str], ...] = ()  # per trial left out: (id, reason)

    @property
    def kept(self) -> int:
        return len(self.demos)

    def why_left_out(self, demo_id: str) -> str | None:
        """The reason a trial was left out (``"excluded"``, ``"role test"``, …), or None if it was not."""
        return dict(self.reasons).get(demo_id)

    def describe(self) -> str:
        """One line: the trials used, what they were chosen by and what was left out (empty where nothing was to
        choose: no trial records a role and none was left out)."""
        if not self.recorded and not self.left_out:
            return ""
        by = []
        if self.recorded:
            by.append("every role" if self.roles is None else f"role {' or '.join(self.roles)}")
            by.append("every outcome" if self.outcomes is None else f"outcome {' or '.join(self.outcomes)}")
        notes = "; ".join(self.excluded_notes[:3]) + ("; …" if len(self.excluded_notes) > 3 else "")
        out = ", ".join(f"{n} {why}" + (f" ({notes})" if why == "excluded" and notes else "")
                        for why, n in self.left_out)
        line = f"trials used: {self.kept} of {self.total}"
        if by:
            line += f" ({', '.join(by)})"
        return line + (f"; left out {out}" if out else "; none left out")


def select_trials(
    demos: DemonstrationSet,
    selection: Selection | None = None,
    purpose: str = "fit",
    *,
    role: str | Sequence[str] | None = None,
    outcome: str | Sequence[str] | None = None,
    include_excluded: bool | None = None,
) -> Selected:
    """The trials of ``demos`` a study means.

    Parameters
    ----------
    demos : DemonstrationSet
    selection : Selection, optional
        What to take; or give ``role``, ``outcome`` and ``include_excluded`` as words (what the command line takes).
    purpose : {"fit", "study", "look"}
        The default roles of collected trials (:data:`PURPOSES`): ``fit`` their training trials, ``study`` their
        training and test trials, ``look`` every one. ``fit`` and ``study`` take their landed trials by default
        (:data:`DEFAULT_OUTCOMES`), ``look`` every outcome.

    Returns
    -------
    Selected
        The trials kept (in their order) and what was left out, with :meth:`Selected.describe` to say so.

    Raises
    ------
    DataError
        No trial is left; or a role or outcome asked for is recorded by no trial (named, with those present).
    """
    if purpose not in PURPOSES:
        raise DataError(f"purpose must be one of {list(PURPOSES)}, got {purpose!r}")
    sel = selection or Selection()
    if role is not None or outcome is not None or include_excluded is not None:
        sel = Selection(parse_choice(role) if role is not None else sel.role,
                        parse_choice(outcome) if outcome is not None else sel.outcome,
                        sel.include_excluded if include_excluded is None else bool(include_excluded))
    recorded = any(_role_of(d) is not None for d in demos)
    roles = _effective(sel.role, PURPOSES[purpose] if recorded else None)
    outcomes = _effective(sel.outcome, (DEFAULT_OUTCOMES if purpose != "look" and recorded else None))
    _check_asked(demos, "role", sel.role, roles, _role_of, ROLES)
    _check_asked(demos, "outcome", sel.outcome, outcomes, outcome_of, ())
    kept: list[Demonstration] = []
    reasons: list[tuple[str, str]] = []
    notes: list[str] = []
    for d in demos:
        why = _why_not(d, roles, outcomes, sel, explicit_outcome=sel.outcome is not None)
        if why is None:
            kept.append(d)
            continue
        reasons.append((d.id, why))
        if why == "excluded":
            note = str(d.meta.get("exclusion_note") or "").strip()
            notes.append(f"{d.id}: {note}" if note else d.id)
    # said in the order a reader asks: which roles, which outcomes, what the experimenter struck
    order = {"excluded": 2}
    left_out = tuple(sorted(Counter(why for _, why in reasons).items(),
                            key=lambda kv: order.get(kv[0], 0 if kv[0].startswith("role") else 1)))
    if not kept:
        what = ", ".join(f"{n} {why}" for why, n in left_out)
        raise DataError(f"no trial left to use: all {len(demos)} were left out ({what}); --role, --outcome and "
                        "--include-excluded choose which trials count")
    return Selected(demos.with_demos(kept), len(demos), roles, outcomes, left_out, tuple(notes), recorded,
                    tuple(reasons))


def _effective(asked: tuple[str, ...] | None, default: Iterable[str] | None) -> tuple[str, ...] | None:
    if asked is None:
        return None if default is None else tuple(default)
    return None if ALL in asked else asked


def _why_not(d: Demonstration, roles: tuple[str, ...] | None, outcomes: tuple[str, ...] | None, sel: Selection,
             explicit_outcome: bool) -> str | None:
    """Why a trial is left out (``None``: it is kept). A trial that records no role is not held to a role, and by
    default not to an outcome either (it was not collected); an outcome asked for explicitly applies to every
    trial that records one."""
    if is_excluded(d) and not sel.include_excluded:
        return "excluded"
    role = _role_of(d)
    collected = role is not None
    if roles is not None and collected and role not in roles:
        return f"role {role}"
    if roles is not None and not collected and sel.role is not None:
        return "without a role"
    outcome = outcome_of(d)
    if outcomes is not None and (collected or explicit_outcome):
        if outcome is None:
            return "without an outcome"
        if outcome not in outcomes:
            return outcome
    return None


def _check_asked(demos: DemonstrationSet, key: str, asked: tuple[str, ...] | None, effective: tuple[str, ...] | None,
                 value_of: Any, known: tuple[str, ...]) -> None:
    """A role or outcome asked for by name that no trial records is a mistake (a typo, or data without roles):
    refused naming what the trials do record."""
    if asked is None or effective is None:
        return
    present = sorted({v for d in demos if (v := value_of(d)) is not None})
    missing = [w for w in effective if w not in present]
    if len(missing) < len(effective):
        return
    if not present:
        raise DataError(f"--{key} {','.join(asked)}: no trial records a {key} (only `workbench collect` writes one); "
                        f"leave --{key} out")
    hint = f" (a {key} is one of {', '.join(known)})" if known and not set(missing) <= set(known) else ""
    raise DataError(f"--{key} {','.join(asked)}: no trial has that {key}; the trials record {', '.join(present)}"
                    f"{hint}")


def recorded_test_ids(demos: DemonstrationSet, by: str | None = None) -> list[str] | None:
    """The ids of the trials recorded as test trials (``meta["role"]``, written by ``workbench collect``), when
    every trial has a role, train or test, and every label (and every value of the metadata key ``by``, e.g.
    ``"subject"``) has both; else ``None`` (the study then draws its test trials; :func:`unrecorded_split` says
    why)."""
    return None if unrecorded_split(demos, by) else [d.id for d in demos if _role_of(d) == "test"]


def unrecorded_split(demos: DemonstrationSet, by: str | None = None) -> str:
    """Why the trials do not carry a recorded train/test split (empty when they do): no role, a role other than
    train or test, or a strategy (and ``by`` value) without a training or a test trial among them."""
    if not len(demos):
        return "no trials"
    roles = [_role_of(d) for d in demos]
    if all(r is None for r in roles):
        return "the trials record no role"
    if any(r not in ("train", "test") for r in roles):
        other = sorted({str(r) for r in roles if r not in ("train", "test")})
        return f"some trials record no role train or test ({', '.join(other)})"
    groups: dict[Any, set[str]] = {}
    for d, r in zip(demos, roles, strict=True):
        groups.setdefault((d.label, d.meta.get(by) if by else None), set()).add(str(r))
    gaps = []
    for (label, value), got in groups.items():
        if got != {"train", "test"}:
            name = " ".join(str(v) for v in (label, value) if v is not None) or "the trials"
            gaps.append(f"{name} has no {'test' if 'test' not in got else 'training'} trial")
    return "; ".join(gaps)
