"""Learning from answers, without a reasoner: what a user's answers about
open-world objects say about their classes (virf.authoring.learn), the
answer rounds of ``virf verify --answers`` (virf.planner.questions.settle),
and the answers a ``virf plan`` run's transcript holds."""

from __future__ import annotations

import json
import re
from typing import Any

import pytest
from conftest import inst, rel
from learn_support import ELECTRIC, HAIR_DRYER, HAIR_DRYER_PLAN, TODDLER

from virf.api import LogicTutor
from virf.authoring.learn import (
    answered_from_transcript,
    check_who,
    class_name,
    lessons,
    scene_digest,
)
from virf.errors import InputError
from virf.ontology import manchester
from virf.planner.loop import Turn
from virf.planner.questions import settle
from virf.schema import Question, Report

TWO_DRYERS: dict[str, Any] = {
    "instances": [
        inst("HairDryer", "HairDryer_1"),
        inst("hair dryer", "HairDryer_2"),
        inst("SinkBasin", "SinkBasin_1"),
    ],
    "assertions": [
        rel("SinkBasin_1", "hasState", "filled"),
        rel("HairDryer_1", "isNear", "SinkBasin_1"),
        rel("HairDryer_2", "isNear", "SinkBasin_1"),
    ],
}
GIZMO: dict[str, Any] = {
    "instances": [inst("Microwave", "Microwave_1"), inst("Gizmo", "Gizmo_1")],
    "assertions": [rel("Microwave_1", "contains", "Gizmo_1")],
}


def verifier(tutor: LogicTutor, plan: list[str]) -> Any:
    return lambda data: tutor.verify(tutor.scene(dict(data)), plan)


def answered(
    tutor: LogicTutor, scene: dict[str, Any], plan: list[str], answers: dict[str, str]
) -> tuple[Report, list[tuple[Question, str]]]:
    done = settle(scene, verifier(tutor, plan), answers, tutor.tbox.vocabulary)
    return done.report, list(done.answered)


# ---------------------------------------------------------------------- names
@pytest.mark.parametrize(
    ("word", "name"),
    [
        ("HairDryer", "HairDryer"),
        ("hair dryer", "HairDryer"),
        ("hair_dryer", "HairDryer"),
        ("space-heater", "SpaceHeater"),
        ("toddler", "Toddler"),
        ("TV", "TV"),
    ],
)
def test_a_class_word_becomes_an_upper_camel_case_name(word: str, name: str) -> None:
    assert class_name(word) == name


@pytest.mark.parametrize("word", ["x", "9lives", "", "hair/dryer"])
def test_a_word_that_cannot_be_a_class_name_is_refused_in_one_line(word: str) -> None:
    with pytest.raises(InputError, match=r"cannot learn the class .*UpperCamelCase"):
        class_name(word)


def test_who_answered_is_one_visible_line() -> None:
    assert check_who("  Ana \n Lima ") == "Ana Lima"
    for bad, words in (
        ("", "say who answered"),
        ("ana\x1b[2J", "hidden character \\x1b"),
        ("a" * 101, "longer than 100 characters"),
    ):
        with pytest.raises(InputError, match=re.escape(words)):
            check_who(bad)


def test_the_scene_digest_does_not_depend_on_key_order() -> None:
    a = {"instances": [], "assertions": [], "name": "x"}
    b = {"name": "x", "assertions": [], "instances": []}
    assert scene_digest(a) == scene_digest(b) and len(scene_digest(a)) == 64
    assert scene_digest(a) != scene_digest({**a, "name": "y"})


def test_conjuncts_split_a_top_level_conjunction_only() -> None:
    assert manchester.conjuncts("PhysicalObject and (hasProperty value Fragile)") == [
        "PhysicalObject",
        "(hasProperty value Fragile)",
    ]
    assert manchester.conjuncts("A and (B or C)", prefix=":") == [":A", "(:B or :C)"]
    # 'and' binds tighter than 'or': this is not a conjunction at the top.
    assert manchester.conjuncts("A and B or C") == ["A and B or C"]


# ---------------------------------------------------------------------- answer rounds
def test_answers_settle_the_question_and_the_plan_is_verified_again(tutor: LogicTutor) -> None:
    first = tutor.verify(tutor.scene(HAIR_DRYER), HAIR_DRYER_PLAN)
    assert first.status == "UNKNOWN" and [q.key for q in first.questions] == [ELECTRIC]
    report, settled = answered(tutor, HAIR_DRYER, HAIR_DRYER_PLAN, {ELECTRIC: "Yes"})
    assert report.status == "UNSAFE" and report.dangerous_step == 2
    assert [(q.key, value) for q, value in settled] == [(ELECTRIC, "yes")]
    report, settled = answered(tutor, HAIR_DRYER, HAIR_DRYER_PLAN, {ELECTRIC: "no"})
    assert report.status == "SAFE" and [v for _, v in settled] == ["no"]


def test_settle_keeps_open_what_has_no_answer_and_names_unused_keys(tutor: LogicTutor) -> None:
    given = {"confirm:HairDryer_1 hasProperty ElectricalyPowered": "yes"}
    done = settle(HAIR_DRYER, verifier(tutor, HAIR_DRYER_PLAN), given, tutor.tbox.vocabulary)
    assert done.report.status == "UNKNOWN" and done.answered == () and done.rounds == 0
    assert done.unused(given) == list(given) and ELECTRIC in done.asked
    with pytest.raises(InputError, match=f"answer to '{ELECTRIC}': 'perhaps' is not yes or no"):
        settle(
            HAIR_DRYER,
            verifier(tutor, HAIR_DRYER_PLAN),
            {ELECTRIC: "perhaps"},
            tutor.tbox.vocabulary,
        )


