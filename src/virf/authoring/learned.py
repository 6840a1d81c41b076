"""A class learned from answers, as a candidate of the workspace: the block
accepting it adds to a layer module (the class, each superclass a background
axiom citing the answers) and the checks it goes through before a person
decides (:mod:`virf.authoring.learn` makes the candidate).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from virf.authoring import checks, layers
from virf.authoring.check_items import reasoner_items
from virf.authoring.learn import CLASS_NAME
from virf.authoring.models import CheckItem, CheckReport, Layer, Learned, Related
from virf.authoring.normalize import normalise
from virf.errors import InputError, clip
from virf.names import term_key
from virf.ontology import manchester
from virf.ontology.tbox import Vocabulary
from virf.ontology.workspace import LAYERS
from virf.world.open_world import HYPOTHESIS_WORDS

if TYPE_CHECKING:
    from virf.authoring.store import CandidateRow
    from virf.authoring.workspace import Workspace


def learned_of(row: CandidateRow) -> Learned:
    return Learned.model_validate(row.draft["learned"])


def evidence_lines(learned: Learned) -> list[str]:
    """Each answer as one line, for the module's ``:evidence`` annotations."""
    return [
        f"answer by {learned.who} at {learned.when} about scene {learned.scene_name} "
        f"(sha256 {learned.scene_sha256[:16]}): {a.question} ({a.key}) -> {a.answer}"
        for a in learned.answers
    ]


def source_text(learned: Learned) -> str:
    instances = ", ".join(learned.instances)
    return (
        f"answers by {learned.who} on {learned.when[:10]} about {instances} in scene "
        f"{learned.scene_name} (sha256 {learned.scene_sha256[:16]}), learned through VIRF"
    )


def _axiom_id(name: str, part: str, n: int, vocab: Vocabulary) -> str:
    m = re.fullmatch(r"\(?\s*(hasProperty|hasMaterial) value (\w+)\s*\)?", part)
    if m:
        kind = "property" if m[1] == "hasProperty" else "material"
        return f"LEARNED-{name}-{kind}-{m[2]}"
    if re.fullmatch(r"\w+", part) and part in vocab.classes:
        return f"LEARNED-{name}-isa-{part}"
    return f"LEARNED-{name}-axiom-{n}"


def block(
    vocab: Vocabulary,
    cid: int,
    learned: Learned,
    axiom: str,
    display: str,
    drafter: str,
    decision: Mapping[str, str] | None,
) -> str:
    """The Manchester frames accepting a learned class adds to a layer
    module: the class, each superclass as a background axiom citing the
    answers, and the answers themselves as evidence."""
    name = learned.class_name
    lines = [layers.block_header(cid, name)]
    for term, role in sorted(manchester.names(axiom).items()):
        lines.append(manchester.frame(manchester.FRAME_OF_ROLE[role], term))
    lines.append("")
    source = source_text(learned)
    anns = [
        ("rdfs:comment", f"{name}: learned from answers about an open-world object."),
        *(("evidence", e) for e in evidence_lines(learned)),
        ("source", source),
        ("drafter", drafter),
        ("candidate", str(cid)),
        *(decision or {}).items(),
    ]
    parts = manchester.conjuncts(display, prefix=":")
    shown = manchester.conjuncts(display)
    confirmed = {a.effect for a in learned.answers}
    supers = []
    for n, (part, text) in enumerate(zip(parts, shown, strict=True), start=1):
        ident = _axiom_id(name, text, n, vocab)
        said = f"{name} SubClassOf {text.removeprefix('(').removesuffix(')')}" in confirmed
        how = "confirmed by an answer" if said else "accepted with the learned class"
        comment = f"Every {name} {_in_words(text)} ({how})."
        about = (
            ("id", ident),
            ("rdfs:comment", comment),
            ("source", source),
            ("kind", "background"),
        )
        supers.append(manchester.Axiom(part, about))
    lines += [
        manchester.frame(
            "Class",
            name,
            manchester.annotations_section(anns),
            manchester.section("SubClassOf", supers),
        ),
        "",
    ]
    return "\n".join(lines)


def _in_words(part: str) -> str:
    m = re.fullmatch(r"\(?\s*(hasProperty|hasMaterial) value (\w+)\s*\)?", part)
    if m and m[1] == "hasMaterial":
        return f"is made of {m[2]}"
    if m:
        return f"is {HYPOTHESIS_WORDS.get(m[2], m[2])}"
    if re.fullmatch(r"\w+", part):
        return f"is a {part}"
    return f"is {part}"


