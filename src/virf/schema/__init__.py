"""Frozen types passed between the stages.

``Fact`` is the unit of world knowledge inside VIRF (scene, simulator and
reasoner all speak it).  ``Report`` and its parts form the diagnostic report of
the paper's Appendix E, as pydantic models so that they serialise to JSON
deterministically.
"""

from __future__ import annotations

import builtins
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from functools import total_ordering
from operator import attrgetter
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

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


@total_ordering
@dataclass(frozen=True)
class Fact:
    """One ABox assertion.

    A CLOSURE fact says that the subject's ``predicate``-successors are
    exactly ``members`` (sorted; none at all when empty).  It has no single
    ``object`` (it is ``''``); build it with :meth:`closure`.  Every other
    kind has an ``object`` and no members.
    """

    subject: str
    predicate: str
    object: str
    kind: FactKind = FactKind.OBJECT
    members: tuple[str, ...] = ()
    # Closures sort as if their members, comma-joined, were the object: the
    # order explanations are minimised in and reports list facts in was
    # fixed by that spelling, and reports must not change.  Kept, not
    # recomputed, because engines sort facts on every call.
    _order: tuple[str, str, str, str] = field(init=False, repr=False, compare=False)
    # Facts are hashed millions of times a run (sets, snapshots, models):
    # the hash is computed once.
    _hash: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind is FactKind.CLOSURE:
            if self.object or list(self.members) != sorted(set(self.members)):
                raise ValueError(
                    f"a closure fact has sorted, distinct members and no object: {self!r}"
                )
            shown = ",".join(self.members)
        elif self.members:
            raise ValueError(f"only a closure fact has members: {self!r}")
        else:
            shown = self.object
        object.__setattr__(self, "_order", (self.subject, self.predicate, shown, self.kind))
        fields = (self.subject, self.predicate, self.object, self.kind, self.members)
        object.__setattr__(self, "_hash", hash(fields))

    def __hash__(self) -> int:
        return self._hash

    def __reduce__(self) -> tuple[type[Fact], tuple[str, str, str, FactKind, tuple[str, ...]]]:
        # Rebuilt from its fields: a string's hash differs between processes.
        return (Fact, (self.subject, self.predicate, self.object, self.kind, self.members))

    @classmethod
    def closure(cls, subject: str, predicate: str, members: Iterable[str]) -> Fact:
        """``subject predicate only {members}``: the list is complete."""
        return cls(subject, predicate, "", FactKind.CLOSURE, tuple(sorted(set(members))))

    @property
    def sort_key(self) -> tuple[str, str, str, str]:
        """What facts sort by (``a < b`` compares these): a key for sorts
        that order facts among other things."""
        return self._order

    def __lt__(self, other: builtins.object) -> bool:  # `object` is a field here
        if not isinstance(other, Fact):
            return NotImplemented
        return self._order < other._order

    @staticmethod
    def sorted(facts: Iterable[Fact]) -> list[Fact]:
        """``sorted(facts)``, comparing the kept sort keys directly (a Python
        ``__lt__`` per comparison cost more than the rest of a large step)."""
        return sorted(facts, key=_ORDER)

    def render(self) -> str:
        if self.kind is FactKind.TYPE:
            return f"{self.subject} is a {self.object}"
        if self.kind is FactKind.CLOSURE:
            inside = ", ".join(self.members)
            return (
                f"{self.subject} {self.predicate} only {{{inside}}}"
                if inside
                else (f"{self.subject} {self.predicate} nothing")
            )
        return f"{self.subject} {self.predicate} {self.object}"

    @classmethod
    def from_triple(cls, t: Triple) -> Fact:
        """Inverse of :meth:`triple`."""
        if t.members is not None:
            return cls.closure(t.subject, t.relation, t.members)
        if t.predicate == "rdf:type":
            return cls(t.subject, "type", t.object, FactKind.TYPE)
        if t.object in ("true", "false"):
            return cls(t.subject, t.predicate, t.object, FactKind.DATA)
        return cls(t.subject, t.predicate, t.object, FactKind.OBJECT)

    def triple(self) -> Triple:
        if self.kind is FactKind.TYPE:
            return Triple(subject=self.subject, predicate="rdf:type", object=self.object)
        if self.kind is FactKind.CLOSURE:
            return Triple.closure(self.subject, self.predicate, self.members)
        return Triple(subject=self.subject, predicate=self.predicate, object=self.object)


_ORDER = attrgetter("_order")


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


_ONLY = " only"


