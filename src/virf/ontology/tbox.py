"""Load the layered safety ontology (TBox) and index it for Python callers.

OWLAPI parses the Manchester-syntax modules shipped in ``virf/ontology/modules``.
Everything the simulator and the input checks need (names, ancestors,
annotations, USC metadata) is copied once into immutable Python data, so only
the reasoning engines talk to Java afterwards.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache, cached_property
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from virf.errors import InputError, closest, unknown_term
from virf.names import term_key
from virf.ontology.jvm import ensure_jvm

NS = "http://virf.dev/ontology#"
MODULE_BASE = "http://virf.dev/ontology/"
DEFAULT_SCENARIO = "kitchen"

USC_KINDS = ("state-based", "action-based", "logical-inconsistency", "uncertainty")
DANGER_LEVELS = ("low", "medium", "high", "critical")
REQUIRED_USC_ANNOTATIONS = (
    "id",
    "kind",
    "category",
    "dangerLevel",
    "comment",
    "safetyWarning",
    "triggerReason",
    "suggestion",
    "source",
    "checkAt",
)


def ontology_dir() -> Path:
    return Path(str(resources.files("virf.ontology").joinpath("modules")))


def scenario_names() -> list[str]:
    return sorted(p.stem.removeprefix("scenario-") for p in ontology_dir().glob("scenario-*.omn"))


@dataclass(frozen=True)
class UnsafeStateConcept:
    """An Unsafe State Concept with the annotations a report needs."""

    id: str
    name: str
    kind: str
    category: str
    danger_level: str
    description: str
    safety_warning: str
    trigger_reason: str
    suggestion: str
    source: str
    check_at: str
    definition: str
    module: str
    question: str = ""
    generalizes: str = ""

    @property
    def final_only(self) -> bool:
        return self.check_at == "final"


@dataclass(frozen=True)
class BackgroundAxiom:
    """A TBox axiom carrying world knowledge (``:kind "background"``)."""

    id: str
    description: str
    source: str
    text: str
    module: str
    signature: frozenset[str]


@dataclass(frozen=True)
class ModuleStats:
    name: str
    iri: str
    label: str
    imports: tuple[str, ...]
    classes: int
    object_properties: int
    data_properties: int
    individuals: int
    logical_axioms: int
    uscs: int
    usc_by_category: Mapping[str, int]
    usc_by_kind: Mapping[str, int]


@dataclass(frozen=True)
class Vocabulary:
    """Immutable, Java-free view of the TBox."""

    classes: frozenset[str]
    object_properties: frozenset[str]
    data_properties: frozenset[str]
    individuals: frozenset[str]
    ancestors: Mapping[str, frozenset[str]]
    annotations: Mapping[str, Mapping[str, tuple[str, ...]]]
    uscs: Mapping[str, UnsafeStateConcept]
    preconditions: Mapping[str, UnsafeStateConcept]
    background: Mapping[str, BackgroundAxiom]
    property_synonyms: Mapping[str, str]
    class_synonyms: Mapping[str, str]
    class_materials: Mapping[str, frozenset[str]]
    _lower: Mapping[str, str] = field(default_factory=dict)
    # property -> its declared inverse (both directions listed)
    inverses: Mapping[str, str] = field(default_factory=dict)
    # C -> M for a class defined exactly as "PhysicalObject and hasMaterial some M"
    # that says nothing else: typing an object C says no more than hasMaterial M.
    material_classes: Mapping[str, str] = field(default_factory=dict)
    # state -> the states it excludes (declared disjoint), plus the epistemic
    # markers it settles (UnknownFillState is settled by a known fill state)
    exclusive_states: Mapping[str, frozenset[str]] = field(default_factory=dict)
    # object types generated from an object-type catalogue (a `:catalogue` annotation)
    catalogue_types: frozenset[str] = frozenset()

    def is_a(self, cls: str, ancestor: str) -> bool:
        return cls == ancestor or ancestor in self.ancestors.get(cls, frozenset())

    def any_is_a(self, classes: frozenset[str] | set[str], ancestor: str) -> bool:
        return any(self.is_a(c, ancestor) for c in classes)

    def annotation(self, term: str, prop: str) -> tuple[str, ...]:
        return self.annotations.get(term, {}).get(prop, ())

    def canonical_class(self, name: str) -> str | None:
        """Resolve a class name case-insensitively, through synonyms."""
        if name in self.classes:
            return self.class_synonyms.get(name, name)
        hit = self._lower.get(name.lower())
        if hit is None:
            return None
        return self.class_synonyms.get(hit, hit)

    def require_class(self, name: str) -> str:
        found = self.canonical_class(name)
        if found is None:
            raise unknown_term("class", name, self.classes)
        return found

    def materials_of(self, classes: frozenset[str] | set[str]) -> frozenset[str]:
        """Materials every instance of these classes has by background knowledge."""
        out: set[str] = set()
        for cls in classes:
            for c in {cls} | set(self.ancestors.get(cls, ())):
                out |= self.class_materials.get(c, frozenset())
        return frozenset(out)

    def typical_materials(self, classes: frozenset[str] | set[str]) -> tuple[str, ...]:
        for cls in sorted(classes):
            found = self.annotation(cls, "typicalMaterial")
            if found:
                return found
        return ()

    @cached_property
    def _keys(self) -> Mapping[str, str]:
        out: dict[str, str] = {}
        for term in sorted(self.classes | self.individuals):
            out.setdefault(term_key(term), term)
        return out

    def term_by_key(self, key: str) -> str | None:
        """The class or individual a name reads as, ignoring case and separators."""
        return self._keys.get(key)

    def excluded_by(self, state: str) -> frozenset[str]:
        """The states an object leaves when it enters ``state``."""
        return self.exclusive_states.get(state, frozenset())

    def canonical_property(self, name: str) -> str | None:
        if name in self.property_synonyms:
            return self.property_synonyms[name]
        if name in self.object_properties or name in self.data_properties:
            return name
        return None


def _hint(near: list[str]) -> str:
    return f"; closest known: {', '.join(near)}" if near else ""


def _short(iri: Any) -> str:
    text = str(iri.toString()) if not isinstance(iri, str) else iri
    if text.startswith("<") and text.endswith(">"):
        text = text[1:-1]
    if "#" in text:
        return text.rsplit("#", 1)[1]
    return text.rsplit("/", 1)[-1]


def _literal(value: Any) -> str:
    if value.isLiteral():
        return str(value.asLiteral().get().getLiteral())
    return _short(value.asIRI().get())


class TBox:
    """The loaded ontology for one scenario (its import closure)."""

    def __init__(
        self, scenario: str = DEFAULT_SCENARIO, extra_modules: tuple[str, ...] = ()
    ) -> None:
        """``extra_modules``: further Manchester-syntax files imported into the
        scenario (synthetic domain modules for scaling runs, test fixtures)."""
        names = scenario_names()
        if scenario not in names:
            raise InputError(
                f"unknown scenario '{scenario}'" + _hint(closest(scenario, names) or names)
            )
        ensure_jvm()
        from java.io import File
        from org.semanticweb.owlapi.apibinding import OWLManager
        from org.semanticweb.owlapi.model import IRI
        from org.semanticweb.owlapi.util import SimpleIRIMapper

        self.scenario = scenario
        self.manager = OWLManager.createOWLOntologyManager()
        for path in sorted(ontology_dir().glob("*.omn")):
            self.manager.getIRIMappers().add(
                SimpleIRIMapper(IRI.create(MODULE_BASE + path.stem), IRI.create(File(str(path))))
            )
        try:
            self.root = self.manager.loadOntology(IRI.create(MODULE_BASE + f"scenario-{scenario}"))
        except Exception as exc:  # OWLAPI reports every parser it tried; keep the Manchester one
            raise OntologyLoadError(_manchester_message(str(exc))) from None
        self.factory = self.manager.getOWLDataFactory()
        self.extra_modules = tuple(str(p) for p in extra_modules)
        for extra in self.extra_modules:
            from org.semanticweb.owlapi.model import AddImport

            if not Path(extra).is_file():
                raise InputError(f"ontology module not found: {extra}")
            try:
                ont = self.manager.loadOntologyFromOntologyDocument(File(extra))
            except Exception as exc:
                raise OntologyLoadError(_manchester_message(str(exc))) from None
            iri = ont.getOntologyID().getOntologyIRI().get()
            self.manager.applyChange(
                AddImport(self.root, self.factory.getOWLImportsDeclaration(iri))
            )
        self.closure = list(self.root.getImportsClosure())
        self._renderer = _make_renderer()
        self.vocabulary, self.module_stats = self._index()

    # ------------------------------------------------------------------ indexing
    def module_name(self, ontology: Any) -> str:
        iri = ontology.getOntologyID().getOntologyIRI().get()
        return _short(iri)

    def render(self, obj: Any) -> str:
        text = str(self._renderer.render(obj))
        return re.sub(r"\s+", " ", text).strip()

    def logical_axioms(self) -> list[Any]:
        out = []
        for ont in self.closure:
            out.extend(ont.getLogicalAxioms())
        return out

    def _index(self) -> tuple[Vocabulary, tuple[ModuleStats, ...]]:
        from org.semanticweb.HermiT import ReasonerFactory

        classes: set[str] = set()
        oprops: set[str] = set()
        dprops: set[str] = set()
        individuals: set[str] = set()
        annotations: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
        background: dict[str, BackgroundAxiom] = {}
        definitions: dict[str, tuple[str, str]] = {}
        direct_materials: dict[str, set[str]] = defaultdict(set)
        inverses: dict[str, str] = {}
        defined_by_material: dict[str, str] = {}
        told_elsewhere: set[str] = set()  # classes with axioms beyond a material definition
        disjoint_pairs: set[tuple[str, str]] = set()
        for ont in self.closure:
            module = self.module_name(ont)
            for c in ont.getClassesInSignature():
                if str(c.getIRI().toString()).startswith(NS):
                    classes.add(_short(c.getIRI()))
            for p in ont.getObjectPropertiesInSignature():
                if str(p.getIRI().toString()).startswith(NS):
                    oprops.add(_short(p.getIRI()))
            for p in ont.getDataPropertiesInSignature():
                if str(p.getIRI().toString()).startswith(NS):
                    dprops.add(_short(p.getIRI()))
            for i in ont.getIndividualsInSignature():
                if i.isNamed():
                    individuals.add(_short(i.asOWLNamedIndividual().getIRI()))
            for ax in ont.axioms(_axiom_type("ANNOTATION_ASSERTION")).toArray():
                if True:
                    subject = ax.getSubject()
                    if subject.isIRI():
                        key = _short(subject.asIRI().get())
                        prop = _short(ax.getProperty().getIRI())
                        annotations[key][prop].append(_literal(ax.getValue()))
            for ax in ont.axioms(_axiom_type("SUBCLASS_OF")).toArray():
                sub, sup = ax.getSubClass(), ax.getSuperClass()
                if (
                    sub.isAnonymous()
                    or str(sup.getClassExpressionType().toString()) != "ObjectHasValue"
                ):
                    continue
                if _short(sup.getProperty().asOWLObjectProperty().getIRI()) == "hasMaterial":
                    value = sup.getFiller()
                    if value.isNamed():
                        direct_materials[_short(sub.asOWLClass().getIRI())].add(
                            _short(value.asOWLNamedIndividual().getIRI())
                        )
            for ax in ont.axioms(_axiom_type("INVERSE_OBJECT_PROPERTIES")).toArray():
                first, second = ax.getFirstProperty(), ax.getSecondProperty()
                if first.isNamed() and second.isNamed():
                    a = _short(first.asOWLObjectProperty().getIRI())
                    b = _short(second.asOWLObjectProperty().getIRI())
                    inverses[a], inverses[b] = b, a
            for ax in ont.axioms(_axiom_type("EQUIVALENT_CLASSES")).toArray():
                named = [c for c in ax.getClassExpressionsAsList() if not c.isAnonymous()]
                other = [c for c in ax.getClassExpressionsAsList() if c.isAnonymous()]
                if len(named) == 1 and len(other) == 1:
                    material = _material_definition(other[0])
                    if material is not None:
                        defined_by_material[_short(named[0].asOWLClass().getIRI())] = material
                        continue
                told_elsewhere.update(_short(c.asOWLClass().getIRI()) for c in named)
            for ax in ont.axioms(_axiom_type("SUBCLASS_OF")).toArray():
                if not ax.getSubClass().isAnonymous():
                    told_elsewhere.add(_short(ax.getSubClass().asOWLClass().getIRI()))
            for ax in ont.axioms(_axiom_type("DISJOINT_CLASSES")).toArray():
                named_ops = [
                    _short(c.asOWLClass().getIRI())
                    for c in ax.getClassExpressionsAsList()
                    if not c.isAnonymous()
                ]
                disjoint_pairs.update((a, b) for a in named_ops for b in named_ops if a != b)
            for ax in ont.getLogicalAxioms():
                notes: dict[str, str] = {}
                for ann in ax.getAnnotations():
                    notes[_short(ann.getProperty().getIRI())] = _literal(ann.getValue())
                if "id" not in notes:
                    continue
                ident = notes["id"]
                text = self.render(ax)
                if ident.endswith("-def"):
                    definitions[ident[: -len("-def")]] = (text, module)
                if notes.get("kind") == "background":
                    sig = frozenset(_short(e.getIRI()) for e in ax.getSignature())
                    background[ident] = BackgroundAxiom(
                        id=ident,
                        description=notes.get("comment", ""),
                        source=notes.get("source", ""),
                        text=text,
                        module=module,
                        signature=sig,
                    )

        # Classify once so that ancestors include inferred ones (a Pot is a
        # MetallicObject because every pot is made of metal).
        reasoner = ReasonerFactory().createReasoner(self.root)
        try:
            from org.semanticweb.owlapi.reasoner import InferenceType

            reasoner.precomputeInferences(InferenceType.CLASS_HIERARCHY)
            if not reasoner.isConsistent():
                raise InputError(f"the {self.scenario} TBox is inconsistent")
            ancestors: dict[str, frozenset[str]] = {}
            for name in sorted(classes):
                cls = self.factory.getOWLClass(_iri(name))
                sup = reasoner.getSuperClasses(cls, False).getFlattened()
                eq = reasoner.getEquivalentClasses(cls).getEntities()
                found = {_short(s.getIRI()) for s in list(sup) + list(eq)}
                found.discard("Thing")
                found.discard(name)
                ancestors[name] = frozenset(a for a in found if a in classes)
        finally:
            reasoner.dispose()

        frozen_ann = {
            k: MappingProxyType({p: tuple(v) for p, v in props.items()})
            for k, props in annotations.items()
        }
        uscs: dict[str, UnsafeStateConcept] = {}
        preconditions: dict[str, UnsafeStateConcept] = {}
        usc_module: dict[str, str] = {}
        for name in sorted(classes):
            anc = ancestors.get(name, frozenset())
            ann = frozen_ann.get(name, MappingProxyType({}))
            is_usc = "UnsafeStateConcept" in anc
            is_pre = "PreconditionViolation" in anc
            if not (is_usc or is_pre) or "id" not in ann:
                continue
            ident = ann["id"][0]
            text, module = definitions.get(ident, ("", ""))
            usc = UnsafeStateConcept(
                id=ident,
                name=name,
                kind=_one(ann, "kind"),
                category=_one(ann, "category"),
                danger_level=_one(ann, "dangerLevel"),
                description=_one(ann, "comment"),
                safety_warning=_one(ann, "safetyWarning"),
                trigger_reason=_one(ann, "triggerReason"),
                suggestion=_one(ann, "suggestion"),
                source=_one(ann, "source"),
                check_at=_one(ann, "checkAt") or "always",
                definition=text,
                module=module,
                question=_one(ann, "question"),
                generalizes=_one(ann, "generalizes"),
            )
            (uscs if is_usc else preconditions)[name] = usc
            usc_module[name] = module

        prop_syn: dict[str, str] = {}
        cls_syn: dict[str, str] = {}
        for term, props in frozen_ann.items():
            for alias in props.get("synonym", ()):
                if term in oprops or term in dprops:
                    if alias in oprops:
                        continue  # a declared equivalent property, not just a word
                    prop_syn[alias] = term
                elif term in classes:
                    cls_syn[alias] = term
        # Equivalent named properties (isMadeOf == hasMaterial) act as synonyms too.
        prop_syn.setdefault("isMadeOf", "hasMaterial")
        prop_syn.setdefault("hasActor", "hasAgent")
        for alias, target in list(cls_syn.items()):
            if alias in classes:
                continue
            classes.add(alias)
            ancestors[alias] = ancestors.get(target, frozenset()) | {target}
        lower = {c.lower(): c for c in sorted(classes)}

        def is_state(c: str) -> bool:
            return "State" in ancestors.get(c, frozenset()) and c in individuals

        exclusive: dict[str, set[str]] = defaultdict(set)
        for a, b in disjoint_pairs:
            if is_state(a) and is_state(b):
                exclusive[a].add(b)
        for marker, props in frozen_ann.items():
            for settled_by in props.get("settledBy", ()):
                exclusive[settled_by].add(marker)
        material_classes = {
            c: m
            for c, m in defined_by_material.items()
            if c not in told_elsewhere and m in individuals
        }

        vocab = Vocabulary(
            classes=frozenset(classes),
            object_properties=frozenset(oprops),
            data_properties=frozenset(dprops),
            individuals=frozenset(individuals),
            ancestors=MappingProxyType(ancestors),
            annotations=MappingProxyType(frozen_ann),
            uscs=MappingProxyType(uscs),
            preconditions=MappingProxyType(preconditions),
            background=MappingProxyType(background),
            property_synonyms=MappingProxyType(prop_syn),
            class_synonyms=MappingProxyType(cls_syn),
            class_materials=MappingProxyType(
                {k: frozenset(v) for k, v in sorted(direct_materials.items())}
            ),
            _lower=MappingProxyType(lower),
            inverses=MappingProxyType(dict(sorted(inverses.items()))),
            material_classes=MappingProxyType(dict(sorted(material_classes.items()))),
            exclusive_states=MappingProxyType(
                {k: frozenset(v) for k, v in sorted(exclusive.items())}
            ),
            catalogue_types=frozenset(
                c for c, props in frozen_ann.items() if c in classes and props.get("catalogue")
            ),
        )
        return vocab, self._stats(uscs, usc_module)

    def _stats(
        self, uscs: Mapping[str, UnsafeStateConcept], usc_module: Mapping[str, str]
    ) -> tuple[ModuleStats, ...]:
        out = []
        for ont in self.closure:
            name = self.module_name(ont)
            labels = [
                _literal(a.getValue())
                for a in ont.getAnnotations()
                if _short(a.getProperty().getIRI()) == "label"
            ]
            imports = tuple(sorted(_short(d.getIRI()) for d in ont.getImportsDeclarations()))
            mine = [u for n, u in uscs.items() if usc_module.get(n) == name]
            by_cat: dict[str, int] = defaultdict(int)
            by_kind: dict[str, int] = defaultdict(int)
            for u in mine:
                by_cat[u.category] += 1
                by_kind[u.kind] += 1
            out.append(
                ModuleStats(
                    name=name,
                    iri=MODULE_BASE + name,
                    label=labels[0] if labels else name,
                    imports=imports,
                    classes=int(ont.getClassesInSignature().size()),
                    object_properties=int(ont.getObjectPropertiesInSignature().size()),
                    data_properties=int(ont.getDataPropertiesInSignature().size()),
                    individuals=int(ont.getIndividualsInSignature().size()),
                    logical_axioms=int(ont.getLogicalAxiomCount()),
                    uscs=len(mine),
                    usc_by_category=MappingProxyType(dict(sorted(by_cat.items()))),
                    usc_by_kind=MappingProxyType(dict(sorted(by_kind.items()))),
                )
            )
        order = {"core": 0, "kitchen": 1}
        out.sort(
            key=lambda m: (order.get(m.name, 3 if m.name.startswith("scenario") else 2), m.name)
        )
        return tuple(out)


class OntologyLoadError(InputError):
    """An ontology module does not parse."""


def _manchester_message(text: str) -> str:
    """The Manchester parser's diagnosis out of OWLAPI's multi-parser report."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("Parser: org.semanticweb.owlapi.manchestersyntax"):
            for follow in lines[i + 1 : i + 12]:
                if "Encountered" in follow:
                    return "ontology does not parse: " + follow.split("    ")[0].strip()
    document = next((ln for ln in lines if "ocument" in ln and ".omn" in ln), "")
    return "ontology does not parse" + (f" ({document.strip()})" if document else "")


