"""Reasoning engines behind one interface, with a registry.

An engine answers three questions about ``TBox + facts``: is it consistent,
which individuals are instances of which concepts, and is one class assertion
entailed (optionally with some background axioms left out).  The verifier
builds diagnoses from nothing else, so any engine that answers these exactly
gives the same reports.

Every question takes an optional ``deadline`` (a :func:`time.monotonic`
instant).  Once it passes, the engine stops where it is and raises
:class:`DeadlineExceeded`, a :class:`ReasonerFailure`, so the caller fails
closed.  The deadline is held in a context variable for the duration of the
call: an engine that asks another engine (the fast engine's fallback, a
wrapper that delegates) passes it on without having to thread it through,
and an engine's inner loops read it with :func:`check_deadline`.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Collection, Iterable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

from virf.errors import InputError, closest
from virf.ontology.tbox import TBox
from virf.schema import Fact


class ReasonerFailure(Exception):
    """The engine could not answer (crash, timeout).  Verification fails closed."""


class DeadlineExceeded(ReasonerFailure):
    """The caller's deadline passed before the engine had an answer."""


_DEADLINE: ContextVar[float | None] = ContextVar("virf_deadline", default=None)


def current_deadline() -> float | None:
    """The deadline in force for the engine call running in this context."""
    return _DEADLINE.get()


def check_deadline(where: str = "") -> None:
    """Raise :class:`DeadlineExceeded` when the deadline in force has passed.

    Cheap enough for an inner loop that calls it every few thousand
    iterations, not on every one."""
    deadline = _DEADLINE.get()
    if deadline is not None and time.monotonic() > deadline:
        raise DeadlineExceeded(f"the deadline passed{' ' + where if where else ''}")


@contextmanager
def until(deadline: float | None) -> Iterator[None]:
    """Engine calls inside the block stop at ``deadline``.  An earlier deadline
    already in force is kept: a nested call may not extend its caller's time."""
    outer = _DEADLINE.get()
    if deadline is None or (outer is not None and outer <= deadline):
        yield
        return
    token = _DEADLINE.set(deadline)
    try:
        yield
    finally:
        _DEADLINE.reset(token)


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

    def fork(self) -> Engine:
        """An independent engine of the same kind, for another thread."""
        return type(self)(self.tbox, self.timeout_s)

    def classify(
        self, facts: Iterable[Fact], concepts: Sequence[str], *, deadline: float | None = None
    ) -> Classification:
        """Consistency, then the ABox instances of each concept."""
        unknown = [c for c in concepts if c not in self.tbox.vocabulary.classes]
        if unknown:
            raise InputError(f"unknown concept '{unknown[0]}'")
        with until(deadline):
            check_deadline(f"before the {self.name} engine classified the facts")
            return self._classify(sorted(set(facts)), list(concepts))

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
            return self._entails(sorted(set(facts)), concept, individual, frozenset(without))

    def consistent(
        self, facts: Iterable[Fact], without: Collection[str] = (), *, deadline: float | None = None
    ) -> bool:
        with until(deadline):
            check_deadline(f"before the {self.name} engine checked consistency")
            return self._consistent(sorted(set(facts)), frozenset(without))

    @abstractmethod
    def _classify(self, facts: list[Fact], concepts: list[str]) -> Classification: ...

    @abstractmethod
    def _entails(
        self, facts: list[Fact], concept: str, individual: str, without: frozenset[str]
    ) -> bool: ...

    @abstractmethod
    def _consistent(self, facts: list[Fact], without: frozenset[str]) -> bool: ...


_REGISTRY: dict[str, Callable[[TBox, float], Engine]] = {}
_ALIASES = {"reference": "hermit", "openllet": "pellet"}


def register(name: str, factory: Callable[[TBox, float], Engine]) -> None:
    _REGISTRY[name] = factory


def engine_names() -> list[str]:
    _load_builtin()
    return sorted(set(_REGISTRY) | set(_ALIASES))


def make_engine(name: str, tbox: TBox, timeout_s: float = 30.0) -> Engine:
    _load_builtin()
    key = _ALIASES.get(name, name)
    if key not in _REGISTRY:
        near = closest(name, engine_names()) or engine_names()
        raise InputError(f"unknown engine '{name}'; choose from {', '.join(near)}")
    return _REGISTRY[key](tbox, timeout_s)


def _load_builtin() -> None:
    # Imported here, not at the top: they import this module.  Importing is
    # idempotent, and each registers its engines.
    from virf.reasoning import fast, owlapi  # noqa: F401