# ---------------------------------------------------------------------- what is learned
def test_a_yes_to_a_property_is_learned_with_the_default_parent(tutor: LogicTutor) -> None:
    _, settled = answered(tutor, HAIR_DRYER, HAIR_DRYER_PLAN, {ELECTRIC: "yes"})
    [lesson] = lessons(HAIR_DRYER, settled, tutor.tbox.vocabulary, scene_name="bathroom")
    assert lesson.name == "HairDryer" and lesson.instances == ("HairDryer_1",)
    assert lesson.axiom == "PhysicalObject and (hasProperty value ElectricallyPowered)"
    assert lesson.axioms == (
        "HairDryer SubClassOf PhysicalObject",
        "HairDryer SubClassOf hasProperty value ElectricallyPowered",
    )
    [said] = lesson.answers
    assert (said.question, said.answer) == ("Is HairDryer_1 an electrical appliance?", "yes")
    assert said.effect == "HairDryer SubClassOf hasProperty value ElectricallyPowered"
    # WordNet also guessed a heat source; nobody was asked, and a known
    # class would stop guessing it: the reviewer is told.
    assert lesson.unconfirmed == ("a heat source (not asked)",)
    assert "hair dryer" in lesson.reading


def test_a_no_is_kept_but_teaches_nothing(tutor: LogicTutor) -> None:
    _, settled = answered(tutor, HAIR_DRYER, HAIR_DRYER_PLAN, {ELECTRIC: "no"})
    assert lessons(HAIR_DRYER, settled, tutor.tbox.vocabulary) == []


def test_answers_that_disagree_between_objects_of_a_class_give_no_axiom(
    tutor: LogicTutor,
) -> None:
    plan = ["turn_on HairDryer_1", "turn_on HairDryer_2"]
    other = ELECTRIC.replace("HairDryer_1", "HairDryer_2")
    _, settled = answered(tutor, TWO_DRYERS, plan, {ELECTRIC: "yes", other: "no"})
    assert lessons(TWO_DRYERS, settled, tutor.tbox.vocabulary) == []
    # The same answer for both ('HairDryer' and 'hair dryer' are one class).
    _, settled = answered(tutor, TWO_DRYERS, plan, {ELECTRIC: "yes", other: "yes"})
    [lesson] = lessons(TWO_DRYERS, settled, tutor.tbox.vocabulary)
    assert lesson.words == ("HairDryer", "hair dryer")
    assert lesson.instances == ("HairDryer_1", "HairDryer_2")
    assert lesson.restrictions == ("hasProperty value ElectricallyPowered",)


def test_a_confirmed_type_is_the_parent(tutor: LogicTutor) -> None:
    question = "confirm:Toddler_1 rdf:type Child"
    report, settled = answered(tutor, TODDLER, ["turn_on Toaster_1"], {question: "yes"})
    assert report.status == "UNSAFE"
    [lesson] = lessons(TODDLER, settled, tutor.tbox.vocabulary)
    assert (lesson.name, lesson.parents, lesson.restrictions) == ("Toddler", ("Child",), ())
    assert lesson.axiom == "Child"
    assert lesson.answers[0].question == "Is Toddler_1 a child?"


def test_a_material_answer_is_learned(tutor: LogicTutor) -> None:
    report, settled = answered(tutor, GIZMO, ["turn_on Microwave_1"], {"material:Gizmo_1": "metal"})
    assert report.status == "UNSAFE"
    [lesson] = lessons(GIZMO, settled, tutor.tbox.vocabulary)
    assert lesson.axiom == "PhysicalObject and (hasMaterial value Metal)"
    assert lesson.answers[0].effect == "Gizmo SubClassOf hasMaterial value Metal"


def test_a_scene_without_open_world_objects_teaches_nothing(tutor: LogicTutor) -> None:
    scene = {"instances": [inst("Toaster", "Toaster_1")], "assertions": []}
    assert lessons(scene, [], tutor.tbox.vocabulary) == []


def test_the_answers_of_a_plan_run_are_read_from_its_transcript(tutor: LogicTutor) -> None:
    report = tutor.verify(tutor.scene(HAIR_DRYER), HAIR_DRYER_PLAN)
    [q] = report.questions
    turns = [
        Turn(0, "apprentice", "proposal", "\n".join(HAIR_DRYER_PLAN)),
        Turn(0, "tutor", "questions", q.text, data={"questions": [q.model_dump(mode="json")]}),
        Turn(0, "user", "answers", json.dumps({ELECTRIC: "Y"}), data={"settled": [ELECTRIC]}),
        Turn(1, "apprentice", "proposal", "find HairDryer_1"),
    ]
    got, plan = answered_from_transcript(turns, tutor.tbox.vocabulary)
    assert [(x.key, v) for x, v in got] == [(ELECTRIC, "yes")]
    assert plan == tuple(HAIR_DRYER_PLAN)
    unsettled = [*turns[:2], Turn(0, "user", "answers", "{}", data={"settled": []})]
    assert answered_from_transcript(unsettled, tutor.tbox.vocabulary)[0] == []