def _one(ann: Mapping[str, tuple[str, ...]], key: str) -> str:
    values = ann.get(key, ())
    return values[0] if values else ""


def _iri(name: str) -> Any:
    from org.semanticweb.owlapi.model import IRI

    return IRI.create(NS + name)


def _material_definition(expr: Any) -> str | None:
    """M when ``expr`` is exactly ``PhysicalObject and (hasMaterial some M)``."""
    if str(expr.getClassExpressionType().toString()) != "ObjectIntersectionOf":
        return None
    ops = list(expr.getOperandsAsList())
    if len(ops) != 2:
        return None
    named = [o for o in ops if not o.isAnonymous()]
    some = [o for o in ops if str(o.getClassExpressionType().toString()) == "ObjectSomeValuesFrom"]
    if (
        len(named) != 1
        or len(some) != 1
        or _short(named[0].asOWLClass().getIRI()) != "PhysicalObject"
    ):
        return None
    prop, filler = some[0].getProperty(), some[0].getFiller()
    if prop.isAnonymous() or filler.isAnonymous():
        return None
    if _short(prop.asOWLObjectProperty().getIRI()) != "hasMaterial":
        return None
    return _short(filler.asOWLClass().getIRI())


def _axiom_type(name: str) -> Any:
    from org.semanticweb.owlapi.model import AxiomType

    return getattr(AxiomType, name)


def _make_renderer() -> Any:
    from org.semanticweb.owlapi.manchestersyntax.renderer import (
        ManchesterOWLSyntaxOWLObjectRendererImpl,
    )
    from org.semanticweb.owlapi.util import SimpleShortFormProvider

    renderer = ManchesterOWLSyntaxOWLObjectRendererImpl()
    renderer.setShortFormProvider(SimpleShortFormProvider())
    return renderer


@cache
def load_tbox(scenario: str = DEFAULT_SCENARIO, extra_modules: tuple[str, ...] = ()) -> TBox:
    """The TBox for ``scenario`` (plus ``extra_modules``), loaded once per process."""
    return TBox(scenario, extra_modules)
