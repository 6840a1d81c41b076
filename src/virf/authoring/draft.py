"""Drafting: evidence retrieved for a question, turned into candidate rules by
an LLM with the paper's knowledge-engineering prompt.

The drafter is an apprentice of :mod:`virf.planner` (``openai:MODEL``,
``replay:FILE``, ``scripted``), so drafting shares the planner's client,
retries, replay files and run log.  A draft is keyed in replay files and the
run log by ``task_id`` = ``draft:<slug of the question>``, iteration 1,
method ``kb-draft``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from virf.authoring.drafts import Draft, parse_reply
from virf.errors import InputError
from virf.files import read_prompt
from virf.ontology.tbox import Vocabulary

if TYPE_CHECKING:
    from virf.authoring.corpus import Hit
    from virf.planner.apprentices import Apprentice

METHOD: Final = "kb-draft"
ATTRIBUTE_RELATIONS: Final = ("hasState", "hasMaterial", "hasProperty")
# Relations the prompt leaves out: the action ontology's roles, which no
# state-based rule needs, and inverses a rule can express the other way.
_HIDDEN_RELATIONS: Final = frozenset(
    {
        "hasActor",
        "hasAgent",
        "hasInstrument",
        "hasParticipant",
        "hasPatient",
        "hasTarget",
        "isAgentIn",
        "isInstrumentIn",
        "isPatientIn",
        "isTargetOf",
        "participatesIn",
        "isMadeOf",
    }
)


def task_id(query: str) -> str:
    slug = re.sub(r"[^a-z0-9]+", "-", query.lower()).strip("-")[:60]
    return f"draft:{slug or 'query'}"


def _template() -> str:
    return read_prompt("virf.authoring", "draft_system.txt")


def _below(vocab: Vocabulary, root: str) -> list[str]:
    return sorted(
        c
        for c in vocab.classes
        if c != root and vocab.is_a(c, root) and c not in vocab.class_synonyms
    )


def system_prompt(vocab: Vocabulary) -> str:
    """The knowledge-engineering prompt with the current TBox's vocabulary."""
    relations = sorted(vocab.object_properties - _HIDDEN_RELATIONS)
    uscs = set(vocab.uscs) | set(vocab.preconditions)
    objects = [c for c in _below(vocab, "PhysicalObject") if c not in uscs]
    categories = [c for c in objects if c not in vocab.catalogue_types]
    return _template().format(
        spatial_relations=", ".join(r for r in relations if r not in ATTRIBUTE_RELATIONS),
        attribute_relations=", ".join(r for r in ATTRIBUTE_RELATIONS if r in relations),
        categories=", ".join(categories),
        object_types=", ".join(sorted(vocab.catalogue_types)),
        materials=", ".join(_below(vocab, "Material")),
        attributes=", ".join(_below(vocab, "Attribute")),
        states=", ".join(_below(vocab, "State")),
        hazard_categories=", ".join(sorted({u.category for u in vocab.uscs.values()})),
    )


def user_prompt(query: str, hits: Sequence[Hit]) -> str:
    lines = [f"Question: {query}", "", "Evidence passages:"]
    for hit in hits:
        doc = hit.document
        lines.append(
            f"[{hit.passage.id}] {doc.title} ({doc.publisher}), section {hit.passage.section}:"
        )
        lines.append(hit.passage.text)
        lines.append("")
    lines.append("Draft the safety rules these passages support, as the JSON object described.")
    return "\n".join(lines)


@dataclass(frozen=True)
class Drafted:
    draft: Draft | None
    problem: str  # why there is no draft ("" when there is one)
    reply: str | None


def ask_drafter(
    apprentice: Apprentice, vocab: Vocabulary, query: str, hits: Sequence[Hit]
) -> Drafted:
    """One request to the drafter; a reply that is not a usable draft is
    reported, not raised, so the audit can count it."""
    # Here, not at the top: the rest of authoring runs without the planner's
    # clients, and an apprentice in hand means they are loaded already.
    from virf.planner.apprentices import Purpose

    if not hits:
        raise InputError("no evidence retrieved for the question; add documents to the corpus")
    proposal = apprentice.propose(
        [
            {"role": "system", "content": system_prompt(vocab)},
            {"role": "user", "content": user_prompt(query, hits)},
        ],
        task_id=task_id(query),
        iteration=1,
        method=METHOD,
        purpose=Purpose.DRAFT,
    )
    if not proposal.ok or proposal.text is None:
        return Drafted(None, proposal.reason or "no reply", None)
    try:
        return Drafted(parse_reply(proposal.text), "", proposal.text)
    except InputError as exc:
        return Drafted(None, str(exc), proposal.text)
