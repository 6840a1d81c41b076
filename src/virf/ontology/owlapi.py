"""The Java bridge: every call into OWLAPI, HermiT and Openllet goes through here.

* :func:`load_modules` parses a scenario's Manchester-syntax modules into an
  OWLAPI ontology with its import closure (:class:`OwlModules`);
* :func:`iri_short`, :func:`literal` and :func:`annotations_of` are the one
  reader of IRIs and OWL annotations;
* :func:`make_reasoner` is the one place a reasoner is built (for the
  knowledge-base compiler, ``virf kb check`` and the reference engines);
* :class:`ReasonerSession` answers the engine questions over ``TBox + facts``
  with a fresh reasoner per question: the TBox axioms live in one working
  ontology, the facts are added for the question and removed afterwards, so no
  state leaks from one snapshot to the next (owlready2's stale ``is_a`` after
  ABox edits cannot happen here).

Nothing outside :mod:`virf.ontology` imports Java.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from virf.deadlines import DeadlineExceeded, ReasonerFailure, check_deadline, current_deadline
from virf.errors import InputError
from virf.ontology.iri import MODULE_BASE, NS, iri_short
from virf.ontology.jvm import ensure_jvm
from virf.schema import Fact, FactKind

REASONERS = ("hermit", "pellet")


def literal(value: Any) -> str:
    """An annotation value: a literal's text, or an IRI's short name."""
    if value.isLiteral():
        return str(value.asLiteral().get().getLiteral())
    return iri_short(value.asIRI().get())


def annotations_of(owl_object: Any) -> dict[str, str]:
    """The annotations on an axiom or an ontology, property -> value (the last
    one read wins where a property is repeated)."""
    return {
        iri_short(a.getProperty().getIRI()): literal(a.getValue())
        for a in owl_object.getAnnotations()
    }


def make_reasoner(kind: str, ontology: Any, timeout_s: float | None = None) -> Any:
    """A reasoner over ``ontology``.  HermiT answers "inconsistent" instead
    of throwing, and stops a task after ``timeout_s`` when given."""
    if kind == "hermit":
        from org.semanticweb.HermiT import Configuration, Reasoner

        config = Configuration()
        config.throwInconsistentOntologyException = False
        if timeout_s is not None:
            config.individualTaskTimeout = int(timeout_s * 1000)
        return Reasoner(config, ontology)
    if kind == "pellet":
        from openllet.owlapi import OpenlletReasonerFactory

        return OpenlletReasonerFactory.getInstance().createNonBufferingReasoner(ontology)
    raise ValueError(f"no reasoner '{kind}'; choose from {', '.join(REASONERS)}")


class OntologyLoadError(InputError):
    """An ontology module does not parse."""


class OwlModules:
    """A scenario's modules as OWLAPI loaded them: the root ontology and its
    import closure, plus any further modules imported into it."""

    def __init__(
        self, scenario: str, module_dir: Path, extra_modules: tuple[str, ...] = ()
    ) -> None:
        ensure_jvm()
        from java.io import File
        from org.semanticweb.owlapi.apibinding import OWLManager
        from org.semanticweb.owlapi.model import IRI, AddImport
        from org.semanticweb.owlapi.util import SimpleIRIMapper

        self.scenario = scenario
        self.manager = OWLManager.createOWLOntologyManager()
        for path in sorted(module_dir.glob("*.omn")):
            self.manager.getIRIMappers().add(
                SimpleIRIMapper(IRI.create(MODULE_BASE + path.stem), IRI.create(File(str(path))))
            )
        try:
            self.root = self.manager.loadOntology(IRI.create(MODULE_BASE + f"scenario-{scenario}"))
        except Exception as exc:  # OWLAPI reports every parser it tried; keep the Manchester one
            raise OntologyLoadError(manchester_message(str(exc))) from None
        self.factory = self.manager.getOWLDataFactory()
        for extra in extra_modules:
            if not Path(extra).is_file():
                raise InputError(f"ontology module not found: {extra}")
            try:
                ont = self.manager.loadOntologyFromOntologyDocument(File(extra))
            except Exception as exc:
                raise OntologyLoadError(manchester_message(str(exc))) from None
            found = ont.getOntologyID().getOntologyIRI()
            if not found.isPresent():
                raise OntologyLoadError(f"ontology module {extra} has no 'Ontology: <IRI>' header")
            iri = found.get()
            self.manager.applyChange(
                AddImport(self.root, self.factory.getOWLImportsDeclaration(iri))
            )
        self.closure = list(self.root.getImportsClosure())
        self._renderer = _make_renderer()

    def module_name(self, ontology: Any) -> str:
        return iri_short(ontology.getOntologyID().getOntologyIRI().get())

    def render(self, obj: Any) -> str:
        """Manchester syntax on one line, with short names."""
        return re.sub(r"\s+", " ", str(self._renderer.render(obj))).strip()

    def logical_axioms(self) -> list[Any]:
        out = []
        for ont in self.closure:
            out.extend(ont.getLogicalAxioms())
        return out

    def owl_class(self, name: str) -> Any:
        return self.factory.getOWLClass(_iri(name))

    def export_rdfxml(self, path: Path, individual_ns: str | None = None) -> int:
        """The logical axioms and declarations of the closure, without
        annotations, as one RDF/XML ontology (for owlready2, which reads no
        Manchester syntax).  ``individual_ns`` moves the TBox's named
        individuals to another namespace."""
        from java.io import File
        from java.util import HashMap, HashSet
        from org.semanticweb.owlapi.apibinding import OWLManager
        from org.semanticweb.owlapi.formats import RDFXMLDocumentFormat
        from org.semanticweb.owlapi.model import IRI
        from org.semanticweb.owlapi.util import OWLObjectDuplicator

        manager = OWLManager.createOWLOntologyManager()
        df = manager.getOWLDataFactory()
        renames = HashMap()
        if individual_ns is not None:
            for ont in self.closure:
                for ind in ont.getIndividualsInSignature():
                    if ind.isNamed():
                        name = str(ind.getIRI().getShortForm())
                        renames.put(ind, IRI.create(individual_ns + name))
        copy = OWLObjectDuplicator(renames, manager)
        axioms = HashSet()
        for ont in self.closure:
            for entity in ont.getSignature():
                if not entity.isBuiltIn():
                    axioms.add(copy.duplicateObject(df.getOWLDeclarationAxiom(entity)))
            for ax in ont.getLogicalAxioms():
                axioms.add(copy.duplicateObject(ax.getAxiomWithoutAnnotations()))
        merged = manager.createOntology(IRI.create(NS.rstrip("#")))
        manager.addAxioms(merged, axioms)
        fmt = RDFXMLDocumentFormat()
        fmt.setDefaultPrefix(NS)
        manager.saveOntology(merged, fmt, IRI.create(File(str(path))))
        return int(merged.getLogicalAxiomCount())


def axiom_type(name: str) -> Any:
    from org.semanticweb.owlapi.model import AxiomType

    return getattr(AxiomType, name)


def _iri(name: str) -> Any:
    from org.semanticweb.owlapi.model import IRI

    return IRI.create(NS + name)


def _make_renderer() -> Any:
    from org.semanticweb.owlapi.manchestersyntax.renderer import (
        ManchesterOWLSyntaxOWLObjectRendererImpl,
    )
    from org.semanticweb.owlapi.util import SimpleShortFormProvider

    renderer = ManchesterOWLSyntaxOWLObjectRendererImpl()
    renderer.setShortFormProvider(SimpleShortFormProvider())
    return renderer


def manchester_message(text: str) -> str:
    """The Manchester parser's diagnosis out of OWLAPI's multi-parser report."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("Parser: org.semanticweb.owlapi.manchestersyntax"):
            for follow in lines[i + 1 : i + 12]:
                if "Encountered" in follow:
                    return "ontology does not parse: " + follow.split("    ")[0].strip()
    document = next((ln for ln in lines if "ocument" in ln and ".omn" in ln), "")
    return "ontology does not parse" + (f" ({document.strip()})" if document else "")


