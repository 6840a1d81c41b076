"""A workspace's modules as Manchester text: each layer's header, the block a
decision adds to a layer, the module a candidate is checked in, and the export.

Every block starts with the line ``# candidate N: Name``, written and read
here: it is how the modules and the decisions are kept in step.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Final

from virf.ontology import manchester
from virf.ontology.iri import MODULE_BASE
from virf.ontology.tbox import Vocabulary, ontology_dir
from virf.ontology.workspace import KbLayout

CANDIDATE_IRI: Final = "http://virf.dev/ontology/workspace/candidate"
EXPORT_IRI: Final = "http://virf.dev/ontology/workspace/export"
# The annotations a workspace adds to what every USC carries.
PROVENANCE: Final = ("evidence", "drafter", "reviewer", "decision", "decidedOn", "candidate")
_USC_ANNOTATIONS: Final = (
    "id",
    "kind",
    "category",
    "dangerLevel",
    "safetyWarning",
    "triggerReason",
    "suggestion",
    "source",
    "checkAt",
    "mechanism",
    "twin",
    "question",
)
_BLOCK_HEADER: Final = re.compile(r"^# candidate ([0-9]+): [A-Za-z][A-Za-z0-9_]*$", re.MULTILINE)


def block_header(cid: int, name: str) -> str:
    """The first line of the block accepting candidate ``cid``."""
    return f"# candidate {cid}: {name}"


def block_ids(module: str) -> list[int]:
    """The candidates whose blocks a module holds."""
    return [int(n) for n in _BLOCK_HEADER.findall(module)]


def append_block(module: str, block: str) -> str:
    return module.rstrip("\n") + "\n\n" + block


def declarations() -> str:
    props = (*_USC_ANNOTATIONS, *PROVENANCE, "rdfs:comment", "rdfs:label")
    return "".join(manchester.frame("AnnotationProperty", p) + "\n" for p in props)


def _builtin_imports(scenario: str) -> list[str]:
    """The modules the built-in scenario module imports (its domain layer)."""
    path = ontology_dir() / f"scenario-{scenario}.omn"
    return list(manchester.header_of(path.read_text(encoding="utf-8"), path.name).imports)


def module_header(layout: KbLayout, layer: str) -> str:
    """A layer module as a new workspace has it: no block yet."""
    if layer == "core":
        imports = [f"{MODULE_BASE}core"]
    elif layer == "domain":
        imports = [layout.module_iri("core"), *_builtin_imports(layout.scenario)]
    else:
        imports = [layout.module_iri("domain"), f"{MODULE_BASE}scenario-{layout.scenario}"]
    about = (
        ("rdfs:label", f"Workspace {layer} layer"),
        (
            "rdfs:comment",
            "Axioms accepted through VIRF knowledge acquisition (virf kb decide or the review "
            "page). Written by VIRF, one block per decision; edit through the workflow.",
        ),
    )
    return manchester.document(layout.module_iri(layer), imports, about, declarations())


def candidate_module(layout: KbLayout, block: str) -> str:
    """A candidate's block as a module of its own, on top of the workspace."""
    return manchester.document(
        CANDIDATE_IRI, [layout.module_iri("scenario")], (), declarations(), block
    )


def export_module(scenario: str, iri: str, label: str, blocks: Iterable[str]) -> str:
    """Accepted blocks as one module importing the built-in ``scenario``."""
    about = (
        ("rdfs:label", label),
        (
            "rdfs:comment",
            "Written by 'virf kb export' from the workspace's accepted candidates; "
            "each block is one decision. Edit through the workflow, not by hand.",
        ),
    )
    module = manchester.document(iri, [f"{MODULE_BASE}scenario-{scenario}"], about, declarations())
    return module + "".join(f"\n{block.rstrip()}\n" for block in blocks)


def rule_block(
    vocab: Vocabulary,
    cid: int,
    rule: Mapping[str, Any],
    axiom: str,
    new_classes: Sequence[tuple[str, str]],
    evidence_ids: Sequence[str],
    source: str,
    drafter: str,
    decision: Mapping[str, str] | None,
) -> str:
    """The Manchester frames accepting a drafted rule adds to a layer module:
    the terms it uses, the new classes it introduces, and the rule as an
    Unsafe State Concept with its annotations and provenance."""
    name = rule["name"]
    lines = [block_header(cid, name)]
    # Every term the block uses is declared in it: OWLAPI's Manchester
    # parser does not look into already-loaded imports when it parses a
    # document from a string, and the declarations cost nothing.
    new = {c for c, _ in new_classes}
    for term, role in sorted(manchester.names(axiom).items()):
        if term in new:
            continue
        keyword = manchester.FRAME_OF_ROLE[role]
        if term in vocab.data_properties:
            keyword = "DataProperty"
        lines.append(manchester.frame(keyword, term))
    for parent in sorted({p for _, p in new_classes} - new | {"UnsafeStateConcept"}):
        lines.append(manchester.frame("Class", parent))
    lines.append("")
    for cls, parent in new_classes:
        introduced = ("rdfs:comment", f"Introduced by candidate {cid} ({name}).")
        lines += [
            manchester.frame(
                "Class",
                cls,
                manchester.annotations_section([introduced], one_line=True),
                manchester.section("SubClassOf", [manchester.term(parent)], one_line=True),
            ),
            "",
        ]
    anns = [
        ("id", name),
        ("kind", rule["kind"]),
        ("category", rule["category"]),
        ("dangerLevel", rule["danger_level"]),
        ("rdfs:comment", rule["description"]),
        ("safetyWarning", rule["safety_warning"]),
        ("triggerReason", rule["trigger_reason"]),
        ("suggestion", rule["suggestion"]),
        ("source", source),
        ("checkAt", rule["check_at"]),
        *([("mechanism", rule["mechanism"])] if rule.get("mechanism") else []),
        *([("question", rule["question"])] if rule.get("question") else []),
        *(("twin", t) for t in rule.get("twins", ())),
        *(("evidence", pid) for pid in evidence_ids),
        ("drafter", drafter),
        ("candidate", str(cid)),
        *(decision or {}).items(),
    ]
    definition = manchester.Axiom(axiom, (("id", name + "-def"), ("source", source)))
    lines += [
        manchester.frame(
            "Class",
            name,
            manchester.annotations_section(anns),
            manchester.section("EquivalentTo", [definition]),
            manchester.section(
                "SubClassOf", [manchester.term("UnsafeStateConcept")], one_line=True
            ),
        ),
        "",
    ]
    return "\n".join(lines)
