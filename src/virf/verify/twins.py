"""Minimal pairs: a world where a rule holds and its twin, which differs only
in the property the rule's mechanism turns on.

Each Unsafe State Concept carries its pairs as ``:twin`` annotations, one
line each, so that a rule and its tests travel together (through the
knowledge-acquisition workflow, into the compiled artifact, into Protégé)::

    Candle_1: Candle; Shelf_1: Shelf; Drape_1: PhysicalObject;
    Drape_1 hasMaterial Fabric; Candle_1 isOn Shelf_1; Shelf_1 isNear Drape_1
    | find Candle_1; turn_on Candle_1
    | Drape_1 hasMaterial Fabric => Drape_1 hasMaterial Metal

* the **world**: statements separated by ``;``: ``NAME: Class`` declares an
  instance (several lines give several types), ``SUBJECT property OBJECT``
  asserts a fact (states and materials may be words: ``Toaster_1 hasState
  on``), ``closed: contains`` closes a relation as a scene's
  ``closed_world`` does;
* the **plan**: steps separated by ``;`` (``-`` for none, when the world
  itself is the hazard);
* the **change**: ``OLD => NEW``, one statement of the world (or one step
  of the plan, for a rule about an action) replaced by another (``-`` on
  either side adds or removes one).  The rule must hold somewhere in the
  world's run, and nowhere in the twin's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from virf.errors import InputError, clip

_DECLARATION = re.compile(r"^([A-Za-z_][\w.\-]*)\s*:\s*([A-Za-z_][\w]*)$")
_CLOSED = re.compile(r"^closed\s*:\s*(.+)$")


@dataclass(frozen=True)
class MinimalPair:
    """One ``:twin`` annotation, read."""

    rule: str
    text: str
    world: tuple[str, ...]
    plan: tuple[str, ...]
    old: str | None  # the statement the twin replaces (None: the twin adds one)
    new: str | None  # what the twin says instead (None: the twin drops ``old``)

    @property
    def twin(self) -> tuple[str, ...]:
        """The twin's world statements."""
        if self.old is None:
            return (*self.world, self.new) if self.new else self.world
        return _replaced(self.world, self.old, self.new)

    @property
    def twin_plan(self) -> tuple[str, ...]:
        """The twin's plan: the same as the world's, unless the change is a step."""
        if self.old is not None and self.old in self.plan:
            return _replaced(self.plan, self.old, self.new)
        return self.plan

    @property
    def change(self) -> str:
        return f"{self.old or '-'} => {self.new or '-'}"


def _replaced(items: tuple[str, ...], old: str, new: str | None) -> tuple[str, ...]:
    return tuple(s for s in (new if s == old else s for s in items) if s)


def _statements(text: str) -> tuple[str, ...]:
    return tuple(" ".join(s.split()) for s in text.split(";") if s.strip())


def read_pair(rule: str, text: str) -> MinimalPair:
    """A ``:twin`` annotation of ``rule``, or an InputError naming its problem."""
    parts = text.split("|")
    if len(parts) != 3:
        raise InputError(f"{rule}: a twin is 'WORLD | PLAN | OLD => NEW', not {clip(text, 80)!r}")
    world, plan, change = (p.strip() for p in parts)
    statements = _statements(world)
    if not statements:
        raise InputError(f"{rule}: a twin's world needs at least one statement")
    steps = () if plan in ("", "-") else _statements(plan)
    old_text, arrow, new_text = change.partition("=>")
    if not arrow:
        raise InputError(f"{rule}: a twin's change is 'OLD => NEW', not {clip(change, 80)!r}")
    old = " ".join(old_text.split())
    new = " ".join(new_text.split())
    old_s = None if old in ("", "-") else old
    new_s = None if new in ("", "-") else new
    if old_s is None and new_s is None:
        raise InputError(f"{rule}: a twin must change one statement")
    if old_s is not None and statements.count(old_s) + steps.count(old_s) != 1:
        raise InputError(
            f"{rule}: the twin changes '{old_s}', which its world or plan does not state once"
        )
    if old_s == new_s:
        raise InputError(f"{rule}: the twin's change '{change}' changes nothing")
    return MinimalPair(rule, text, statements, steps, old_s, new_s)


def scene_data(statements: tuple[str, ...]) -> dict[str, Any]:
    """The scene document (Appendix C form) a world's statements describe."""
    instances: list[dict[str, str]] = []
    assertions: list[dict[str, Any]] = []
    closed: list[str] = []
    for s in statements:
        closure = _CLOSED.match(s)
        if closure:
            closed += [c.strip() for c in closure[1].split(",") if c.strip()]
            continue
        declared = _DECLARATION.match(s)
        if declared:
            instances.append({"instance_name": declared[1], "class_name": declared[2]})
            continue
        words = s.split()
        if len(words) != 3:
            raise InputError(
                f"twin statement '{clip(s, 80)}' is neither 'NAME: Class', "
                "'SUBJECT property OBJECT' nor 'closed: RELATION'"
            )
        subject, prop, obj = words
        value: str | bool = {"true": True, "false": False}.get(obj.lower(), obj)
        assertions.append({"subject": subject, "property": prop, "object": value})
    return {"instances": instances, "assertions": assertions, "closed_world": closed}