def fact_axiom(df: Any, fact: Fact, entity: Callable[[str, str], Any]) -> Any:
    """The OWL axiom of one fact; ``entity(kind, name)`` makes (or finds) the
    class, individual or property a name denotes (kinds "class", "ind",
    "oprop", "dprop").  A closure fact says the subject's relation reaches
    only its members (nothing, when it has none)."""
    subject = entity("ind", fact.subject)
    if fact.kind is FactKind.TYPE:
        return df.getOWLClassAssertionAxiom(entity("class", fact.object), subject)
    if fact.kind is FactKind.DATA:
        return df.getOWLDataPropertyAssertionAxiom(
            entity("dprop", fact.predicate),
            subject,
            df.getOWLLiteral(fact.object == "true"),
        )
    prop = entity("oprop", fact.predicate)
    if fact.kind is FactKind.CLOSURE:
        members = fact.members
        if members:
            from java.util import HashSet

            inds = HashSet()
            for m in members:
                inds.add(entity("ind", m))
            filler = df.getOWLObjectOneOf(inds)
        else:
            filler = df.getOWLNothing()
        return df.getOWLClassAssertionAxiom(df.getOWLObjectAllValuesFrom(prop, filler), subject)
    return df.getOWLObjectPropertyAssertionAxiom(prop, subject, entity("ind", fact.object))


