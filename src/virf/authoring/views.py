"""What a workspace shows of its candidates and rules: the queue, one
candidate with its evidence, checks, preview and decision, and the accepted
rules, as the view models the terminal and the review page share.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from virf.authoring.decisions import decision_view
from virf.authoring.models import (
    AcceptedRule,
    CandidateSummary,
    CandidateView,
    CheckReport,
    Evidence,
    Preview,
    RuleDraft,
    Status,
)
from virf.authoring.store import CandidateRow, status_of

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace


def candidates(ws: Workspace, status: Status | None = None) -> list[CandidateSummary]:
    statuses = ws.store.statuses()
    out = []
    for cid, st in statuses.items():
        if status is not None and st != status:
            continue
        out.append(_summary(ws.store.candidate(cid), st, ws.store.latest_check(cid)))
    return out


def _summary(row: CandidateRow, status: str, latest: dict[str, Any] | None) -> CandidateSummary:
    return CandidateSummary(
        id=row.id,
        name=row.name,
        category=str(row.rule["category"]),
        drafter=row.drafter,
        query=row.query,
        created_at=row.created_at,
        status=status,  # type: ignore[arg-type]
        passed=None if latest is None else bool(latest["passed"]),
        origin=row.origin,  # type: ignore[arg-type]
    )


def summary(ws: Workspace, cid: int) -> CandidateSummary:
    """The candidate's queue entry (InputError for an unknown id)."""
    row = ws.store.candidate(cid)  # first: it refuses an id no candidate can have
    decision = ws.store.decision(cid)
    return _summary(
        row,
        status_of(decision.decision if decision else None),
        ws.store.latest_check(cid),
    )


def candidate(ws: Workspace, cid: int) -> CandidateView:
    row = ws.store.candidate(cid)
    check = ws.store.latest_check(cid)
    preview = ws.store.latest_preview(cid)
    decision = ws.store.decision(cid)
    status = status_of(decision.decision if decision else None)
    learned = None
    if row.origin == "answer":
        from virf.authoring.learned import learned_of

        learned = learned_of(row)
    return CandidateView(
        summary=_summary(row, status, check),
        rule=RuleDraft(**row.rule),
        evidence=evidence(ws, row.evidence),
        retrieved=row.retrieved,
        draft=row.draft,
        check=CheckReport.model_validate(check) if check else None,
        preview=Preview.model_validate(preview) if preview else None,
        decision=decision_view(decision) if decision else None,
        learned=learned,
    )


def evidence(ws: Workspace, ids: Sequence[str]) -> tuple[Evidence, ...]:
    """The passages ``ids`` cite, with their documents; one the corpus lacks is marked so."""
    corpus = ws.corpus()
    out = []
    for pid in ids:
        passage = corpus.passage(pid)
        if passage is None:
            out.append(Evidence(passage_id=pid, found=False))
            continue
        doc = corpus.document(passage.document)
        out.append(
            Evidence(
                passage_id=pid,
                found=True,
                document_id=passage.document,
                document_title=doc.title if doc else "",
                publisher=doc.publisher if doc else "",
                url=doc.url if doc else "",
                section=passage.section,
                text=passage.text,
            )
        )
    return tuple(out)


def rules(ws: Workspace) -> list[AcceptedRule]:
    out = []
    for d in ws.store.decisions():
        if d.decision != "accept":
            continue
        row = ws.store.candidate(d.candidate_id)
        out.append(
            AcceptedRule(
                id=row.name,
                name=row.name,
                layer=d.layer or "core",  # type: ignore[arg-type]
                axiom=d.axiom or row.axiom,
                category=str(row.rule["category"]),
                evidence=row.evidence,
                drafter=row.drafter,
                reviewer=d.reviewer,
                edit=d.edit,  # type: ignore[arg-type]
                decided_at=d.created_at,
                candidate_id=d.candidate_id,
            )
        )
    return out
