"""The drafter's JSON, checked at the edge.

The shape follows the paper's knowledge-engineering prompt (objects,
materials, attributes, states, dangers, relations, and ``propertyChains``
whose ``definition`` is a Manchester class expression), extended with what
every Unsafe State Concept carries here (category, danger level, warning,
trigger reason, suggestion) and the evidence passages each rule relies on.
A person's proposal (``virf kb propose FILE``) is the same document.
"""

from __future__ import annotations

import json
import re
from typing import Any, Final, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from virf.authoring.models import RuleDraft
from virf.errors import InputError, clip, hidden_char, parse_json, printable
from virf.ontology.tbox import DANGER_LEVELS, USC_KINDS

MAX_RULES: Final = 20
_NAME: Final = re.compile(r"^[A-Z][A-Za-z0-9_]{2,80}$")


class _Edge(BaseModel):
    # Models answer in camelCase and add keys of their own; unknown keys are
    # kept out of the way rather than refused.
    model_config = ConfigDict(extra="ignore", populate_by_name=True, frozen=True)


class DraftTerm(_Edge):
    name: str = Field(alias="class", min_length=1, max_length=100)
    subclass_of: str | None = Field(default=None, alias="subclassOf", max_length=100)


class DraftRule(_Edge):
    name: str = Field(alias="equivalentClass")
    definition: str = Field(min_length=1, max_length=4000)
    category: str = Field(min_length=1, max_length=80)
    danger_level: Literal["low", "medium", "high", "critical"] = Field(alias="dangerLevel")
    kind: Literal["state-based", "action-based", "logical-inconsistency", "uncertainty"] = (
        "state-based"
    )
    check_at: Literal["always", "final"] = Field(default="always", alias="checkAt")
    description: str = Field(min_length=1, max_length=500)
    safety_warning: str = Field(alias="safetyWarning", min_length=1, max_length=500)
    trigger_reason: str = Field(alias="triggerReason", min_length=1, max_length=500)
    suggestion: str = Field(min_length=1, max_length=500)
    evidence: tuple[str, ...] = ()
    modelling_decision: str | None = Field(default=None, alias="modellingDecision", max_length=500)
    # "SOURCE -> VULNERABLE via PATHWAY", and the minimal pairs 'WORLD | PLAN |
    # OLD => NEW' (virf.verify.twins) that show the rule turning on it.
    mechanism: str | None = Field(default=None, max_length=300)
    # An uncertainty rule's question about what it cannot decide ({x}: the
    # individual it holds for).
    question: str | None = Field(default=None, max_length=300)
    twins: tuple[str, ...] = Field(default=(), max_length=8)

    @field_validator("twins")
    @classmethod
    def _one_line_each(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        out = []
        for text in value:
            flat = " ".join(text.split())
            if not flat or hidden_char(flat) is not None or len(flat) > 2000:
                raise ValueError("each twin must be one line of at most 2000 visible characters")
            out.append(flat)
        return tuple(out)

    @field_validator(
        "category",
        "description",
        "safety_warning",
        "trigger_reason",
        "suggestion",
        "modelling_decision",
        "definition",
        "mechanism",
        "question",
    )
    @classmethod
    def _one_line(cls, value: str | None) -> str | None:
        # Annotation texts become one-line Manchester literals and report
        # lines: line breaks and tabs are spaces, other hidden characters refused.
        if value is None:
            return None
        flat = " ".join(value.split())
        bad = hidden_char(flat)
        if bad is not None:
            raise ValueError(f"contains the hidden character {printable(bad)}")
        if not flat:
            raise ValueError("must not be blank")
        return flat

    @field_validator("name")
    @classmethod
    def _class_name(cls, value: str) -> str:
        if not _NAME.match(value):
            raise ValueError(
                f"rule name '{clip(value)}' must be a class name in UpperCamelCase "
                "(letters, digits, underscores), e.g. CandleNearCurtainDanger"
            )
        return value

    def as_rule(self) -> RuleDraft:
        return RuleDraft(
            name=self.name,
            definition=self.definition,
            kind=self.kind,
            category=self.category,
            danger_level=self.danger_level,
            description=self.description,
            safety_warning=self.safety_warning,
            trigger_reason=self.trigger_reason,
            suggestion=self.suggestion,
            check_at=self.check_at,
            mechanism=self.mechanism or "",
            twins=self.twins,
            question=self.question or "",
        )


class Draft(_Edge):
    objects: tuple[DraftTerm, ...] = ()
    materials: tuple[DraftTerm, ...] = ()
    attributes: tuple[DraftTerm, ...] = ()
    states: tuple[DraftTerm, ...] = ()
    dangers: tuple[DraftTerm, ...] = ()
    rules: tuple[DraftRule, ...] = Field(alias="propertyChains", min_length=1, max_length=MAX_RULES)
    evidence: tuple[str, ...] = ()

    def parents(self) -> dict[str, str]:
        """The parent the drafter proposed for each class it named."""
        out: dict[str, str] = {}
        for group in (self.objects, self.materials, self.attributes, self.states, self.dangers):
            for term in group:
                if term.subclass_of:
                    out.setdefault(term.name, term.subclass_of)
        return out

    def evidence_of(self, rule: DraftRule) -> tuple[str, ...]:
        return rule.evidence or self.evidence


assert set(DANGER_LEVELS) == {"low", "medium", "high", "critical"}
assert set(USC_KINDS) == {"state-based", "action-based", "logical-inconsistency", "uncertainty"}


def read_draft(data: object, what: str) -> Draft:
    """A draft document, or one line naming its first problem."""
    try:
        return Draft.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "the document"
        message = str(first["msg"]).removeprefix("Value error, ")
        if first["type"] == "missing":
            message = "is missing"
        raise InputError(f"{what}: {where} {message}") from None


_FENCE: Final = re.compile(r"```(?:json)?\s*(.*?)```", re.DOTALL)


def parse_reply(text: str) -> Draft:
    """A model's reply as a draft: the JSON object in it (inside a code fence,
    or the outermost braces), checked like a person's proposal."""
    fenced = _FENCE.search(text)
    body = fenced.group(1) if fenced else text
    start, end = body.find("{"), body.rfind("}")
    if start < 0 or end < start:
        raise InputError("the drafter's reply holds no JSON object")
    data: Any = parse_json(body[start : end + 1], "the drafter's reply")
    return read_draft(data, "the drafter's reply")


def rule_json(draft: Draft, rule: DraftRule) -> dict[str, Any]:
    """One rule of a draft as stored with its candidate: the rule and the
    terms it introduced, in the drafter's own keys."""
    full: dict[str, Any] = json.loads(draft.model_dump_json(by_alias=True))
    own = json.loads(rule.model_dump_json(by_alias=True))
    full["propertyChains"] = [own]
    return full
