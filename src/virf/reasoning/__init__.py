"""Reasoning engines behind one interface, with a registry.

An engine answers three questions about ``TBox + facts``: is it consistent,
which individuals are instances of which concepts, and is one class assertion
entailed (optionally with some background axioms left out).  The verifier
builds diagnoses from nothing else, so any engine that answers these exactly
gives the same reports.

Every question takes an optional ``deadline``; see :mod:`virf.deadlines`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from importlib import import_module
from typing import Protocol

from virf.deadlines import (
    DeadlineExceeded,
    ReasonerFailure,
    check_deadline,
    current_deadline,
    until,
)
from virf.errors import InputError, closest
from virf.ontology.tbox import TBox
from virf.schema import Fact

__all__ = [
    "Classification",
    "DeadlineExceeded",
    "Engine",
    "Oracle",
    "Proof",
    "ReasonerFailure",
    "check_deadline",
    "current_deadline",
    "engine_names",
    "make_engine",
    "register",
    "until",
]


@dataclass(frozen=True)
class Proof:
    """The input facts and the axiom ids one derivation uses, and those of
    the question's facts and axioms that every derivation needs (without
    one, the query is not entailed; an engine may name fewer, or none)."""

    facts: frozenset[Fact]
    axioms: frozenset[str]
    needed_facts: frozenset[Fact] = frozenset()
    needed_axioms: frozenset[str] = frozenset()
    # Answers whether the query is still entailed once some of the
    # question's facts and axioms are left out (see Oracle).
    oracle: Oracle | None = field(default=None, compare=False)


class Oracle(Protocol):
    """Questions about a proof's facts and axioms with some left out: the
    items as a bit mask (None: some cannot be left out here), and whether
    the query is still entailed without a mask's items (True, False, or
    None: ask the engine)."""

    def mask(self, facts: Collection[Fact], axioms: Collection[str]) -> int | None: ...

    def decide(self, removed: int) -> bool | None: ...


@dataclass(frozen=True)
class Classification:
    consistent: bool
    instances: dict[str, tuple[str, ...]]  # concept name -> sorted ABox individuals


class Engine(ABC):
    name: str = "abstract"
    complete: bool = False

    def __init__(self, tbox: TBox, timeout_s: float = 30.0) -> None:
        self.tbox = tbox
        self.timeout_s = timeout_s

    def stats(self) -> Mapping[str, int]:
        """Counters of how the engine answered so far (``calls``, ``fallbacks``
        and one ``fallback: <why>`` per reason for an engine that can hand a
        question to another); empty for an engine that keeps none."""
        return {}

    def fork(self) -> Engine:
        """An independent engine of the same kind, for another thread."""
        return type(self)(self.tbox, self.timeout_s)

    @contextmanager
    def sharing(self, facts: Collection[Fact], *, deadline: float | None = None) -> Iterator[None]:
        """A hint: most questions asked in the block are about sets of facts
        that include ``facts`` (what no step of a plan changes).  An engine
        may prepare for them once, by ``deadline``; the answers are the same
        either way."""
        yield

    def classify(
        self, facts: Iterable[Fact], concepts: Sequence[str], *, deadline: float | None = None
    ) -> Classification:
        """Consistency, then the ABox instances of each concept."""
        unknown = [c for c in concepts if c not in self.tbox.vocabulary.classes]
        if unknown:
            raise InputError(f"unknown concept '{unknown[0]}'")
        with until(deadline):
            check_deadline(f"before the {self.name} engine classified the facts")
            return self._classify(Fact.sorted(set(facts)), list(concepts))

    def classify_shared(
        self,
        shared: frozenset[Fact],
        extra: Collection[Fact],
        concepts: Sequence[str],
        *,
        deadline: float | None = None,
    ) -> Classification:
        """:meth:`classify` of ``shared | extra``, where ``shared`` is the set
        the enclosing :meth:`sharing` block was given: an engine that
        prepared for it needs only ``extra``, what one step adds."""
        return self.classify([*shared, *extra], concepts, deadline=deadline)

    def entails(
        self,
        facts: Iterable[Fact],
        concept: str,
        individual: str,
        without: Collection[str] = (),
        *,
        deadline: float | None = None,
    ) -> bool:
        with until(deadline):
            check_deadline(f"before the {self.name} engine answered an entailment")
            return self._entails(Fact.sorted(set(facts)), concept, individual, frozenset(without))

    def entails_each(
        self,
        kept: Sequence[Fact],
        items: Sequence[Fact],
        tested: Sequence[bool],
        concept: str,
        individual: str,
        *,
        deadline: float | None = None,
    ) -> Iterator[bool]:
        """For each item ``i`` with ``tested[i]``, in order: is ``concept(individual)``
        entailed by ``kept``, the tested items before ``i`` and every item
        after it?  (The questions a deletion search asks while it keeps
        every tested item; an engine may answer them together.)  Answered
        as they are read: a search that stops early asks no more."""
        for i, test in enumerate(tested):
            if test:
                before = [f for f, t in zip(items[:i], tested[:i], strict=True) if t]
                trial = [*kept, *before, *items[i + 1 :]]
                yield self.entails(trial, concept, individual, deadline=deadline)

    def entails_each_without(
        self,
        facts: Sequence[Fact],
        dropped: Collection[str],
        items: Sequence[str],
        tested: Sequence[bool],
        concept: str,
        individual: str,
        *,
        deadline: float | None = None,
    ) -> Iterator[bool]:
        """For each axiom id ``items[i]`` with ``tested[i]``, in order: is
        ``concept(individual)`` entailed by ``facts`` without the axioms
        ``dropped``, the untested items before ``i`` and ``items[i]``?  (The
        questions a deletion search over axioms asks while it keeps every
        tested item; an engine may answer them together.)  Answered as they
        are read."""
        for i, test in enumerate(tested):
            if test:
                left = [a for a, t in zip(items[:i], tested[:i], strict=True) if not t]
                without = {*dropped, *left, items[i]}
                yield self.entails(facts, concept, individual, without=without, deadline=deadline)

    def consistent(
        self, facts: Iterable[Fact], without: Collection[str] = (), *, deadline: float | None = None
    ) -> bool:
        with until(deadline):
            check_deadline(f"before the {self.name} engine checked consistency")
            return self._consistent(Fact.sorted(set(facts)), frozenset(without))

    def proof(
        self,
        facts: Iterable[Fact],
        concept: str,
        individual: str,
        *,
        without: Collection[str] = (),
        order: Sequence[object] = (),
        deadline: float | None = None,
    ) -> Proof | None:
        """One derivation of ``concept(individual)`` from ``facts`` without the
        axioms ``without``: the facts and axiom ids it uses, or None when the
        engine keeps no derivations (or found none).  Where there are
        alternatives, it prefers facts and axioms late in ``order``, unless
        it brings an oracle that answers for them all (then any derivation
        serves: the search asks the oracle first).  A hint for explanations,
        which test it (see :func:`virf.verify.deletion.drop_greedily`),
        never a verdict."""
        return None

    @abstractmethod
    def _classify(self, facts: list[Fact], concepts: list[str]) -> Classification: ...

    @abstractmethod
    def _entails(
        self, facts: list[Fact], concept: str, individual: str, without: frozenset[str]
    ) -> bool: ...

    @abstractmethod
    def _consistent(self, facts: list[Fact], without: frozenset[str]) -> bool: ...


# The built-in engines, named by where they live: a module is imported only
# when its engine is asked for, so choosing the fast engine never loads the
# Java bridge, and the engine modules can import this one without a cycle.
BUILTIN: dict[str, str] = {
    "fast": "virf.reasoning.fast:FastEngine",
    "hermit": "virf.reasoning.reference:HermitEngine",
    "pellet": "virf.reasoning.reference:PelletEngine",
}
ALIASES = {"reference": "hermit", "openllet": "pellet"}
_REGISTRY: dict[str, Callable[[TBox, float], Engine]] = {}


def register(name: str, factory: Callable[[TBox, float], Engine]) -> None:
    """Add an engine beyond the built-in ones (a plugin, a test double)."""
    _REGISTRY[name] = factory


def engine_names() -> list[str]:
    return sorted(set(BUILTIN) | set(_REGISTRY) | set(ALIASES))


def engine_factory(name: str) -> Callable[[TBox, float], Engine]:
    key = ALIASES.get(name, name)
    if key in _REGISTRY:
        return _REGISTRY[key]
    if key not in BUILTIN:
        near = closest(name, engine_names())
        guess = f"did you mean {' or '.join(near)}? " if near else ""
        raise InputError(f"unknown engine '{name}'; {guess}choose from {', '.join(engine_names())}")
    module, _, attr = BUILTIN[key].partition(":")
    factory: Callable[[TBox, float], Engine] = getattr(import_module(module), attr)
    return factory


def make_engine(name: str, tbox: TBox, timeout_s: float = 30.0) -> Engine:
    return engine_factory(name)(tbox, timeout_s)
