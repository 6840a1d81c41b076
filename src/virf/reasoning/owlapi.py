"""Reference engines: complete OWL 2 DL reasoners (HermiT, Openllet/Pellet)
running in-process through OWLAPI 5 over JPype.

Each question gets a fresh reasoner over ``TBox + facts``: the TBox axioms
live in one working ontology, the facts are added for the question and
removed afterwards, so no state leaks from one snapshot to the next (owlready2's
stale ``is_a`` after ABox edits cannot happen here).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from virf.ontology.tbox import NS, TBox
from virf.reasoning import (
    Classification,
    DeadlineExceeded,
    Engine,
    ReasonerFailure,
    check_deadline,
    current_deadline,
    register,
)
from virf.schema import Fact, FactKind


class OwlapiEngine(Engine):
    complete = True
    name = "owlapi"

    def __init__(self, tbox: TBox, timeout_s: float = 30.0) -> None:
        super().__init__(tbox, timeout_s)
        from org.semanticweb.owlapi.apibinding import OWLManager
        from org.semanticweb.owlapi.model import IRI

        self._IRI = IRI
        self._lock = threading.Lock()
        self.manager = OWLManager.createOWLOntologyManager()
        self.df = self.manager.getOWLDataFactory()
        self.ontology = self.manager.createOntology(IRI.create("http://virf.dev/ontology/working"))
        self._by_id: dict[str, list[Any]] = {}
        from java.util import ArrayList

        batch = ArrayList()
        for ax in tbox.logical_axioms():
            batch.add(ax)
            for ann in ax.getAnnotations():
                if str(ann.getProperty().getIRI().toString()) == NS + "id":
                    ident = str(ann.getValue().asLiteral().get().getLiteral())
                    self._by_id.setdefault(ident, []).append(ax)
        self.manager.addAxioms(self.ontology, batch)
        self._cache: dict[tuple[str, str], Any] = {}

    # ------------------------------------------------------------------ java helpers
    def _entity(self, kind: str, name: str) -> Any:
        key = (kind, name)
        hit = self._cache.get(key)
        if hit is None:
            iri = self._IRI.create(NS + name)
            make: Callable[[Any], Any] = {
                "class": self.df.getOWLClass,
                "ind": self.df.getOWLNamedIndividual,
                "oprop": self.df.getOWLObjectProperty,
                "dprop": self.df.getOWLDataProperty,
            }[kind]
            hit = make(iri)
            self._cache[key] = hit
        return hit

    def _axiom(self, fact: Fact) -> Any:
        df = self.df
        subject = self._entity("ind", fact.subject)
        if fact.kind is FactKind.TYPE:
            return df.getOWLClassAssertionAxiom(self._entity("class", fact.object), subject)
        if fact.kind is FactKind.DATA:
            return df.getOWLDataPropertyAssertionAxiom(
                self._entity("dprop", fact.predicate),
                subject,
                df.getOWLLiteral(fact.object == "true"),
            )
        prop = self._entity("oprop", fact.predicate)
        if fact.kind is FactKind.CLOSURE:
            members = fact.members()
            if members:
                from java.util import HashSet

                inds = HashSet()
                for m in members:
                    inds.add(self._entity("ind", m))
                filler = df.getOWLObjectOneOf(inds)
            else:
                filler = df.getOWLNothing()
            return df.getOWLClassAssertionAxiom(df.getOWLObjectAllValuesFrom(prop, filler), subject)
        return df.getOWLObjectPropertyAssertionAxiom(
            prop, subject, self._entity("ind", fact.object)
        )

    def _with(
        self, facts: list[Fact], without: frozenset[str], question: Callable[[Any], Any]
    ) -> Any:
        """Run ``question(reasoner)`` over TBox (minus ``without``) plus ``facts``."""
        from java.util import ArrayList

        added = ArrayList()
        for f in facts:
            added.add(self._axiom(f))
        removed = ArrayList()
        for ident in sorted(without):
            for ax in self._by_id.get(ident, ()):
                removed.add(ax)
        with self._lock:
            # Waiting for the lock may have used up the caller's time.
            check_deadline(f"before the {self.name} engine started")
            self.manager.addAxioms(self.ontology, added)
            self.manager.removeAxioms(self.ontology, removed)
            # The reasoner is stopped from a watchdog thread at its own timeout
            # or at the caller's deadline, whichever comes first; the
            # interruption surfaces as ReasonerFailure (DeadlineExceeded for
            # the deadline), never as an answer.
            deadline = current_deadline()
            limit, by_deadline = self.timeout_s, False
            if deadline is not None and deadline - time.monotonic() < limit:
                limit, by_deadline = max(0.0, deadline - time.monotonic()), True
            watch = _Watchdog()
            watchdog = threading.Timer(limit, watch.fire)
            watchdog.daemon = True
            watchdog.start()
            try:
                # Started before the reasoner is built: building it (HermiT's
                # preprocessing) takes time too, and is checked right after.
                watch.attach(self._reasoner(self.ontology))
                return question(watch.reasoner)
            except ReasonerFailure:
                raise
            except Exception as exc:  # any Java-side failure: fail closed upstream
                timed_out = "TimeOut" in type(exc).__name__ or "TimeOut" in str(exc)
                if watch.fired.is_set() and by_deadline:
                    raise DeadlineExceeded(
                        f"the deadline passed while the {self.name} engine was reasoning"
                    ) from exc
                if watch.fired.is_set() or timed_out:
                    raise ReasonerFailure(
                        f"{self.name} timed out after {self.timeout_s:g}s"
                    ) from exc
                raise ReasonerFailure(f"{self.name} failed: {type(exc).__name__}: {exc}") from exc
            finally:
                watchdog.cancel()
                watch.detach()
                self.manager.removeAxioms(self.ontology, added)
                self.manager.addAxioms(self.ontology, removed)

    def _reasoner(self, ontology: Any) -> Any:
        raise NotImplementedError

    # ------------------------------------------------------------------ engine API
    def _classify(self, facts: list[Fact], concepts: list[str]) -> Classification:
        abox = {f.subject for f in facts} | {f.object for f in facts if f.kind is FactKind.OBJECT}

        def ask(reasoner: Any) -> Classification:
            if not reasoner.isConsistent():
                return Classification(False, {})
            found: dict[str, tuple[str, ...]] = {}
            for concept in concepts:
                # Also here, in case a reasoner ignores the interruption.
                check_deadline(f"while the {self.name} engine classified the facts")
                nodes = reasoner.getInstances(self._entity("class", concept), False).getFlattened()
                names = sorted(
                    n for n in (str(i.getIRI().getShortForm()) for i in nodes) if n in abox
                )
                if names:
                    found[concept] = tuple(names)
            return Classification(True, found)

        result: Classification = self._with(facts, frozenset(), ask)
        return result

    def _entails(
        self, facts: list[Fact], concept: str, individual: str, without: frozenset[str]
    ) -> bool:
        axiom = self.df.getOWLClassAssertionAxiom(
            self._entity("class", concept), self._entity("ind", individual)
        )

        def ask(reasoner: Any) -> bool:
            if not reasoner.isConsistent():
                return True  # everything follows from a contradiction
            return bool(reasoner.isEntailed(axiom))

        result: bool = self._with(facts, without, ask)
        return result

    def _consistent(self, facts: list[Fact], without: frozenset[str]) -> bool:
        result: bool = self._with(facts, without, lambda r: bool(r.isConsistent()))
        return result


class _Watchdog:
    """Interrupts the reasoner it is attached to once fired (from the timer
    thread), including a reasoner attached after the timer went off."""

    def __init__(self) -> None:
        self.fired = threading.Event()
        self.reasoner: Any = None
        self._lock = threading.Lock()

    def fire(self) -> None:
        with self._lock:
            self.fired.set()
            if self.reasoner is not None:
                self.reasoner.interrupt()

    def attach(self, reasoner: Any) -> None:
        with self._lock:
            self.reasoner = reasoner
            late = self.fired.is_set()
        if late:
            raise _Late()

    def detach(self) -> None:
        with self._lock:
            reasoner, self.reasoner = self.reasoner, None
        if reasoner is not None:
            reasoner.dispose()


class _Late(Exception):
    """The watchdog went off while the reasoner was being built."""


class HermitEngine(OwlapiEngine):
    """HermiT 1.4 (hypertableau), the default reference engine."""

    name = "hermit"

    def _reasoner(self, ontology: Any) -> Any:
        from org.semanticweb.HermiT import Configuration, Reasoner

        config = Configuration()
        config.throwInconsistentOntologyException = False
        config.individualTaskTimeout = int(self.timeout_s * 1000)
        return Reasoner(config, ontology)


class PelletEngine(OwlapiEngine):
    """Openllet 2.6 (the maintained fork of Pellet, the paper's reasoner)."""

    name = "pellet"

    def _reasoner(self, ontology: Any) -> Any:
        from openllet.owlapi import OpenlletReasonerFactory

        return OpenlletReasonerFactory.getInstance().createNonBufferingReasoner(ontology)


register("hermit", HermitEngine)
register("pellet", PelletEngine)
