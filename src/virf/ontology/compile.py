"""Compile the ontology modules into the knowledge artifact the fast path loads.

For each scenario, OWLAPI parses the Manchester-syntax modules and HermiT
classifies them once; what the Python side needs (names, the inferred class
hierarchy, annotations, USC metadata, background axioms, module statistics and
the TBox as fast-engine terms) is written to ``compiled/<scenario>.json``.
``virf verify`` with the fast engine then answers without starting Java.

Scenarios that compile to the same knowledge share one file: the four room
scenarios import the same rules, and differ only in their own module (its
name, IRI and label).  ``compiled/scenarios.json`` names each scenario's file
and, for a scenario that shares another's, the statistics of its own module,
which :func:`read_artifact` puts back.

The artifact names a digest of the module files it came from; a module edited
since is noticed when the knowledge base loads, and the modules are compiled
in-process instead (see :func:`virf.ontology.tbox.load_tbox`).  The digest is
a cache key, not a proof: a workspace's artifact, in a folder anyone with the
workspace can write, is also sealed (:mod:`virf.ontology.seal`), and
``virf kb check`` compiles the modules and compares.

    python -m virf.ontology.compile          # rewrite every artifact
    python -m virf.ontology.compile --check  # exit 1 when one is out of date
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from virf.errors import InputError
from virf.files import write_atomically
from virf.ontology.artifact import (
    FORMAT,
    CompiledKB,
    from_json,
    module_stats_from,
    plain,
    to_json,
)
from virf.ontology.fragment import load_fragment
from virf.ontology.iri import MODULE_BASE, NS, THING, iri_short
from virf.ontology.tbox import (
    DEFAULT_SCENARIO,
    BackgroundAxiom,
    ModuleStats,
    UnsafeStateConcept,
    Vocabulary,
    lower_index,
    ontology_dir,
    scenario_names,
)

if TYPE_CHECKING:
    from virf.ontology.owlapi import OwlModules

# Which file holds each scenario's knowledge (see the module's docstring).
INDEX = "scenarios.json"


def artifact_dir() -> Path:
    return Path(__file__).with_name("compiled")


def index_path() -> Path:
    return artifact_dir() / INDEX


def _index_entries() -> dict[str, Any]:
    entries: dict[str, Any] = json.loads(index_path().read_text(encoding="utf-8"))["scenarios"]
    return entries


def artifact_path(scenario: str) -> Path:
    """The file that holds ``scenario``'s knowledge, shared or its own;
    ``<scenario>.json`` when the index does not name one (yet)."""
    try:
        name = str(_index_entries()[scenario]["artifact"])
    except (OSError, ValueError, KeyError, TypeError):
        name = f"{scenario}.json"
    return artifact_dir() / name


def source_digest(module_dir: Path | None = None) -> str:
    """A digest of every module file (any edit may change any scenario's
    closure) and of the artifact format."""
    h = hashlib.sha256(f"virf-kb-format-{FORMAT}\n".encode())
    for path in sorted((module_dir or ontology_dir()).glob("*.omn")):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def compile_kb(owl: OwlModules, digest: str) -> CompiledKB:
    vocabulary, stats = _index(owl)
    fragment = load_fragment(owl.logical_axioms(), owl.render)
    return CompiledKB(owl.scenario, digest, vocabulary, stats, fragment)


def _index(owl: OwlModules) -> tuple[Vocabulary, tuple[ModuleStats, ...]]:
    # The Java bridge is imported by the compiling functions only: loading a
    # compiled artifact (every start of the fast engine) does not need it.
    from virf.ontology.owlapi import annotations_of, axiom_type, literal, make_reasoner

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
    for ont in owl.closure:
        module = owl.module_name(ont)
        for c in ont.getClassesInSignature():
            if str(c.getIRI().toString()).startswith(NS):
                classes.add(iri_short(c.getIRI()))
        for p in ont.getObjectPropertiesInSignature():
            if str(p.getIRI().toString()).startswith(NS):
                oprops.add(iri_short(p.getIRI()))
        for p in ont.getDataPropertiesInSignature():
            if str(p.getIRI().toString()).startswith(NS):
                dprops.add(iri_short(p.getIRI()))
        for i in ont.getIndividualsInSignature():
            if i.isNamed():
                individuals.add(iri_short(i.asOWLNamedIndividual().getIRI()))
        for ax in ont.axioms(axiom_type("ANNOTATION_ASSERTION")).toArray():
            subject = ax.getSubject()
            if subject.isIRI():
                key = iri_short(subject.asIRI().get())
                prop = iri_short(ax.getProperty().getIRI())
                annotations[key][prop].append(literal(ax.getValue()))
        for ax in ont.axioms(axiom_type("SUBCLASS_OF")).toArray():
            sub, sup = ax.getSubClass(), ax.getSuperClass()
            if (
                sub.isAnonymous()
                or str(sup.getClassExpressionType().toString()) != "ObjectHasValue"
            ):
                continue
            if iri_short(sup.getProperty().asOWLObjectProperty().getIRI()) == "hasMaterial":
                value = sup.getFiller()
                if value.isNamed():
                    direct_materials[iri_short(sub.asOWLClass().getIRI())].add(
                        iri_short(value.asOWLNamedIndividual().getIRI())
                    )
        for ax in ont.axioms(axiom_type("INVERSE_OBJECT_PROPERTIES")).toArray():
            first, second = ax.getFirstProperty(), ax.getSecondProperty()
            if first.isNamed() and second.isNamed():
                a = iri_short(first.asOWLObjectProperty().getIRI())
                b = iri_short(second.asOWLObjectProperty().getIRI())
                inverses[a], inverses[b] = b, a
        for ax in ont.axioms(axiom_type("EQUIVALENT_CLASSES")).toArray():
            named = [c for c in ax.getClassExpressionsAsList() if not c.isAnonymous()]
            other = [c for c in ax.getClassExpressionsAsList() if c.isAnonymous()]
            if len(named) == 1 and len(other) == 1:
                material = _material_definition(other[0])
                if material is not None:
                    defined_by_material[iri_short(named[0].asOWLClass().getIRI())] = material
                    continue
            told_elsewhere.update(iri_short(c.asOWLClass().getIRI()) for c in named)
        for ax in ont.axioms(axiom_type("SUBCLASS_OF")).toArray():
            if not ax.getSubClass().isAnonymous():
                told_elsewhere.add(iri_short(ax.getSubClass().asOWLClass().getIRI()))
        for ax in ont.axioms(axiom_type("DISJOINT_CLASSES")).toArray():
            named_ops = [
                iri_short(c.asOWLClass().getIRI())
                for c in ax.getClassExpressionsAsList()
                if not c.isAnonymous()
            ]
            disjoint_pairs.update((a, b) for a in named_ops for b in named_ops if a != b)
        for ax in ont.getLogicalAxioms():
            notes = annotations_of(ax)
            if "id" not in notes:
                continue
            ident = notes["id"]
            text = owl.render(ax)
            if ident.endswith("-def"):
                definitions[ident[: -len("-def")]] = (text, module)
            if notes.get("kind") == "background":
                sig = frozenset(iri_short(e.getIRI()) for e in ax.getSignature())
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
    reasoner = make_reasoner("hermit", owl.root)
    try:
        from org.semanticweb.owlapi.reasoner import InferenceType

        reasoner.precomputeInferences(InferenceType.CLASS_HIERARCHY)
        if not reasoner.isConsistent():
            raise InputError(f"the {owl.scenario} TBox is inconsistent")
        ancestors: dict[str, frozenset[str]] = {}
        for name in sorted(classes):
            cls = owl.owl_class(name)
            sup = reasoner.getSuperClasses(cls, False).getFlattened()
            eq = reasoner.getEquivalentClasses(cls).getEntities()
            found = {iri_short(s.getIRI()) for s in list(sup) + list(eq)}
            found.discard(THING)
            found.discard(name)
            ancestors[name] = frozenset(a for a in found if a in classes)
    finally:
        reasoner.dispose()

    frozen_ann = {
        # Repeated values sorted: OWLAPI hands them over in hash order.
        k: MappingProxyType({p: tuple(sorted(v)) for p, v in props.items()})
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
            ai2thor_refuses=_one(ann, "ai2thorRefuses"),
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
    lower = lower_index(classes)

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
        c: m for c, m in defined_by_material.items() if c not in told_elsewhere and m in individuals
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
        exclusive_states=MappingProxyType({k: frozenset(v) for k, v in sorted(exclusive.items())}),
        catalogue_types=frozenset(
            c for c, props in frozen_ann.items() if c in classes and props.get("catalogue")
        ),
    )
    return vocab, _stats(owl, uscs, usc_module)


def _stats(
    owl: OwlModules, uscs: Mapping[str, UnsafeStateConcept], usc_module: Mapping[str, str]
) -> tuple[ModuleStats, ...]:
    from virf.ontology.owlapi import annotations_of

    out = []
    for ont in owl.closure:
        name = owl.module_name(ont)
        imports = tuple(sorted(iri_short(d.getIRI()) for d in ont.getImportsDeclarations()))
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
                label=annotations_of(ont).get("label", name),
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
    out.sort(key=_module_order)
    return tuple(out)


def _module_order(m: ModuleStats) -> tuple[int, str]:
    order = {"core": 0, "kitchen": 1}
    return order.get(m.name, 3 if m.name.startswith("scenario") else 2), m.name


def _one(ann: Mapping[str, tuple[str, ...]], key: str) -> str:
    values = ann.get(key, ())
    return values[0] if values else ""


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
        or iri_short(named[0].asOWLClass().getIRI()) != "PhysicalObject"
    ):
        return None
    prop, filler = some[0].getProperty(), some[0].getFiller()
    if prop.isAnonymous() or filler.isAnonymous():
        return None
    if iri_short(prop.asOWLObjectProperty().getIRI()) != "hasMaterial":
        return None
    return iri_short(filler.asOWLClass().getIRI())


# ---------------------------------------------------------------------------
# The artifact as JSON, written canonically so that compiling the same modules
# twice gives the same bytes: OWLAPI hands axioms over in hash order, so every
# mapping is written with sorted keys, and sets and repeated annotation
# values sorted.  (No reader depends on the order the JVM happened to use.)


# ---------------------------------------------------------------------------


def _own_module(scenario: str) -> str:
    return f"scenario-{scenario}"


def shared_form(kb: CompiledKB) -> str:
    """The artifact without what only names its scenario (the scenario and
    its own module's statistics): two scenarios with the same shared form
    compile to the same knowledge."""
    own = _own_module(kb.scenario)
    rest = tuple(m for m in kb.module_stats if m.name != own)
    return to_json(replace(kb, scenario="", module_stats=rest))


def as_scenario(kb: CompiledKB, scenario: str, own: ModuleStats) -> CompiledKB:
    """``kb``'s knowledge as ``scenario``'s, whose own module is ``own``."""
    former = _own_module(kb.scenario)
    stats = sorted([*(m for m in kb.module_stats if m.name != former), own], key=_module_order)
    return replace(kb, scenario=scenario, module_stats=tuple(stats))


def artifact_files(kbs: list[CompiledKB]) -> dict[str, str]:
    """The files of ``compiled/`` for these scenarios, by name: one artifact
    per distinct knowledge, named after the first scenario that has it (the
    default scenario first), and the index."""
    ordered = sorted(kbs, key=lambda kb: (kb.scenario != DEFAULT_SCENARIO, kb.scenario))
    files: dict[str, str] = {}
    owner: dict[str, str] = {}  # shared form -> the file that holds it
    entries: dict[str, dict[str, Any]] = {}
    for kb in ordered:
        form = shared_form(kb)
        name = owner.get(form)
        if name is None:
            name = owner[form] = f"{kb.scenario}.json"
            files[name] = to_json(kb)
            entries[kb.scenario] = {"artifact": name}
            continue
        [own] = [m for m in kb.module_stats if m.name == _own_module(kb.scenario)]
        entries[kb.scenario] = {"artifact": name, "module": plain(vars(own))}
    index = {"format": FORMAT, "scenarios": dict(sorted(entries.items()))}
    files[INDEX] = json.dumps(index, indent=1, ensure_ascii=False, sort_keys=True) + "\n"
    return files


def read_artifact(scenario: str) -> CompiledKB:
    """``scenario``'s knowledge as the built-in artifacts hold it.  OSError,
    ValueError or KeyError when they are missing, unreadable or name no such
    scenario."""
    entry = _index_entries()[scenario]
    kb = from_json((artifact_dir() / entry["artifact"]).read_text(encoding="utf-8"))
    if kb.scenario == scenario:
        return kb
    return as_scenario(kb, scenario, module_stats_from(entry["module"]))


def write_artifacts() -> list[Path]:
    from virf.ontology.owlapi import OwlModules

    digest = source_digest()
    kbs = [compile_kb(OwlModules(s, ontology_dir()), digest) for s in scenario_names()]
    folder = artifact_dir()
    folder.mkdir(exist_ok=True)
    files = artifact_files(kbs)
    written = []
    for name, text in files.items():
        write_atomically(folder / name, text)
        written.append(folder / name)
    for path in sorted(folder.glob("*.json")):
        if path.name not in files:
            path.unlink()  # a scenario's own file from before it shared another's
    return written


def stale_artifacts() -> list[str]:
    """Scenarios whose artifact is missing or was compiled from other modules."""
    digest = source_digest()
    out = []
    try:
        entries = _index_entries()
    except (OSError, ValueError, KeyError, TypeError):
        entries = {}
    for scenario in scenario_names():
        if _artifact_digest(scenario, entries.get(scenario)) != digest:
            out.append(scenario)
    return out


def _artifact_digest(scenario: str, entry: Any) -> str | None:
    """The digest of the file the index entry names, if it can be read as
    ``scenario``'s (only the digest: loading every artifact whole would take
    seconds)."""
    try:
        doc = json.loads((artifact_dir() / entry["artifact"]).read_text(encoding="utf-8"))
        if doc["scenario"] != scenario and "module" not in entry:
            return None  # another scenario's file, and no module of its own to put back
        return str(doc["digest"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m virf.ontology.compile",
        description="Compile the ontology modules into the knowledge artifacts the fast "
        "engine loads without Java.",
    )
    parser.add_argument(
        "--check", action="store_true", help="only report artifacts that are out of date"
    )
    args = parser.parse_args(argv)
    if args.check:
        stale = stale_artifacts()
        for scenario in stale:
            print(f"out of date: {artifact_path(scenario)} (run 'make kb')", file=sys.stderr)
        return 1 if stale else 0
    try:
        for path in write_artifacts():
            print(f"wrote {path}")
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
