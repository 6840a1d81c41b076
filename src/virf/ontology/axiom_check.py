"""Logical checks of a candidate axiom with the reference reasoner (HermiT),
before a person is asked to accept it: does the module parse, does the TBox
stay consistent, is the new concept satisfiable, and does it coincide with,
narrow or widen an Unsafe State Concept the TBox already has?

The candidate is a Manchester module importing the workspace's top layer; the
built-in modules, the workspace's modules and the candidate are loaded into
one OWLAPI manager, the candidate is imported into the scenario's root, and
one HermiT instance answers every question.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from virf.ontology.iri import NS, iri_short
from virf.ontology.owlapi import OwlModules, fact_axiom, make_reasoner, manchester_message
from virf.ontology.tbox import ontology_dir
from virf.ontology.workspace import LAYERS, WORKSPACE_BASE
from virf.schema import Fact, FactKind

# Java objects are not shared between checks, but OWLAPI's parser and HermiT
# keep static state: one check at a time.
_LOCK = threading.Lock()


@dataclass(frozen=True)
class AxiomCheck:
    parses: bool
    parse_error: str = ""
    consistent: bool | None = None
    satisfiable: bool | None = None
    every_state: bool = False  # the concept is owl:Thing: everything would be unsafe
    # Of the classes every verification has an individual of (``always``),
    # those the concept holds of: each makes every scene or plan unsafe.
    holds_of_every: tuple[str, ...] = ()
    # The knowledge base's own named individuals (states, materials,
    # properties) the concept holds of: every scene that mentions one.
    holds_of_named: tuple[str, ...] = ()
    # The individuals of the empty scene (``scene``) the concept holds of,
    # and whether that scene stays consistent with the candidate.
    empty_scene: tuple[str, ...] = ()
    empty_scene_consistent: bool = True
    equivalent: tuple[str, ...] = ()
    subsumed_by: tuple[str, ...] = ()
    subsumes: tuple[str, ...] = ()
    # term -> the layer of the module that declares it (core, domain, scenario)
    layers: dict[str, str] = field(default_factory=dict)


def module_layer(module_iri: str) -> str:
    """The layer an ontology module belongs to, from its IRI."""
    if module_iri.startswith(WORKSPACE_BASE):
        return module_iri.removeprefix(WORKSPACE_BASE).split("/")[0]
    name = module_iri.rsplit("/", 1)[-1]
    if name == "core":
        return "core"
    if name.startswith("scenario-"):
        return "scenario"
    return "domain"


def check_candidate(
    scenario: str,
    extra_modules: tuple[str, ...],
    module_text: str,
    concept: str,
    terms: Iterable[str],
    rules: Iterable[str],
    *,
    always: Iterable[str] = (),
    scene: Iterable[Fact] = (),
) -> AxiomCheck:
    """Check ``module_text`` (a whole Manchester ontology document) on top of
    the scenario and ``extra_modules`` (the workspace's layers, in order);
    ``rules`` are the Unsafe State Concepts the TBox has, which the new
    concept is compared with.

    ``always`` are classes every verification has an individual of, and
    ``scene`` the facts every verification starts from (the empty scene):
    which of them the new concept holds of is reported, as is which of the
    knowledge base's named individuals it holds of.  What those are is the
    caller's to say: the scene reader and the simulator decide them."""
    with _LOCK:
        owl = OwlModules(scenario, ontology_dir(), extra_modules)
        return _check(
            owl, module_text, concept, tuple(terms), frozenset(rules), tuple(always), tuple(scene)
        )


def parses_with(scenario: str, extra_modules: tuple[str, ...]) -> None:
    """Load the modules, or raise the parser's one-line message."""
    with _LOCK:
        OwlModules(scenario, ontology_dir(), extra_modules)


def _check(
    owl: OwlModules,
    module_text: str,
    concept: str,
    terms: tuple[str, ...],
    rules: frozenset[str],
    always: tuple[str, ...] = (),
    scene: tuple[Fact, ...] = (),
) -> AxiomCheck:
    from org.semanticweb.owlapi.io import StringDocumentSource
    from org.semanticweb.owlapi.model import AddImport

    try:
        candidate = owl.manager.loadOntologyFromOntologyDocument(StringDocumentSource(module_text))
    except Exception as exc:  # OWLAPI's parse failures come as several Java types
        return AxiomCheck(parses=False, parse_error=manchester_message(str(exc)))
    iri = candidate.getOntologyID().getOntologyIRI().get()
    owl.manager.applyChange(AddImport(owl.root, owl.factory.getOWLImportsDeclaration(iri)))
    layers = _declaring_layers(owl, candidate, terms)
    reasoner = make_reasoner("hermit", owl.root)
    try:
        if not reasoner.isConsistent():
            return AxiomCheck(parses=True, consistent=False, layers=layers)
        cls = owl.owl_class(concept)
        if not reasoner.isSatisfiable(cls):
            return AxiomCheck(parses=True, consistent=True, satisfiable=False, layers=layers)
        uscs = set(rules) - {concept}
        same = reasoner.getEquivalentClasses(cls)
        if same.isTopNode():
            return AxiomCheck(
                parses=True, consistent=True, satisfiable=True, every_state=True, layers=layers
            )
        equivalent = _names(same.getEntities()) & uscs
        supers = _names(reasoner.getSuperClasses(cls, False)) & uscs - equivalent
        subs = _names(reasoner.getSubClasses(cls, False)) & uscs - equivalent
        every = tuple(
            c
            for c in always
            if reasoner.isEntailed(owl.factory.getOWLSubClassOfAxiom(owl.owl_class(c), cls))
        )
        named = tuple(sorted(str(i.getIRI().getShortForm()) for i in _individuals(reasoner, cls)))
    finally:
        reasoner.dispose()
    found, scene_consistent = _in_scene(owl, candidate, cls, scene) if scene else ((), True)
    return AxiomCheck(
        parses=True,
        consistent=True,
        satisfiable=True,
        equivalent=tuple(sorted(equivalent)),
        subsumed_by=tuple(sorted(supers)),
        subsumes=tuple(sorted(subs)),
        layers=layers,
        holds_of_every=every,
        holds_of_named=named,
        empty_scene=found,
        empty_scene_consistent=scene_consistent,
    )


def _individuals(reasoner: Any, cls: Any) -> list[Any]:
    return [i for i in reasoner.getInstances(cls, False).getFlattened() if i.isNamed()]


def _in_scene(
    owl: OwlModules, candidate: Any, cls: Any, scene: tuple[Fact, ...]
) -> tuple[tuple[str, ...], bool]:
    """The individuals of ``scene`` the concept holds of, as the reference
    engine classifies a snapshot (the facts added to the TBox and the
    candidate), and whether the facts are consistent with them."""
    from java.util import ArrayList
    from org.semanticweb.owlapi.model import IRI

    made = {
        "class": owl.factory.getOWLClass,
        "ind": owl.factory.getOWLNamedIndividual,
        "oprop": owl.factory.getOWLObjectProperty,
        "dprop": owl.factory.getOWLDataProperty,
    }
    axioms = ArrayList()
    for fact in scene:
        axioms.add(
            fact_axiom(owl.factory, fact, lambda kind, name: made[kind](IRI.create(NS + name)))
        )
    owl.manager.addAxioms(candidate, axioms)
    abox = {f.subject for f in scene} | {f.object for f in scene if f.kind is FactKind.OBJECT}
    reasoner = make_reasoner("hermit", owl.root)
    try:
        if not reasoner.isConsistent():
            return (), False
        names = {str(i.getIRI().getShortForm()) for i in _individuals(reasoner, cls)}
        return tuple(sorted(names & abox)), True
    finally:
        reasoner.dispose()
        owl.manager.removeAxioms(candidate, axioms)


def _names(classes: Any) -> set[str]:
    """Short names of a node set (or a node's entities), without owl:Thing and owl:Nothing."""
    out = set()
    for c in classes.getFlattened() if hasattr(classes, "getFlattened") else classes:
        if not c.isOWLNothing() and not c.isOWLThing():
            out.add(iri_short(c.getIRI()))
    return out


def _declaring_layers(owl: OwlModules, candidate: Any, terms: tuple[str, ...]) -> dict[str, str]:
    """The lowest layer that declares each term (the candidate's own module
    does not count: it declares every term it uses)."""
    from org.semanticweb.owlapi.model import IRI
    from org.semanticweb.owlapi.model.parameters import Imports

    out: dict[str, str] = {}
    for term in terms:
        iri = IRI.create(NS + term)
        best: str | None = None
        for ont in owl.closure:
            if not ont.containsEntityInSignature(iri, Imports.EXCLUDED):
                continue
            entities = ont.getEntitiesInSignature(iri, Imports.EXCLUDED)
            if any(any(True for _ in ont.getDeclarationAxioms(e)) for e in entities):
                layer = module_layer(str(ont.getOntologyID().getOntologyIRI().get()))
                best = _lowest(best, layer)
        if best is not None:
            out[term] = best
    return out


def _lowest(a: str | None, b: str) -> str:
    if a is None:
        return b
    return a if LAYERS.index(a) <= LAYERS.index(b) else b
