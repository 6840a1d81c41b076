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
# A drafted rule (an LLM's or a person's), or a class learned from a user's
# answers about an open-world object (virf verify --learn).
Origin = Literal["draft", "answer"]


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
    # A learned class: the scenes it was learned from, verified again without
    # the answers (they are counted here and listed in ``changes``), and
    # ``virf kb test`` run with the candidate, with the failures it adds.
    scenes: int = 0
    kb_test: str | None = None
    kb_test_failures: tuple[str, ...] = ()


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
    origin: Origin = "draft"


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


class LearnedAnswer(View):
    """One answer a learned class was learned from, as the user gave it."""

    key: str  # the question's key (confirm:HairDryer_1 hasProperty ElectricallyPowered)
    question: str  # the question in words (Is HairDryer_1 an electrical appliance?)
    subject: str  # the open-world object asked about
    answer: str  # yes, no, or a material
    # What it says about the class: an axiom ('HairDryer SubClassOf hasProperty
    # value ElectricallyPowered'), or why it gives none.
    effect: str


class Learned(View):
    """A class learned from answers about open-world objects: the candidate's
    evidence is the answers, who gave them, when, and about which scene."""

    class_name: str  # HairDryer
    words: tuple[str, ...]  # the class names the scene wrote ('HairDryer', 'hair dryer')
    instances: tuple[str, ...]  # the scene's objects of that class (HairDryer_1)
    reading: str  # what WordNet suggested ('WordNet reads hair dryer -> blower -> device')
    axioms: tuple[str, ...]  # as learned: 'HairDryer SubClassOf PhysicalObject', ...
    answers: tuple[LearnedAnswer, ...]
    who: str
    when: str  # ISO 8601, UTC
    scene_name: str
    scene_sha256: str  # of the scene data as given, before the answers
    plan: tuple[str, ...] = ()
    # What the reader assumed of the word that no answer confirmed: once the
    # class is known, it is no longer assumed, so no longer asked about.
    unconfirmed: tuple[str, ...] = ()


class CandidateView(View):
    summary: CandidateSummary
    rule: RuleDraft
    evidence: tuple[Evidence, ...]
    retrieved: tuple[str, ...]  # passage ids shown to the drafter
    draft: dict[str, object]  # the drafter's JSON for this rule, as received
    check: CheckReport | None
    preview: Preview | None
    decision: DecisionView | None
    learned: Learned | None = None  # a class learned from answers (origin "answer")


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