def check(
    ws: Workspace,
    row: CandidateRow,
    axiom: str,
    decision: Mapping[str, str] | None = None,
) -> CheckReport:
    """Normalise and check a learned class's superclass expression: the name
    is new, every term is known, the class has a parent, the answers are its
    evidence; then HermiT (parse, consistency, satisfiability, and whether
    every object of the class would already be an unsafe state)."""
    from virf.ontology.axiom_check import check_candidate

    learned = learned_of(row)
    name = learned.class_name
    vocab = ws.tbox().vocabulary
    items: list[CheckItem] = []

    def done(
        normalised: str, terms: Sequence[Any], layer: Layer, text: str, related: Related
    ) -> CheckReport:
        return checks.report(ws.threshold, axiom, normalised, items, terms, related, layer, text)

    if not CLASS_NAME.match(name):
        items.append(CheckItem.error("name", f"'{clip(name)}' is not a class name"))
        return done("", (), "core", "", Related())
    known = vocab.canonical_class(name) or vocab.term_by_key(term_key(name))
    if known is not None:
        items.append(
            CheckItem.error(
                "name",
                f"{name} is already a term of the knowledge base ({known}): learned since, or "
                "known under another spelling; reject this candidate",
            )
        )
    try:
        normalised = normalise(
            axiom,
            vocab,
            ws.vocabulary_index(vocab),
            threshold=ws.threshold,
            own_name=name,
        )
    except InputError as exc:
        items.append(CheckItem.error("parses", str(exc)))
        return done("", (), "core", "", Related())
    items.extend(normalised.problems)
    for cls, _parent in normalised.new_classes:
        items.append(
            CheckItem.error(
                "normalisation",
                f"'{cls}' is not a class of the knowledge base: a learned class is placed "
                "under known classes only",
            )
        )
    parents = [
        p
        for p in manchester.conjuncts(normalised.display)
        if re.fullmatch(r"\w+", p) and p in vocab.classes
    ]
    if not any(vocab.is_a(p, "MaterialEntity") for p in parents):
        items.append(
            CheckItem.error(
                "parent",
                f"{name} needs a parent among the things in a scene: PhysicalObject, a kind of "
                "object, or a kind of person (Child, Adult)",
            )
        )
    items.append(_answers_item(learned))
    if learned.unconfirmed:
        items.append(
            CheckItem.warning(
                "open world",
                f"once {name} is a known class, what its name suggested is no longer assumed "
                f"nor asked about in later scenes: {'; '.join(learned.unconfirmed)}",
                ok=False,
            )
        )
    text = block(
        vocab, row.id, learned, normalised.axiom, normalised.display, row.drafter, decision
    )
    if any(i.severity == "error" for i in items):
        return done(normalised.display, normalised.terms, "core", text, Related())
    used = [t.chosen for t in normalised.terms]
    result = check_candidate(
        ws.scenario,
        tuple(str(p) for p in ws.layout.modules()),
        layers.candidate_module(ws.layout, text),
        name,
        used,
        vocab.uscs,
    )
    items.extend(
        reasoner_items(
            result, name, "its superclasses exclude each other, so no object could be one"
        )
    )
    if not result.parses:
        return done(normalised.display, normalised.terms, "core", text, Related())
    related = Related(equivalent=result.equivalent, subsumed_by=result.subsumed_by)
    if related.equivalent or related.subsumed_by:
        items.append(
            CheckItem.warning(
                "unsafe by kind",
                f"every {name} would be an unsafe state whatever the plan does: it is a "
                f"special case of {', '.join(related.equivalent + related.subsumed_by)}",
                ok=False,
            )
        )
    layer = max((result.layers.get(t, "core") for t in used), key=LAYERS.index, default="core")
    return done(normalised.display, normalised.terms, layer, text, related)  # type: ignore[arg-type]


def _answers_item(learned: Learned) -> CheckItem:
    said = len(learned.answers)
    axioms = sum(1 for a in learned.answers if not a.effect.startswith("no axiom"))
    return CheckItem.info(
        "evidence",
        f"{said} answer(s) by {learned.who} on {learned.when[:10]} about "
        f"{', '.join(learned.instances)} in scene {learned.scene_name} "
        f"(sha256 {learned.scene_sha256[:16]}); {axioms} of them give an axiom",
    )
