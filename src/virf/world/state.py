"""World states and what the simulator says about one step.

A :class:`WorldState` is immutable: the simulator builds a new one per step,
so every state of a run stays available to the reasoner and the report.
"""

from __future__ import annotations

import operator
import re
from bisect import bisect_left
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from itertools import compress, count, islice
from operator import attrgetter
from types import MappingProxyType

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

    # States are immutable, so the relation indexes are built once, on first
    # use; scanning every fact per lookup made big scenes quadratic.
    @cached_property
    def _forward(self) -> dict[tuple[str, str], list[str]]:
        index: dict[tuple[str, str], list[str]] = {}
        for f in self.facts:
            if f.kind is FactKind.OBJECT:
                index.setdefault((f.subject, f.predicate), []).append(f.object)
        return index

    @cached_property
    def _backward(self) -> dict[tuple[str, str], list[str]]:
        index: dict[tuple[str, str], list[str]] = {}
        for f in self.facts:
            if f.kind is FactKind.OBJECT:
                index.setdefault((f.predicate, f.object), []).append(f.subject)
        return index

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
    report each ask it of a step, and each time it is a pass over every fact."""
    kept = after.__dict__.get("_changed")
    if kept is not None and kept[0] is before:
        known: frozenset[Fact] = kept[1]
        return known
    # Sets built from the facts' dicts reuse their hashes (see facts_copy).
    out = frozenset(set(facts_copy(before.facts)) ^ set(facts_copy(after.facts)))
    after.__dict__["_changed"] = (before, out)
    return out


def carry_indexes(before: WorldState, after: WorldState) -> None:
    """Give ``after`` the relation indexes ``before`` has built, updated for
    the facts that differ, instead of a scan of all its facts on first use
    (``after`` is ``before`` one step later: a few facts differ)."""
    built = [name for name in ("_forward", "_backward") if name in before.__dict__]
    if not built:
        return
    new = after.facts
    changes = [f for f in Fact.sorted(changed(before, after)) if f.kind is FactKind.OBJECT]
    for name in built:
        index: dict[tuple[str, str], list[str]] = dict(before.__dict__[name])
        copied: set[tuple[str, str]] = set()
        for f in changes:
            key, value = (
                ((f.subject, f.predicate), f.object)
                if name == "_forward"
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
        # What cached_property would have stored on first use.
        after.__dict__[name] = index


def facts_copy(facts: Mapping[Fact, Provenance]) -> dict[Fact, Provenance]:
    """A mutable copy of a state's facts.  A dict (or a read-only view of
    one) is copied with the hashes it keeps; rebuilding it key by key would
    call ``Fact.__hash__``, a Python method, for every fact of every step."""
    if isinstance(facts, dict | MappingProxyType):
        return facts.copy()
    return dict(facts)


def sorted_facts(facts: dict[Fact, Provenance]) -> dict[Fact, Provenance]:
    """``dict(sorted(facts.items()))``, the order a state keeps its facts in,
    compared by the facts' kept sort keys alone (no Python ``__lt__``), and
    ``facts`` itself when it is in that order already (a step that only
    removed or replaced facts)."""
    keys = list(map(_ORDER, facts))
    # A step's facts are the sorted facts before it, less what it removed,
    # then what it added: find where the sorted run ends, and merge the
    # rest into it (sorting every fact of a thousand objects' scene, as
    # (key, fact, provenance) triples, at every step, cost twice this).
    end = next(compress(count(1), map(operator.ge, keys, keys[1:])), len(keys))
    if end == len(keys):
        return facts
    run = keys[:end]
    added = list(islice(facts, end, None))
    # The run is copied in slices from one pass over the items: a dict fed
    # from its own items reuses their pairs, where a list of them was built
    # pair by pair.  Distinct facts have distinct keys, so the facts
    # themselves are never compared.
    pairs = iter(facts.items())
    out: dict[Fact, Provenance] = {}
    start = 0
    for i in sorted(range(end, len(keys)), key=keys.__getitem__):
        at = bisect_left(run, keys[i], start)
        out.update(islice(pairs, at - start))
        f = added[i - end]
        out[f] = facts[f]
        start = at
    out.update(islice(pairs, end - start))
    return out


_ORDER = attrgetter("_order")


def diff(before: WorldState, after: WorldState) -> tuple[tuple[str, ...], tuple[str, ...]]:
    both = Fact.sorted(changed(before, after))
    added = tuple(f.render() for f in both if f in after.facts)
    removed = tuple(f.render() for f in both if f not in after.facts)
    return added, removed
