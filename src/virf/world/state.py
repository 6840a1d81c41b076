"""World states and what the simulator says about one step.

A :class:`WorldState` is immutable: the simulator builds a new one per step,
so every state of a run stays available to the reasoner and the report.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Any

from virf.names import term_key
from virf.schema import Fact, FactKind, Provenance
from virf.world.plan import PlanStep

# An instance's number at the end of its name: HairDryer_1, Mug2, Stove-Knob 3.
_NUMBER = re.compile(r"[\s_-]*\d+$")


@dataclass(frozen=True)
class WorldState:
    objects: Mapping[str, frozenset[str]]
    order: tuple[str, ...]
    facts: Mapping[Fact, Provenance]
    agent: str
    closed_world: frozenset[str]
    unknown_contents: frozenset[str] = frozenset()
    found: tuple[str, ...] = ()  # objects found so far, most recent last
    # The user's answers to ambiguity questions: term_key(word) -> instance.
    referents: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    # Open-world objects and the class names the scene wrote for them
    # (Board_1 -> 'IroningBoard'): a plan may name one by that word.
    open_world: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def last_found(self) -> str | None:
        return self.found[-1] if self.found else None

    def has(self, subject: str, predicate: str, obj: str) -> bool:
        return Fact(subject, predicate, obj) in self.facts

    # States are immutable, so each index is made once, on first use;
    # scanning every fact per lookup made big scenes quadratic.  A state the
    # simulator made from another (see :func:`remember_change`) has it from
    # that state's, updated for the few facts the step changed.
    @property
    def _forward(self) -> dict[tuple[str, str], list[str]]:
        return self._index("_forward")  # type: ignore[no-any-return]

    @property
    def _backward(self) -> dict[tuple[str, str], list[str]]:
        return self._index("_backward")  # type: ignore[no-any-return]

    @property
    def _mentions(self) -> dict[str, dict[Fact, None]]:
        """Every fact under the names it has as subject or object (a closure
        under its subject): what a step's effects look for, without a pass
        over every fact.  Sets as dicts: ordered, and a fact leaves one by
        its kept hash rather than by comparisons with the others."""
        return self._index("_mentions")  # type: ignore[no-any-return]

    def _index(self, name: str) -> Any:
        kept = self.__dict__.get(name)
        if kept is not None:
            return kept
        # Up to the nearest state that has it (or the first), then down again.
        chain: list[WorldState] = []
        state = self
        while name not in state.__dict__ and "_parent" in state.__dict__:
            chain.append(state)
            state = state.__dict__["_parent"][0]
        build, carry = _INDEXES[name]
        index = state.__dict__.get(name)
        if index is None:
            index = state.__dict__[name] = build(state.facts)
        for later in reversed(chain):
            changes = later.__dict__["_parent"][1]
            index = later.__dict__[name] = carry(index, changes, later.facts)
        return index

    def mentioning(self, name: str) -> Collection[Fact]:
        """The facts with ``name`` as subject or object."""
        return self._mentions.get(name, {}).keys()

    @cached_property
    def _by_lower(self) -> dict[str, str]:
        index: dict[str, str] = {}
        for ind in self.order + tuple(sorted(set(self.objects) - set(self.order))):
            index.setdefault(ind.lower(), ind)
        return index

    @cached_property
    def _by_key(self) -> dict[str, list[str]]:
        index: dict[str, list[str]] = {}
        for ind in self.order + tuple(sorted(set(self.objects) - set(self.order))):
            index.setdefault(term_key(ind), []).append(ind)
        return index

    @cached_property
    def _by_stem(self) -> dict[str, list[str]]:
        index: dict[str, list[str]] = {}
        for ind in self.order + tuple(sorted(set(self.objects) - set(self.order))):
            stem = _NUMBER.sub("", ind)
            if stem and stem != ind:
                index.setdefault(term_key(stem), []).append(ind)
            word = self.open_world.get(ind)
            if word is not None and ind not in index.get(term_key(word), ()):
                index.setdefault(term_key(word), []).append(ind)
        return index

    def named_stem(self, term: str) -> list[str]:
        """The numbered individuals whose name without its number ``term``
        spells: 'hair dryer' names HairDryer_1 and HairDryer_2, whatever
        their classes (an object the knowledge base has no class for); and
        the open-world objects of the class the scene wrote ('ironing board'
        names Board_1, an 'IroningBoard')."""
        return list(self._by_stem.get(term_key(term), ()))

    def named(self, term: str) -> list[str]:
        """The individuals ``term`` spells: itself, else the first that differs
        only in case, else all that differ only in case and separators."""
        if term in self.objects:
            return [term]
        same_case = self._by_lower.get(term.lower())
        if same_case is not None:
            return [same_case]
        return list(self._by_key.get(term_key(term), ()))

    def objects_of(self, subject: str, predicate: str) -> list[str]:
        return sorted(self._forward.get((subject, predicate), ()))

    def subjects_of(self, predicate: str, obj: str) -> list[str]:
        return sorted(self._backward.get((predicate, obj), ()))

    def held(self) -> str | None:
        held = self.objects_of(self.agent, "isHolding")
        return held[0] if held else None


@dataclass(frozen=True)
class ResolvedStep:
    step: PlanStep
    target: str | None = None  # the object acted on / receptacle / pour destination
    patient: str | None = None  # the object moved or transformed besides the target
    liquid: str | None = None  # liquid individual created by fillLiquid
    instrument: str | None = None  # held tool used
    # The object the line says is in the hand ('throw AlarmClock'): the step
    # cannot run unless it is the one held.
    named_held: str | None = None


@dataclass(frozen=True)
class MissingObject:
    """The plan names something the simulator cannot act on: absent from the
    scene, ambiguous between several instances, or a person or agent."""

    step: PlanStep
    term: str
    near: tuple[str, ...]
    ambiguous: bool = False
    agent: bool = False


@dataclass(frozen=True)
class PreconditionFailure:
    step: PlanStep
    precondition: str  # a PreconditionViolation class in the ontology
    subject: str
    message: str
    facts: tuple[Fact, ...] = field(default_factory=tuple)


def changed(before: WorldState, after: WorldState) -> frozenset[Fact]:
    """The facts in one of the two states and not the other.  Remembered on
    ``after`` for ``before``: the relation indexes, the closures and the
    report each ask it of a step.  A state the simulator made knows it from
    the step (see :func:`remember_change`); otherwise it is a pass over
    every fact."""
    kept = after.__dict__.get("_changed")
    if kept is not None and kept[0] is before:
        known: frozenset[Fact] = kept[1]
        return known
    # Sets built from the facts' dicts reuse their hashes (see facts_copy).
    out = frozenset(set(facts_copy(before.facts)) ^ set(facts_copy(after.facts)))
    # Only remembered as the answer: ``before`` need not be the state
    # ``after`` was made from (see :func:`remember_change`).
    after.__dict__["_changed"] = (before, out)
    return out


def remember_change(before: WorldState, after: WorldState, facts: frozenset[Fact]) -> None:
    """Let :func:`changed` answer ``facts`` for ``before`` and ``after``
    (what :func:`changed` would find: the step that made ``after`` knows
    it), and let ``after`` make its indexes from those of ``before``."""
    # Caches, like cached_property's: they change no field of the state.
    after.__dict__["_changed"] = (before, facts)
    after.__dict__["_parent"] = (before, Fact.sorted(facts))
    # The indexes of names read only the names, their order and the words
    # open-world objects were written with; most steps make no object.
    if (
        after.order == before.order
        and after.objects.keys() == before.objects.keys()
        and after.open_world == before.open_world
    ):
        for name in _NAME_INDEXES:
            if name in before.__dict__:
                after.__dict__[name] = before.__dict__[name]


_NAME_INDEXES = ("_by_lower", "_by_key", "_by_stem")


def _forward_index(facts: Mapping[Fact, Provenance]) -> dict[tuple[str, str], list[str]]:
    index: dict[tuple[str, str], list[str]] = {}
    for f in facts:
        if f.kind is FactKind.OBJECT:
            index.setdefault((f.subject, f.predicate), []).append(f.object)
    return index


def _backward_index(facts: Mapping[Fact, Provenance]) -> dict[tuple[str, str], list[str]]:
    index: dict[tuple[str, str], list[str]] = {}
    for f in facts:
        if f.kind is FactKind.OBJECT:
            index.setdefault((f.predicate, f.object), []).append(f.subject)
    return index


def _mentions_index(facts: Mapping[Fact, Provenance]) -> dict[str, dict[Fact, None]]:
    index: dict[str, dict[Fact, None]] = {}
    for f in facts:
        index.setdefault(f.subject, {})[f] = None
        if f.object:
            index.setdefault(f.object, {})[f] = None
    return index


def _carried_relation(
    forward: bool,
) -> Callable[
    [dict[tuple[str, str], list[str]], list[Fact], Mapping[Fact, Provenance]],
    dict[tuple[str, str], list[str]],
]:
    """How a relation index (forward: by subject and predicate; else by
    predicate and object) follows a step's changed facts."""

    def carry(
        before: dict[tuple[str, str], list[str]],
        changes: list[Fact],
        new: Mapping[Fact, Provenance],
    ) -> dict[tuple[str, str], list[str]]:
        index = dict(before)
        copied: set[tuple[str, str]] = set()
        for f in changes:
            if f.kind is not FactKind.OBJECT:
                continue
            key, value = (
                ((f.subject, f.predicate), f.object)
                if forward
                else ((f.predicate, f.object), f.subject)
            )
            if key not in copied:  # lists are shared with ``before`` until changed
                copied.add(key)
                index[key] = list(index.get(key, ()))
            if f in new:
                index[key].append(value)
            else:
                index[key].remove(value)
                if not index[key]:
                    del index[key]
                    copied.discard(key)
        return index

    return carry


