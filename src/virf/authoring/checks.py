"""The automatic checks of a candidate, before a person decides: its axiom
normalised to the vocabulary, its annotations, evidence and minimal pairs,
then HermiT on the block accepting it would add (parse, consistency,
satisfiability, novelty, and whether it would fire on every scene).

A class learned from answers has checks of its own
(:func:`virf.authoring.learned.check`); :func:`check_row` picks them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from virf.authoring import layers
from virf.authoring.check_items import (
    ALWAYS_PRESENT,
    category_items,
    empty_scene_facts,
    everywhere_items,
    evidence_items,
    novelty_items,
    reasoner_items,
    twin_items,
)
from virf.authoring.drafts import read_draft
from virf.authoring.models import CheckItem, CheckReport, Related
from virf.authoring.normalize import normalise
from virf.errors import InputError
from virf.migrations import now
from virf.ontology.workspace import LAYERS

if TYPE_CHECKING:
    from virf.authoring.corpus import Corpus
    from virf.authoring.store import CandidateRow, Store
    from virf.authoring.workspace import Workspace


def check(ws: Workspace, cid: int, axiom: str | None = None) -> CheckReport:
    """Normalise and check the candidate's axiom (or an edited one); the
    result is stored as the candidate's latest check."""
    row = ws.store.candidate(cid)
    ws.store.undecided(cid)
    text = row.axiom if axiom is None else axiom
    report = check_row(ws, row, text)
    ws.store.add_check(cid, text, report.passed, report.model_dump(mode="json"))
    return report


def current_axiom(store: Store, cid: int, drafted: str) -> str:
    """The candidate's axiom as checked last (an edit the checks were run on),
    else as drafted."""
    latest = store.latest_check(cid)
    return str(latest["axiom"]) if latest else drafted


def check_row(
    ws: Workspace, row: CandidateRow, axiom: str, decision: Mapping[str, str] | None = None
) -> CheckReport:
    """The checks of ``axiom`` as the candidate's: a drafted rule's, or a
    learned class's.  ``decision`` (reviewer, decision, date) goes into the
    block when the check is the one an acceptance makes."""
    if row.origin == "answer":
        from virf.authoring import learned

        return learned.check(ws, row, axiom, decision)
    return _check_rule(ws, row, axiom, decision)


def report(
    threshold: float,
    axiom: str,
    normalised: str,
    items: Sequence[CheckItem],
    terms: Sequence[Any],
    related: Related,
    layer: str,
    block: str,
) -> CheckReport:
    return CheckReport(
        axiom=axiom,
        normalised=normalised,
        passed=not any(i.severity == "error" for i in items),
        layer=layer,  # type: ignore[arg-type]
        threshold=threshold,
        terms=tuple(terms),
        items=tuple(items),
        related=related,
        module_text=block,
        checked_at=now(),
    )


def _check_rule(
    ws: Workspace, row: CandidateRow, axiom: str, decision: Mapping[str, str] | None
) -> CheckReport:
    from virf.ontology.axiom_check import check_candidate

    rule = row.rule
    name = str(rule["name"])
    parsed_draft = read_draft(row.draft, f"candidate {row.id}")
    items: list[CheckItem] = []
    vocab = ws.tbox().vocabulary

    def done(
        normalised: str, terms: Sequence[Any], related: Related, layer: str, block: str
    ) -> CheckReport:
        return report(ws.threshold, axiom, normalised, items, terms, related, layer, block)

    try:
        normalised = normalise(
            axiom,
            vocab,
            ws.vocabulary_index(vocab),
            declared_parents=parsed_draft.parents(),
            threshold=ws.threshold,
            own_name=name,
        )
    except InputError as exc:
        items.append(CheckItem.error("parses", str(exc)))
        return done("", (), Related(), "core", "")
    items.extend(normalised.problems)
    if name in vocab.classes:
        items.append(
            CheckItem.error(
                "name",
                f"{name} is already a class of the TBox; a candidate must name a new "
                "concept (propose a different name)",
            )
        )
    corpus = ws.corpus()
    items.extend(category_items(rule, vocab.uscs.values()))
    items.extend(evidence_items(corpus, parsed_draft, row.evidence))
    items.extend(twin_items(name, rule.get("twins", ())))
    block = layers.rule_block(
        vocab,
        row.id,
        rule,
        normalised.axiom,
        normalised.new_classes,
        row.evidence,
        evidence_source(corpus, row.evidence, parsed_draft.rules[0].modelling_decision),
        row.drafter,
        decision,
    )
    if any(i.severity == "error" for i in items):
        return done(normalised.display, normalised.terms, Related(), "core", block)
    used = [t.chosen for t in normalised.terms] + [p for _, p in normalised.new_classes]
    result = check_candidate(
        ws.scenario,
        tuple(str(p) for p in ws.layout.modules()),
        layers.candidate_module(ws.layout, block),
        name,
        used,
        vocab.uscs,
        always=ALWAYS_PRESENT,
        scene=empty_scene_facts(vocab),
    )
    items.extend(reasoner_items(result, name, "no situation can ever fall under it"))
    if not result.parses:
        return done(normalised.display, normalised.terms, Related(), "core", block)
    if result.consistent and result.every_state:
        items.append(
            CheckItem.error("trivial", f"{name} holds of everything: every state would be unsafe")
        )
    elif result.consistent and result.satisfiable:
        items.extend(everywhere_items(name, result))
    related = Related(
        equivalent=result.equivalent, subsumed_by=result.subsumed_by, subsumes=result.subsumes
    )
    items.extend(novelty_items(name, related))
    layer = max((result.layers.get(t, "core") for t in used), key=LAYERS.index, default="core")
    # New classes go into the module the rule goes into.
    terms = tuple(
        t.model_copy(update={"layer": layer}) if t.match == "new" and t.role == "class" else t
        for t in normalised.terms
    )
    return done(normalised.display, terms, related, layer, block)


def evidence_source(corpus: Corpus, ids: Sequence[str], modelling_decision: str | None) -> str:
    """The ``:source`` of a rule: the documents and passages it cites, and
    the modelling decision it states."""
    by_doc: dict[str, list[str]] = {}
    for pid in ids:
        passage = corpus.passage(pid)
        if passage is not None:
            by_doc.setdefault(passage.document, []).append(pid)
    parts = []
    for doc_id, pids in by_doc.items():
        doc = corpus.document(doc_id)
        title = f"{doc.publisher}, {doc.title}" if doc else doc_id
        url = f" <{doc.url}>" if doc and doc.url else ""
        parts.append(f"{title}{url}: passages {', '.join(pids)}")
    if modelling_decision:
        parts.append(f"common-sense modelling decision: {modelling_decision}")
    return "; ".join(parts) or "no evidence"
