"""Frozen types passed between the stages.

``Fact`` is the unit of world knowledge inside VIRF (scene, simulator and
reasoner all speak it).  ``Report`` and its parts form the diagnostic report of
the paper's Appendix E, as pydantic models so that they serialise to JSON
deterministically.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

from pydantic import BaseModel, ConfigDict

TYPE = "type"


class FactKind(StrEnum):
    TYPE = "type"  # subject rdf:type object(class)
    OBJECT = "object"  # object property assertion
    DATA = "data"  # data property assertion, object is a literal
    CLOSURE = "closure"  # subject's predicate-successors are exactly the listed members


class Provenance(StrEnum):
    SCENE = "scene"  # stated by the scene
    DEFAULT = "default"  # a catalogue default applied because the scene was silent
    PLAN = "plan"  # produced by simulating the plan (or the robot's own bookkeeping)
    ASSUMED = "assumed"  # a hypothesis under the open world: needs confirmation


@dataclass(frozen=True, order=True)
class Fact:
    """One ABox assertion.  For CLOSURE facts ``object`` is a comma-joined,
    sorted member list ('' for none)."""

    subject: str
    predicate: str
    object: str
    kind: FactKind = FactKind.OBJECT

    def members(self) -> tuple[str, ...]:
        return tuple(m for m in self.object.split(",") if m)

    def render(self) -> str:
        if self.kind is FactKind.TYPE:
            return f"{self.subject} is a {self.object}"
        if self.kind is FactKind.CLOSURE:
            inside = ", ".join(self.members())
            return (
                f"{self.subject} {self.predicate} only {{{inside}}}"
                if inside
                else (f"{self.subject} {self.predicate} nothing")
            )
        return f"{self.subject} {self.predicate} {self.object}"

    @classmethod
    def from_triple(cls, t: Triple) -> Fact:
        """Inverse of :meth:`triple`."""
        if t.predicate == "rdf:type":
            return cls(t.subject, "type", t.object, FactKind.TYPE)
        if t.predicate.endswith(" only"):
            members = ",".join(m.strip() for m in t.object.strip("{}").split(",") if m.strip())
            return cls(t.subject, t.predicate.removesuffix(" only"), members, FactKind.CLOSURE)
        if t.object in ("true", "false"):
            return cls(t.subject, t.predicate, t.object, FactKind.DATA)
        return cls(t.subject, t.predicate, t.object, FactKind.OBJECT)

    def triple(self) -> Triple:
        if self.kind is FactKind.TYPE:
            return Triple(subject=self.subject, predicate="rdf:type", object=self.object)
        if self.kind is FactKind.CLOSURE:
            inside = ", ".join(self.members())
            return Triple(
                subject=self.subject, predicate=f"{self.predicate} only", object=f"{{{inside}}}"
            )
        return Triple(subject=self.subject, predicate=self.predicate, object=self.object)


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Triple(_Frozen):
    subject: str
    predicate: str
    object: str


class BackgroundKnowledge(_Frozen):
    """TBox knowledge (or a catalogue default) a proof relied on."""

    id: str
    text: str
    source: str


Status = Literal["SAFE", "UNSAFE", "UNKNOWN", "ERROR"]
Phase = Literal[
    "initial",
    "action",
    "state",
    "final",
    "precondition",
    "missing-object",
    "inconsistency",
    "requirement",
    "error",
]


class Violation(_Frozen):
    """One finding at one step."""

    id: str
    name: str
    kind: str
    category: str
    danger_level: str
    description: str
    safety_warning: str
    trigger_reason: str
    suggestion: str
    source: str
    step: int
    phase: Phase
    subject: str
    definite: bool
    message: str
    triggering_facts: tuple[Triple, ...] = ()
    assumed_facts: tuple[Triple, ...] = ()
    # The scene's own statements behind triggering facts it wrote another way
    # (a state individual, an inverse relation, a material class).
    as_written: tuple[Triple, ...] = ()
    background: tuple[BackgroundKnowledge, ...] = ()


class ViolatedConcept(_Frozen):
    id: str
    description: str


class CausalChain(_Frozen):
    message: str
    triggering_facts: tuple[Triple, ...]
    background: tuple[BackgroundKnowledge, ...] = ()


class StepTrace(_Frozen):
    step: int
    action: str
    outcome: Literal["ok", "unsafe", "unknown", "not-checked", "not-simulated", "error"]
    findings: tuple[str, ...] = ()
    added: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()


QuestionKind = Literal[
    "material",  # what is X made of (an UnknownMaterial marker)
    "fill",  # does X hold liquid (an UnknownFillState marker)
    "contents",  # are X's listed contents complete (an open-world closure)
    "confirm",  # is an assumed fact true
    "which",  # which instance a plan's type word means (several fit)
    "where",  # where an object the plan needs but the scene lacks is
    "contradiction",  # which of the scene's contradictory facts is wrong
    "requirement",  # does the plan meet a requirement VIRF cannot read
    "other",  # a rule's question that no scene datum answers yet
]


class Question(_Frozen):
    """One question for the user behind an UNKNOWN verdict.

    ``key`` is stable across runs (answers files are keyed by it); ``options``
    lists the accepted answers when they form a closed set, and is empty when
    the answer is free."""

    key: str
    kind: QuestionKind
    text: str
    subject: str
    fact: Triple | None = None
    options: tuple[str, ...] = ()
    step: int | None = None


class Report(_Frozen):
    """The Logic Tutor's verdict on one plan (paper, Appendix E, extended)."""

    status: Status
    dangerous_step: int | None
    action: str | None
    violated_concept: ViolatedConcept | None
    causal_chain: CausalChain | None
    violations: tuple[Violation, ...]
    questions: tuple[Question, ...]
    suggestion: str | None
    danger_level: str | None
    category: str | None
    reason: str
    plan: tuple[str, ...]
    trace: tuple[StepTrace, ...]
    engine: str
    scenario: str

    def to_json(self) -> str:
        return self.model_dump_json(indent=2)