class ReasonerSession:
    """A complete reasoner (HermiT or Openllet) answering questions about
    ``TBox + facts``, one fresh reasoner per question."""

    def __init__(self, owl: OwlModules, kind: str, timeout_s: float) -> None:
        from org.semanticweb.owlapi.apibinding import OWLManager
        from org.semanticweb.owlapi.model import IRI

        self.kind = kind
        self.timeout_s = timeout_s
        self._IRI = IRI
        self._lock = threading.Lock()
        self.manager = OWLManager.createOWLOntologyManager()
        self.df = self.manager.getOWLDataFactory()
        self.ontology = self.manager.createOntology(IRI.create("http://virf.dev/ontology/working"))
        self._by_id: dict[str, list[Any]] = {}
        from java.util import ArrayList

        batch = ArrayList()
        for ax in owl.logical_axioms():
            batch.add(ax)
            ident = annotations_of(ax).get("id")
            if ident is not None:
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
        return fact_axiom(self.df, fact, self._entity)

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
            check_deadline(f"before the {self.kind} engine started")
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
                watch.attach(make_reasoner(self.kind, self.ontology, self.timeout_s))
                return question(watch.reasoner)
            except ReasonerFailure:
                raise
            except Exception as exc:  # any Java-side failure: fail closed upstream
                timed_out = "TimeOut" in type(exc).__name__ or "TimeOut" in str(exc)
                if watch.fired.is_set() and by_deadline:
                    raise DeadlineExceeded(
                        f"the deadline passed while the {self.kind} engine was reasoning"
                    ) from exc
                if watch.fired.is_set() or timed_out:
                    raise ReasonerFailure(
                        f"{self.kind} timed out after {self.timeout_s:g}s"
                    ) from exc
                raise ReasonerFailure(f"{self.kind} failed: {type(exc).__name__}: {exc}") from exc
            finally:
                watchdog.cancel()
                watch.detach()
                self.manager.removeAxioms(self.ontology, added)
                self.manager.addAxioms(self.ontology, removed)

    # ------------------------------------------------------------------ questions
    def classify(
        self, facts: list[Fact], concepts: list[str]
    ) -> tuple[bool, dict[str, tuple[str, ...]]]:
        """Consistency, then the ABox instances of each concept."""
        abox = {f.subject for f in facts} | {f.object for f in facts if f.kind is FactKind.OBJECT}

        def ask(reasoner: Any) -> tuple[bool, dict[str, tuple[str, ...]]]:
            if not reasoner.isConsistent():
                return False, {}
            found: dict[str, tuple[str, ...]] = {}
            for concept in concepts:
                # Also here, in case a reasoner ignores the interruption.
                check_deadline(f"while the {self.kind} engine classified the facts")
                nodes = reasoner.getInstances(self._entity("class", concept), False).getFlattened()
                names = sorted(
                    n for n in (str(i.getIRI().getShortForm()) for i in nodes) if n in abox
                )
                if names:
                    found[concept] = tuple(names)
            return True, found

        result: tuple[bool, dict[str, tuple[str, ...]]] = self._with(facts, frozenset(), ask)
        return result

    def entails(
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

    def consistent(self, facts: list[Fact], without: frozenset[str]) -> bool:
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
