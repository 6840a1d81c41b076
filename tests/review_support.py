"""An in-memory stand-in for the review workspace: the API tests and the
browser tests drive the review server against it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from virf.authoring.models import (
    AcceptedRule,
    CandidateSummary,
    CandidateView,
    CheckItem,
    CheckReport,
    Decision,
    DecisionView,
    Evidence,
    Preview,
    PreviewChange,
    Related,
    RuleDraft,
    Status,
    TermChoice,
)
from virf.errors import EnvironmentProblem, InputError

NOW = "2025-01-02T03:04:05+00:00"
DRAFT = "StoveBurner and (hasState some OnState) and (supports some PaperTowel)"


@dataclass
class FakeCandidate:
    id: int
    name: str
    axiom: str
    status: Status = "pending"
    evidence: tuple[Evidence, ...] = ()
    check: CheckReport | None = None
    decision: DecisionView | None = None


@dataclass
class FakeWorkspace:
    """The review API of ``Workspace`` over a dict; records what it was asked.

    An axiom containing ``Broken`` fails its checks; one containing ``NoJava``
    raises the error a missing Java runtime raises."""

    items: dict[int, FakeCandidate] = field(default_factory=dict)
    calls: list[tuple[Any, ...]] = field(default_factory=list)

    def add(self, name: str, axiom: str = DRAFT, **kw: Any) -> FakeCandidate:
        cid = len(self.items) + 1
        self.items[cid] = FakeCandidate(cid, name, axiom, **kw)
        return self.items[cid]

    def _get(self, cid: int) -> FakeCandidate:
        if cid not in self.items:
            raise InputError(f"no candidate {cid}; the workspace has 1-{len(self.items)}")
        return self.items[cid]

    def _summary(self, c: FakeCandidate) -> CandidateSummary:
        return CandidateSummary(
            id=c.id,
            name=c.name,
            category="fire",
            drafter="person:ana",
            query="paper towel near a burner",
            created_at=NOW,
            status=c.status,
            passed=None if c.check is None else c.check.passed,
        )

    def candidates(self, status: Status | None = None) -> list[CandidateSummary]:
        self.calls.append(("candidates", status))
        return [self._summary(c) for c in self.items.values() if status in (None, c.status)]

    def summary(self, cid: int) -> CandidateSummary:
        return self._summary(self._get(cid))

    def candidate(self, cid: int) -> CandidateView:
        c = self._get(cid)
        return CandidateView(
            summary=self._summary(c),
            rule=RuleDraft(
                name=c.name,
                definition=c.axiom,
                kind="state",
                category="fire",
                danger_level="high",
                description="A paper towel on a lit burner can catch fire.",
                safety_warning="Keep paper and cloth away from a lit burner.",
                trigger_reason="A paper towel lies on a burner that is on.",
                suggestion="Move the paper towel away before turning the burner on.",
                check_at="any",
            ),
            evidence=c.evidence,
            retrieved=tuple(e.passage_id for e in c.evidence),
            draft={"name": c.name},
            check=c.check,
            preview=None,
            decision=c.decision,
        )

    def opened(self, cid: int, reviewer: str) -> None:
        self._get(cid)
        self.calls.append(("opened", cid, reviewer))

    def recheck(self, cid: int, axiom: str) -> CheckReport:
        c = self._get(cid)
        self.calls.append(("recheck", cid, axiom))
        if "NoJava" in axiom:
            raise EnvironmentProblem("Java is not installed; install a Java 11+ runtime")
        c.check = report(axiom)
        return c.check

    def preview(
        self,
        cid: int,
        axiom: str | None = None,
        tasks: Path | None = None,
        examples: Path | None = None,
    ) -> Preview:
        c = self._get(cid)
        self.calls.append(("preview", cid, axiom))
        return Preview(
            axiom=axiom or c.axiom,
            examples=3,
            tasks=0,
            tasks_file=None,
            changes=(
                PreviewChange(
                    item="example walkthrough",
                    instruction="heat the pan",
                    before="SAFE",
                    after="UNSAFE",
                    concept=c.name,
                ),
            ),
            computed_at=NOW,
        )

    def decide(
        self,
        cid: int,
        decision: Decision,
        *,
        reviewer: str,
        reason: str | None = None,
        axiom: str | None = None,
    ) -> DecisionView:
        c = self._get(cid)
        self.calls.append(("decide", cid, decision, reviewer, reason, axiom))
        if c.status != "pending":
            raise InputError(f"candidate {cid} was already decided")
        if decision == "reject" and not reason:
            raise InputError("rejecting needs a reason")
        if decision == "accept":
            checked = report(axiom or c.axiom)
            if not checked.passed:
                raise InputError(f"cannot accept candidate {cid}: {checked.items[-1].message}")
        c.status = "accepted" if decision == "accept" else "rejected"
        if axiom is not None:
            c.axiom = axiom
        c.decision = DecisionView(
            decision=decision,
            edit="minor" if axiom is not None else "none",
            axiom=axiom or c.axiom,
            reason=reason,
            reviewer=reviewer,
            decided_at=NOW,
            seconds=12.5,
        )
        return c.decision

    def rules(self) -> list[AcceptedRule]:
        return [
            AcceptedRule(
                id=f"KB-{c.id}",
                name=c.name,
                layer="scenario",
                axiom=c.axiom,
                category="fire",
                evidence=tuple(e.passage_id for e in c.evidence),
                drafter="person:ana",
                reviewer=c.decision.reviewer,
                edit=c.decision.edit,
                decided_at=NOW,
                candidate_id=c.id,
            )
            for c in self.items.values()
            if c.status == "accepted" and c.decision is not None
        ]


def report(axiom: str) -> CheckReport:
    broken = "Broken" in axiom
    return CheckReport(
        axiom=axiom,
        normalised=axiom.replace("PaperTowel", "Towel"),
        passed=not broken,
        layer="scenario",
        threshold=0.8,
        terms=(
            TermChoice(
                term="PaperTowel",
                role="class",
                match="similar",
                chosen="Towel",
                score=0.86,
                alternatives=(("Towel", 0.86), ("Paper", 0.71)),
            ),
            TermChoice(
                term="Kindling",
                role="class",
                match="new",
                chosen="Kindling",
                parent="FlammableObject",
                layer="domain",
            ),
        ),
        items=(
            CheckItem(name="syntax", ok=True, severity="error", message="parsed"),
            CheckItem(
                name="satisfiable",
                ok=not broken,
                severity="error",
                message="" if not broken else "the concept is unsatisfiable",
            ),
        ),
        related=Related(subsumed_by=("FlammableOnLitBurnerDanger",)),
        module_text=f"Class: PaperTowelOnBurnerDanger\n    EquivalentTo: {axiom}",
        checked_at=NOW,
    )


def found(pid: str) -> Evidence:
    return Evidence(
        passage_id=pid,
        found=True,
        document_id="nfpa-cooking-safety",
        document_title="Cooking safety",
        publisher="NFPA",
        section="Keep it clear",
        text="Keep anything that can catch fire away from the stovetop.",
    )


def sample_workspace() -> FakeWorkspace:
    ws = FakeWorkspace()
    ws.add("PaperTowelOnBurnerDanger", evidence=(found("nfpa-cooking-safety#3"),))
    ws.add(
        "CurtainNearBurnerDanger",
        evidence=(found("nfpa-cooking-safety#4"), Evidence(passage_id="gone#1", found=False)),
    )
    done = ws.add("KnifeOnFloorDanger", status="rejected")
    done.decision = DecisionView(
        decision="reject",
        edit="none",
        axiom=None,
        reason="duplicate of an existing rule",
        reviewer="bo",
        decided_at=NOW,
        seconds=3.0,
    )
    return ws