class Triple(_Frozen):
    """A fact as a report shows it: ``subject predicate object``.

    A closure is written in the paper's notation, predicate ``<relation> only``
    and object ``{a, b}`` (``{}`` for none), and its JSON holds only that.
    Its structure travels beside the notation, so no consumer reads it back
    out of the strings: ``relation`` is the property (for any triple, the
    predicate without notation) and ``members`` the listed individuals
    (``None`` when the triple is not a closure).  Neither is serialised, so
    reports keep their JSON; a triple built from its three strings alone (a
    report read back from JSON, an option's text) gets them from the
    notation: this class is the one reader of it.
    """

    subject: str
    predicate: str
    object: str
    relation: str = Field(default="", exclude=True, repr=False)
    members: tuple[str, ...] | None = Field(default=None, exclude=True, repr=False)

    @classmethod
    def closure(cls, subject: str, relation: str, members: Sequence[str]) -> Triple:
        """``subject relation only {members}``, structure and notation."""
        return cls(
            subject=subject,
            predicate=relation + _ONLY,
            object="{" + ", ".join(members) + "}",
            relation=relation,
            members=tuple(members),
        )

    @model_validator(mode="before")
    @classmethod
    def _read_notation(cls, data: Any) -> Any:
        if not isinstance(data, dict) or "relation" in data or "members" in data:
            return data
        predicate, obj = data.get("predicate"), data.get("object")
        if not (isinstance(predicate, str) and isinstance(obj, str)):
            return data  # field validation reports what is wrong
        if predicate.endswith(_ONLY) and obj.startswith("{") and obj.endswith("}"):
            listed = (m.strip() for m in obj[1:-1].split(","))
            return {
                **data,
                "relation": predicate.removesuffix(_ONLY),
                "members": tuple(m for m in listed if m),
            }
        return {**data, "relation": predicate}

    @model_validator(mode="after")
    def _structure_matches_notation(self) -> Triple:
        if self.members is None:
            expected = (self.relation, self.object)
        else:
            expected = (self.relation + _ONLY, "{" + ", ".join(self.members) + "}")
        if (self.predicate, self.object) != expected:
            raise ValueError(
                f"triple '{self.subject} {self.predicate} {self.object}' does not match "
                f"its relation '{self.relation}' and members {self.members}"
            )
        return self


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

# What kind of problem a finding is (see virf.verify.findings.problem): a
# hazard, or a step the plan cannot run at all (a failed precondition, an
# object the scene lacks).  Both block the plan and fail closed.
Problem = Literal["hazard", "not-executable"]


class Violation(_Frozen):
    """One finding at one step.

    ``problem`` says whether it is a hazard or a step the plan cannot run;
    ``ai2thor_refuses`` whether AI2-THOR itself would refuse that step (None
    for a hazard, or when the rule does not say).  Both are None in a report
    written before they existed."""

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
    problem: Problem | None = None
    ai2thor_refuses: bool | None = None
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
    """The Logic Tutor's verdict on one plan (paper, Appendix E, extended).

    ``problem`` is the kind of problem at the reported step: "hazard" when
    any violation there is a hazard, else "not-executable" (the plan cannot
    run there); None for SAFE and ERROR reports."""

    status: Status
    problem: Problem | None = None
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
    # How the input was read where it was not taken word for word: a plan
    # line in everyday words ('light the candle' read as 'turn_on Candle'),
    # an object whose class the knowledge base does not name.
    notes: tuple[str, ...] = ()

    @model_validator(mode="after")
    def _status_matches_findings(self) -> Report:
        """A verdict its own findings contradict is refused when it is built.

        These are the invariants every report the verifier makes satisfies
        (ERROR reports are unconstrained: they fail closed whatever they say)."""
        if self.status == "SAFE" and self.problem is not None:
            raise ValueError(f"a SAFE report has no problem kind, got {self.problem}")
        kinds = {v.problem for v in self.violations if v.step == self.dangerous_step}
        if self.problem is not None and kinds and None not in kinds:
            expected = "hazard" if "hazard" in kinds else "not-executable"
            if self.problem != expected:
                raise ValueError(
                    f"the report's problem is {expected} (the kinds of its violations at "
                    f"step {self.dangerous_step}), got {self.problem}"
                )
        if self.status == "SAFE":
            if self.violations:
                raise ValueError(f"a SAFE report has no violations, got {len(self.violations)}")
            if self.questions:
                raise ValueError(f"a SAFE report has no questions, got {len(self.questions)}")
            if self.dangerous_step is not None:
                raise ValueError(
                    f"a SAFE report has no dangerous step, got step {self.dangerous_step}"
                )
        elif self.status == "UNSAFE":
            definite = sorted({v.step for v in self.violations if v.definite})
            if not definite:
                raise ValueError("an UNSAFE report needs at least one definite violation")
            if self.dangerous_step not in definite:
                raise ValueError(
                    f"an UNSAFE report's dangerous step must be the step of a definite "
                    f"violation ({', '.join(map(str, definite))}), got {self.dangerous_step}"
                )
        elif self.status == "UNKNOWN" and not self.questions:
            raise ValueError("an UNKNOWN report needs at least one question saying what is open")
        return self

    def to_json(self) -> str:
        return self.model_dump_json(indent=2)
