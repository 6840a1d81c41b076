"""The audit: the workspace's funnel from drafts to accepted axioms, the
paper's Table (AI synthesiser / human arbiter) for this workspace."""

from __future__ import annotations

import statistics
from collections import Counter
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace


class Stage(BaseModel):
    model_config = ConfigDict(frozen=True)

    stage: str
    count: int
    share: float | None  # of the candidates drafted
    description: str


class Audit(BaseModel):
    model_config = ConfigDict(frozen=True)

    funnel: tuple[Stage, ...]
    draft_requests: int
    unusable_drafts: tuple[str, ...]
    by_drafter: dict[str, dict[str, int]]
    rejection_reasons: tuple[tuple[int, str], ...]
    decision_seconds_median: float | None
    decision_seconds_mean: float | None
    timed_decisions: int


def audit(ws: Workspace) -> Audit:
    store = ws.store
    ids = store.candidate_ids()
    statuses = store.statuses()
    decisions = {d.candidate_id: d for d in store.decisions()}
    normalised = passed = 0
    by_drafter: dict[str, Counter[str]] = {}
    for cid in ids:
        first = store.first_check(cid)
        if first is not None:
            problems = [i for i in first["items"] if i["name"] == "normalisation" and not i["ok"]]
            normalised += bool(first["normalised"]) and not problems
            passed += bool(first["passed"])
        row = store.candidate(cid)
        d = decisions.get(cid)
        outcome = (
            "pending" if d is None else d.decision if d.decision == "reject" else f"accept-{d.edit}"
        )
        # A class learned from answers counts apart from the drafts.
        kind = "answer" if row.origin == "answer" else row.drafter_kind
        by_drafter.setdefault(kind, Counter())[outcome] += 1
        by_drafter[kind]["drafted"] += 1
    total = len(ids)

    def count(pred: Any) -> int:
        return sum(1 for d in decisions.values() if pred(d))

    stages = [
        ("Candidates drafted", total, "rules drafted by the LLM or proposed by a person"),
        ("Normalised", normalised, "every term matched to the vocabulary or placed as a new class"),
        ("Passed automatic checks", passed, "parses, consistent, satisfiable, evidence found"),
        (
            "Accepted (no edit)",
            count(lambda d: d.decision == "accept" and d.edit == "none"),
            "accepted as drafted",
        ),
        (
            "Accepted (minor edit)",
            count(lambda d: d.decision == "accept" and d.edit == "minor"),
            "names changed, structure kept (URI alignment, spelling)",
        ),
        (
            "Accepted (major edit)",
            count(lambda d: d.decision == "accept" and d.edit == "major"),
            "structure changed (scope, restrictions)",
        ),
        ("Rejected", count(lambda d: d.decision == "reject"), "with the reviewer's reason"),
        ("Pending", sum(1 for s in statuses.values() if s == "pending"), "awaiting a decision"),
    ]
    seconds = [d.seconds for d in decisions.values() if d.seconds is not None]
    failed = tuple(store.event_details("draft_failed"))
    return Audit(
        funnel=tuple(
            Stage(stage=s, count=c, share=round(c / total, 4) if total else None, description=t)
            for s, c, t in stages
        ),
        draft_requests=store.count_events("drafted"),
        unusable_drafts=failed,
        by_drafter={k: dict(sorted(v.items())) for k, v in sorted(by_drafter.items())},
        rejection_reasons=tuple(
            (d.candidate_id, d.reason or "") for d in decisions.values() if d.decision == "reject"
        ),
        decision_seconds_median=round(statistics.median(seconds), 1) if seconds else None,
        decision_seconds_mean=round(statistics.fmean(seconds), 1) if seconds else None,
        timed_decisions=len(seconds),
    )
