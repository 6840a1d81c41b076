"""What the workflow shows a reviewer, as data: the terminal, ``--json`` and the
review page all render these models, so each fact about a candidate is read
from the store in one place (:class:`virf.authoring.workspace.Workspace`)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict

Status = Literal["pending", "accepted", "rejected"]
Decision = Literal["accept", "reject"]
EditSize = Literal["none", "minor", "major"]
Layer = Literal["core", "domain", "scenario"]
Severity = Literal["error", "warning", "info"]
Match = Literal["exact", "synonym", "similar", "new"]
Role = Literal["class", "property", "individual"]


class View(BaseModel):
    model_config = ConfigDict(frozen=True)


class Evidence(View):
    """A passage a candidate cites, as the corpus holds it now."""

    passage_id: str
    found: bool
    document_id: str = ""
    document_title: str = ""
    publisher: str = ""
    url: str = ""
    section: str = ""
    text: str = ""


class TermChoice(View):
    """How one term of a drafted axiom was matched to the vocabulary."""

    term: str
    role: Role
    match: Match
    chosen: str
    score: float | None = None
    # Nearest vocabulary entries with their similarity, best first.
    alternatives: tuple[tuple[str, float], ...] = ()
    # New classes only: where the class would go.
    parent: str | None = None
    layer: Layer | None = None


class CheckItem(View):
    name: str
    ok: bool
    severity: Severity
    message: str

    @classmethod
    def error(cls, name: str, message: str) -> CheckItem:
        return cls(name=name, ok=False, severity="error", message=message)

    @classmethod
    def warning(cls, name: str, message: str, *, ok: bool = True) -> CheckItem:
        return cls(name=name, ok=ok, severity="warning", message=message)

    @classmethod
    def info(cls, name: str, message: str) -> CheckItem:
        return cls(name=name, ok=True, severity="info", message=message)


class Related(View):
    """Existing Unsafe State Concepts the candidate's concept coincides with."""

    equivalent: tuple[str, ...] = ()
    subsumed_by: tuple[str, ...] = ()  # the candidate is a special case of these
    subsumes: tuple[str, ...] = ()  # the candidate generalises these


class CheckReport(View):
    """Normalisation and logical checks of one version of a candidate's axiom."""

    axiom: str  # as given (drafted or edited)
    normalised: str  # after term matching, Manchester syntax with short names ("" if unreadable)
    passed: bool  # no check failed with severity "error"
    layer: Layer
    threshold: float  # embedding similarity a term needed to be matched
    terms: tuple[TermChoice, ...]
    items: tuple[CheckItem, ...]
    related: Related
    module_text: str  # the Manchester block that accepting would add
    checked_at: str


class PreviewChange(View):
    item: str  # "example walkthrough" or "unsafe_detailed.jsonl:12"
    instruction: str = ""
    before: str
    after: str
    concept: str | None = None


class Preview(View):
    """Verdicts that change if the candidate is accepted."""

    axiom: str
    examples: int
    tasks: int
    tasks_file: str | None
    changes: tuple[PreviewChange, ...]
    computed_at: str
    error: str | None = None


class DecisionView(View):
    decision: Decision
    edit: EditSize
    axiom: str | None
    reason: str | None
    reviewer: str
    decided_at: str
    seconds: float | None
    layer: Layer | None = None  # where an accepted axiom went


class CandidateSummary(View):
    id: int
    name: str
    category: str
    drafter: str
    query: str | None
    created_at: str
    status: Status
    passed: bool | None  # None: not checked yet


class RuleDraft(View):
    """The USC a candidate proposes, with the annotations every USC carries."""

    name: str
    definition: str
    kind: str
    category: str
    danger_level: str
    description: str
    safety_warning: str
    trigger_reason: str
    suggestion: str
    check_at: str
    # The mechanism the rule states, and its minimal pairs (virf kb test);
    # candidates stored before they existed have neither.
    mechanism: str = ""
    twins: tuple[str, ...] = ()
    question: str = ""


class CandidateView(View):
    summary: CandidateSummary
    rule: RuleDraft
    evidence: tuple[Evidence, ...]
    retrieved: tuple[str, ...]  # passage ids shown to the drafter
    draft: dict[str, object]  # the drafter's JSON for this rule, as received
    check: CheckReport | None
    preview: Preview | None
    decision: DecisionView | None


class AcceptedRule(View):
    id: str
    name: str
    layer: Layer
    axiom: str
    category: str
    evidence: tuple[str, ...]
    drafter: str
    reviewer: str
    edit: EditSize
    decided_at: str
    candidate_id: int