def _carried_mentions(
    index: dict[str, dict[Fact, None]], changes: list[Fact], new: Mapping[Fact, Provenance]
) -> dict[str, dict[Fact, None]]:
    """``index`` (a state's :attr:`WorldState._mentions`) for the state with
    ``changes`` applied, sharing the entries of the names they leave alone."""
    out = dict(index)
    copied: set[str] = set()
    for f in changes:
        present = f in new
        for name in (f.subject, f.object) if f.object else (f.subject,):
            if name not in copied:
                copied.add(name)
                out[name] = dict(out.get(name, {}))
            if present:
                out[name][f] = None
            else:
                out[name].pop(f, None)
    for name in copied:
        if not out[name]:
            del out[name]
    return out


_INDEXES: dict[str, tuple[Callable[[Mapping[Fact, Provenance]], Any], Callable[..., Any]]] = {
    "_forward": (_forward_index, _carried_relation(True)),
    "_backward": (_backward_index, _carried_relation(False)),
    "_mentions": (_mentions_index, _carried_mentions),
}


def facts_copy(facts: Mapping[Fact, Provenance]) -> dict[Fact, Provenance]:
    """A mutable copy of a state's facts.  A dict (or a read-only view of
    one) is copied with the hashes it keeps; rebuilding it key by key would
    call ``Fact.__hash__``, a Python method, for every fact of every step."""
    if isinstance(facts, dict | MappingProxyType):
        return facts.copy()
    return dict(facts)


def diff(before: WorldState, after: WorldState) -> tuple[tuple[str, ...], tuple[str, ...]]:
    both = Fact.sorted(changed(before, after))
    added = tuple(f.render() for f in both if f in after.facts)
    removed = tuple(f.render() for f in both if f not in after.facts)
    return added, removed
