"""How candidates enter a workspace: rules drafted by a model from retrieved
evidence, rules a person proposes in a draft document, and classes learned
from a user's answers.  Each is stored (all of one draft or none) and, unless
asked not to, checked at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from virf.authoring import checks
from virf.authoring.drafts import Draft, read_draft, rule_json
from virf.errors import InputError, read_json_file

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace
    from virf.planner.apprentices import Apprentice


def draft(
    ws: Workspace, query: str, apprentice: Apprentice, *, k: int = 5, check: bool = True
) -> tuple[list[int], str]:
    """Retrieve evidence for ``query``, ask the drafter, store each rule
    as a candidate (and check it).  Returns the candidate ids and, when
    the reply was unusable, why."""
    from virf.authoring.draft import ask_drafter

    query = query.strip()
    if not query:
        raise InputError("the question is empty; say what the rules should be about")
    hits = ws.corpus().search(query, k=k)
    drafted = ask_drafter(apprentice, ws.tbox().vocabulary, query, hits)
    ws.store.add_event("drafted", actor=apprentice.label, detail=query)
    if drafted.draft is None:
        ws.store.add_event(
            "draft_failed", actor=apprentice.label, detail=f"{query}: {drafted.problem}"
        )
        return [], drafted.problem
    ids = _store_draft(
        ws,
        drafted.draft,
        query=query,
        drafter=apprentice.label,
        kind="llm",
        retrieved=[h.passage.id for h in hits],
    )
    if check:
        for cid in ids:
            checks.check(ws, cid)
    return ids, ""


def propose(ws: Workspace, path: Path, author: str, *, check: bool = True) -> list[int]:
    """A person's candidate rules, from a draft document."""
    draft = read_draft(read_json_file(path, "proposal"), f"proposal {path}")
    return propose_draft(ws, draft, author, check=check)


def propose_draft(ws: Workspace, draft: Draft, author: str, *, check: bool = True) -> list[int]:
    ids = _store_draft(
        ws, draft, query=None, drafter=f"person:{author}", kind="person", retrieved=[]
    )
    if check:
        for cid in ids:
            checks.check(ws, cid)
    return ids


def propose_learned(
    ws: Workspace, classes: Sequence[tuple[str, str, dict[str, Any], dict[str, Any]]], who: str
) -> list[int]:
    """Store classes learned from ``who``'s answers (origin "answer"), each
    ``(name, superclass expression, rule fields, learned document)`` as
    :mod:`virf.authoring.learn` makes them; all or none."""
    ids = []
    with ws.store.transaction() as conn:
        for name, axiom, rule, document in classes:
            ids.append(
                ws.store.add_candidate(
                    query=None,
                    drafter=f"answer:{who}",
                    drafter_kind="person",
                    name=name,
                    axiom=axiom,
                    rule=rule,
                    draft=document,
                    evidence=[],
                    retrieved=[],
                    origin="answer",
                    conn=conn,
                )
            )
    for cid, (name, *_rest) in zip(ids, classes, strict=True):
        ws.store.add_event("learned", cid, actor=who, detail=name)
    return ids


def _store_draft(
    ws: Workspace,
    draft: Draft,
    *,
    query: str | None,
    drafter: str,
    kind: str,
    retrieved: Sequence[str],
) -> list[int]:
    ids = []
    with ws.store.transaction() as conn:
        for rule in draft.rules:
            ids.append(
                ws.store.add_candidate(
                    query=query,
                    drafter=drafter,
                    drafter_kind=kind,
                    name=rule.name,
                    axiom=rule.definition,
                    rule=rule.as_rule().model_dump(),
                    draft=rule_json(draft, rule),
                    evidence=draft.evidence_of(rule),
                    retrieved=retrieved,
                    conn=conn,
                )
            )
    return ids
