"""The report model refuses reports whose verdict its own findings contradict,
and triples carry a closure's structure beside the notation their JSON keeps."""

from __future__ import annotations

import json
from typing import Any

import pytest
from pydantic import ValidationError

from virf.schema import Fact, FactKind, Question, Report, Triple, Violation


def violation(step: int, definite: bool) -> Violation:
    return Violation(
        id="HotSurfaceContact",
        name="HotSurfaceContact",
        kind="state",
        category="Burn",
        danger_level="high",
        description="Something touches a hot surface.",
        safety_warning="Hot surfaces burn.",
        trigger_reason="a hot surface touches it",
        suggestion="Turn the stove off first.",
        source="test",
        step=step,
        phase="state",
        subject="Pot_1",
        definite=definite,
        message="Pot_1 is on a lit burner.",
    )


QUESTION = Question(
    key="material:Bowl_1",
    kind="material",
    text="What material is Bowl_1 made of?",
    subject="Bowl_1",
    step=2,
)


def report(**changes: Any) -> Report:
    fields: dict[str, Any] = {
        "status": "SAFE",
        "dangerous_step": None,
        "action": None,
        "violated_concept": None,
        "causal_chain": None,
        "violations": (),
        "questions": (),
        "suggestion": None,
        "danger_level": None,
        "category": None,
        "reason": "test",
        "plan": ("find Pot_1", "pick Pot_1", "put Pot_1 on Stove_1"),
        "trace": (),
        "engine": "fast",
        "scenario": "kitchen",
    }
    return Report(**{**fields, **changes})


VALID = {
    "safe": {},
    "unsafe": {"status": "UNSAFE", "dangerous_step": 3, "violations": (violation(3, True),)},
    "unsafe with an earlier question": {
        "status": "UNSAFE",
        "dangerous_step": 3,
        "violations": (violation(3, False), violation(3, True)),
        "questions": (QUESTION,),
    },
    "unknown": {
        "status": "UNKNOWN",
        "dangerous_step": 2,
        "violations": (violation(2, False),),
        "questions": (QUESTION,),
    },
    "error": {"status": "ERROR", "reason": "reasoner failure (fail closed)"},
}

INVALID = {
    "safe with a violation": (
        {"violations": (violation(3, False),)},
        "a SAFE report has no violations",
    ),
    "safe with a question": ({"questions": (QUESTION,)}, "a SAFE report has no questions"),
    "safe with a dangerous step": ({"dangerous_step": 2}, "a SAFE report has no dangerous step"),
    "unsafe without violations": (
        {"status": "UNSAFE", "dangerous_step": 3},
        "needs at least one definite violation",
    ),
    "unsafe with only uncertain violations": (
        {"status": "UNSAFE", "dangerous_step": 3, "violations": (violation(3, False),)},
        "needs at least one definite violation",
    ),
    "unsafe without a dangerous step": (
        {"status": "UNSAFE", "violations": (violation(3, True),)},
        r"must be the step of a definite violation \(3\), got None",
    ),
    "unsafe at the step of an uncertain violation": (
        {
            "status": "UNSAFE",
            "dangerous_step": 2,
            "violations": (violation(2, False), violation(3, True)),
        },
        r"must be the step of a definite violation \(3\), got 2",
    ),
    "unknown without questions": (
        {"status": "UNKNOWN", "dangerous_step": 2, "violations": (violation(2, False),)},
        "an UNKNOWN report needs at least one question",
    ),
}


@pytest.mark.parametrize("changes", VALID.values(), ids=VALID.keys())
def test_consistent_reports_are_accepted(changes: dict[str, Any]) -> None:
    built = report(**changes)
    assert Report.model_validate_json(built.to_json()) == built


@pytest.mark.parametrize(("changes", "message"), INVALID.values(), ids=INVALID.keys())
def test_contradictory_reports_are_refused(changes: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        report(**changes)


def test_a_report_read_from_json_is_checked_too() -> None:
    data = json.loads(report(**VALID["unknown"]).to_json())
    data["status"] = "SAFE"
    with pytest.raises(ValidationError, match="a SAFE report has no violations"):
        Report.model_validate_json(json.dumps(data))


def test_a_closure_triple_keeps_its_notation_and_its_structure() -> None:
    fact = Fact.closure("Fridge_1", "contains", ["Egg_1", "Apple_1"])
    t = fact.triple()
    assert json.loads(t.model_dump_json()) == {
        "subject": "Fridge_1",
        "predicate": "contains only",
        "object": "{Apple_1, Egg_1}",
    }
    assert (t.relation, t.members) == ("contains", ("Apple_1", "Egg_1"))
    back = Triple.model_validate_json(t.model_dump_json())
    assert back == t and Fact.from_triple(back) == fact
    empty = Fact.closure("Robot_1", "isHolding", []).triple()
    assert (empty.object, empty.members) == ("{}", ())
    assert Triple.model_validate_json(empty.model_dump_json()) == empty


def test_other_triples_have_no_members() -> None:
    t = Triple(subject="Pot_1", predicate="hasMaterial", object="Metal")
    assert (t.relation, t.members) == ("hasMaterial", None)
    assert t == Fact("Pot_1", "hasMaterial", "Metal").triple()
    assert Fact.from_triple(t) == Fact("Pot_1", "hasMaterial", "Metal")


def test_a_triple_whose_structure_contradicts_its_notation_is_refused() -> None:
    with pytest.raises(ValueError, match="does not match"):
        Triple(
            subject="Fridge_1",
            predicate="contains only",
            object="{Apple_1}",
            relation="contains",
            members=("Egg_1",),
        )


def test_closure_facts_are_built_with_their_members() -> None:
    with pytest.raises(ValueError, match="closure fact"):
        Fact("Fridge_1", "contains", "Apple_1,Egg_1", FactKind.CLOSURE)
    with pytest.raises(ValueError, match="only a closure fact has members"):
        Fact("Fridge_1", "contains", "Apple_1", FactKind.OBJECT, ("Apple_1",))


def test_closures_sort_by_their_members_in_the_object_place() -> None:
    # The order explanations are minimised in and reports list facts in.
    closure = Fact.closure("Fridge_1", "contains", ["Apple_1", "Egg_1"])
    apple = Fact("Fridge_1", "contains", "Apple_1")
    egg = Fact("Fridge_1", "contains", "Egg_1")
    assert sorted([egg, closure, apple]) == [apple, closure, egg]
