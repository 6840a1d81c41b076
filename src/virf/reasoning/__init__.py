"""Reasoning engines behind one interface, with a registry.

An engine answers three questions about ``TBox + facts``: is it consistent,
which individuals are instances of which concepts, and is one class assertion
entailed (optionally with some background axioms left out).  The verifier
builds diagnoses from nothing else, so any engine that answers these exactly
gives the same reports.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass

from virf.errors import InputError, closest
from virf.kb.tbox import TBox
from virf.schema import Fact


class ReasonerFailure(Exception):
    """The engine could not answer (crash, timeout).  Verification fails closed."""


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

    def classify(self, facts: Iterable[Fact], concepts: Sequence[str]) -> Classification:
        """Consistency, then the ABox instances of each concept."""
        unknown = [c for c in concepts if c not in self.tbox.vocabulary.classes]
        if unknown:
            raise InputError(f"unknown concept '{unknown[0]}'")
        return self._classify(sorted(set(facts)), list(concepts))

    def entails(
        self, facts: Iterable[Fact], concept: str, individual: str, without: Collection[str] = ()
    ) -> bool:
        return self._entails(sorted(set(facts)), concept, individual, frozenset(without))

    def consistent(self, facts: Iterable[Fact], without: Collection[str] = ()) -> bool:
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
