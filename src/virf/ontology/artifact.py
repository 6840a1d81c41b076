"""The knowledge artifact as data: :class:`CompiledKB`, and its JSON form.

:mod:`virf.ontology.compile` makes one from the modules (Java); the fast path
reads one back without Java.  Kept apart from the compiler so that reading an
artifact needs neither the compiler nor OWLAPI.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, fields
from types import MappingProxyType
from typing import Any

from virf.ontology.fragment import Axiom, Fragment, fragment_from
from virf.ontology.tbox import (
    BackgroundAxiom,
    ModuleStats,
    UnsafeStateConcept,
    Vocabulary,
    lower_index,
)

# Bumped whenever the artifact's layout or the compiler's output changes, so
# an artifact written by an older compiler counts as out of date.
FORMAT = 1


@dataclass(frozen=True)
class CompiledKB:
    """Everything the Python side knows of one scenario's ontology."""

    scenario: str
    digest: str
    vocabulary: Vocabulary
    module_stats: tuple[ModuleStats, ...]
    fragment: Fragment


def to_json(kb: CompiledKB) -> str:
    v = kb.vocabulary
    vocab: dict[str, Any] = {}
    for f in fields(Vocabulary):
        if f.name == "_lower":  # derived from the classes when loaded
            continue
        vocab[f.name] = plain(getattr(v, f.name))

    doc = {
        "format": FORMAT,
        "scenario": kb.scenario,
        "digest": kb.digest,
        "vocabulary": vocab,
        "module_stats": [plain(vars(m)) for m in kb.module_stats],
        "fragment": {
            "problems": list(kb.fragment.problems),
            "axioms": [[a.kind, plain(a.args), a.id, a.text] for a in kb.fragment.axioms],
        },
    }
    return json.dumps(doc, indent=1, ensure_ascii=False, sort_keys=True) + "\n"


def plain(value: Any) -> Any:
    if isinstance(value, UnsafeStateConcept | BackgroundAxiom):
        return {f.name: plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, frozenset | set):
        return sorted(value)
    if isinstance(value, tuple | list):
        return [plain(v) for v in value]
    return value


def from_json(text: str) -> CompiledKB:
    doc = json.loads(text)
    if doc.get("format") != FORMAT:
        raise ValueError(f"knowledge artifact format {doc.get('format')}, expected {FORMAT}")
    raw = doc["vocabulary"]
    classes = frozenset(raw["classes"])
    annotations = raw["annotations"]

    def concept(name: str, fields_: dict[str, Any]) -> UnsafeStateConcept:
        # An artifact written before the field existed still has the annotation.
        refuses = annotations.get(name, {}).get("ai2thorRefuses") or [""]
        return UnsafeStateConcept(**{"ai2thor_refuses": refuses[0], **fields_})

    vocabulary = Vocabulary(
        classes=classes,
        object_properties=frozenset(raw["object_properties"]),
        data_properties=frozenset(raw["data_properties"]),
        individuals=frozenset(raw["individuals"]),
        ancestors=_sets(raw["ancestors"]),
        annotations=MappingProxyType(
            {
                k: MappingProxyType({p: tuple(vs) for p, vs in props.items()})
                for k, props in raw["annotations"].items()
            }
        ),
        uscs=MappingProxyType({k: concept(k, u) for k, u in raw["uscs"].items()}),
        preconditions=MappingProxyType({k: concept(k, u) for k, u in raw["preconditions"].items()}),
        background=MappingProxyType(
            {
                k: BackgroundAxiom(**{**b, "signature": frozenset(b["signature"])})
                for k, b in raw["background"].items()
            }
        ),
        property_synonyms=MappingProxyType(dict(raw["property_synonyms"])),
        class_synonyms=MappingProxyType(dict(raw["class_synonyms"])),
        class_materials=_sets(raw["class_materials"]),
        _lower=MappingProxyType(lower_index(classes)),
        inverses=MappingProxyType(dict(raw["inverses"])),
        material_classes=MappingProxyType(dict(raw["material_classes"])),
        exclusive_states=_sets(raw["exclusive_states"]),
        catalogue_types=frozenset(raw["catalogue_types"]),
    )
    stats = tuple(module_stats_from(m) for m in doc["module_stats"])
    axioms = [
        Axiom(kind, _tuples(args), ident, text)
        for kind, args, ident, text in doc["fragment"]["axioms"]
    ]
    fragment = fragment_from(axioms, list(doc["fragment"]["problems"]))
    return CompiledKB(doc["scenario"], doc["digest"], vocabulary, stats, fragment)


def module_stats_from(m: Mapping[str, Any]) -> ModuleStats:
    return ModuleStats(
        **{
            **m,
            "imports": tuple(m["imports"]),
            "usc_by_category": MappingProxyType(m["usc_by_category"]),
            "usc_by_kind": MappingProxyType(m["usc_by_kind"]),
        }
    )


def _sets(mapping: Mapping[str, list[str]]) -> Mapping[str, frozenset[str]]:
    return MappingProxyType({k: frozenset(v) for k, v in mapping.items()})


def _tuples(value: Any) -> Any:
    """JSON arrays back into the tuples fast-engine terms are made of."""
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value
