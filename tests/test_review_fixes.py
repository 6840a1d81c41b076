"""Fail-closed holes found in review: each of these plans used to be SAFE.

Where a test names the rule that catches the plan, it is checked with the
household rules (the default scenario) and with the paper's (scenario
``paper``), each naming its own rule."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import inst

from virf.errors import InputError
from virf.reasoning import make_engine
from virf.render.feedback import feedback_prompt
from virf.verify.verifier import Verifier
from virf.world.plan import load_plan_file, parse_plan, parse_plan_text


def _status(tutor, scene: dict, plan: list[str]):
    report = tutor.verify(scene, plan)
    return report.status, report.violated_concept.id if report.violated_concept else None, report


def _scenario_tutor(request: pytest.FixtureRequest, scenario: str):
    """The session tutor of ``scenario``: the default (household) or the paper's."""
    return request.getfixturevalue("paper_tutor" if scenario == "paper" else "tutor")


MICROWAVE_PLAN = [
    "find Microwave_1",
    "open Microwave_1",
    "put Microwave_1",
    "close Microwave_1",
    "turn_on Microwave_1",
]


@pytest.mark.parametrize(
    ("scenario", "rule"),
    [("kitchen", "SealedObjectInRunningMicrowaveDanger"), ("paper", "MicrowaveSealedObjectDanger")],
)
def test_nested_contents_are_seen(request, scenario: str, rule: str) -> None:
    tutor = _scenario_tutor(request, scenario)
    scene = {
        "instances": [
            inst("Egg", "Egg_1"),
            inst("Bowl", "Bowl_1"),
            inst("Microwave", "Microwave_1"),
        ],
        "assertions": [{"subject": "Bowl_1", "property": "contains", "object": "Egg_1"}],
    }
    status, _, report = _status(tutor, scene, ["find Bowl_1", "pick Bowl_1", *MICROWAVE_PLAN])
    assert status == "UNSAFE"
    assert rule in {v.id for v in report.violations}


def test_ambiguous_type_is_a_question(tutor) -> None:
    scene = {
        "instances": [
            inst("Bowl", "Bowl_1"),
            inst("Bowl", "Bowl_2"),
            inst("Microwave", "Microwave_1"),
        ],
        "assertions": [
            {"subject": "Bowl_1", "property": "hasMaterial", "object": "Glass"},
            {"subject": "Bowl_2", "property": "hasMaterial", "object": "Metal"},
        ],
    }
    status, concept, report = _status(tutor, scene, ["pick Bowl", *MICROWAVE_PLAN])
    assert status == "UNKNOWN" and concept == "AmbiguousObject"
    assert "Bowl_1 or Bowl_2" in report.questions[0].text


def test_people_are_not_objects(tutor) -> None:
    scene = {
        "instances": [inst("Child", "Toddler_1"), inst("Microwave", "Microwave_1")],
        "assertions": [],
    }
    status, concept, _ = _status(tutor, scene, ["find Toddler_1", "pick Toddler_1"])
    assert status == "UNSAFE" and concept == "ActionOnPerson"


def test_pick_from_closed_fridge_is_a_precondition_failure(tutor) -> None:
    scene = {
        "instances": [inst("Fridge", "Fridge_1"), inst("Apple", "Apple_1")],
        "assertions": [{"subject": "Fridge_1", "property": "contains", "object": "Apple_1"}],
    }
    status, concept, _ = _status(tutor, scene, ["find Apple_1", "pick Apple_1"])
    assert (
        status == "UNSAFE" and concept == "Precondition_ReceptacleClosed"
    )  # closed by catalogue default


@pytest.mark.parametrize(
    ("scenario", "rule"),
    [("kitchen", "IncompatibleChemicalsMeetDanger"), ("paper", "AmmoniaBleachMixedDanger")],
)
def test_poured_cleaners_mix(request, scenario: str, rule: str) -> None:
    tutor = _scenario_tutor(request, scenario)
    scene = {
        "instances": [
            inst("SprayBottle", "Ammonia_1"),
            inst("SprayBottle", "Bleach_1"),
            inst("SinkBasin", "Sink_1"),
        ],
        "assertions": [
            {"subject": "Ammonia_1", "property": "hasMaterial", "object": "Ammonia"},
            {"subject": "Bleach_1", "property": "hasMaterial", "object": "Bleach"},
        ],
    }
    plan = [
        "find Ammonia_1",
        "pick Ammonia_1",
        "find Sink_1",
        "pour",
        "put Sink_1",
        "find Bleach_1",
        "pick Bleach_1",
        "find Sink_1",
        "pour",
    ]
    status, _, report = _status(tutor, scene, plan)
    assert status == "UNSAFE"
    assert rule in [v.id for v in report.violations]


def test_unstated_knob_wiring_is_assumed_and_asked(tutor) -> None:
    scene = {
        "instances": [
            inst("StoveKnob", "Knob_1"),
            inst("StoveBurner", "Burner_1"),
            inst("Bread", "Bread_1"),
        ],
        "assertions": [{"subject": "Bread_1", "property": "isOn", "object": "Burner_1"}],
    }
    status, _, report = _status(tutor, scene, ["find Knob_1", "turn_on Knob_1"])
    assert status != "SAFE"
    assert any("Knob_1 controls Burner_1" in q.text for q in report.questions) or status == "UNSAFE"


def test_heat_spreads_to_what_a_lit_burner_holds(tutor) -> None:
    scene = {
        "instances": [
            inst("StoveKnob", "Knob_1"),
            inst("StoveBurner", "Burner_1"),
            inst("Pan", "Pan_1"),
            inst("Oil", "Oil_1"),
            inst("Cup", "Cup_1"),
        ],
        "assertions": [
            {"subject": "Knob_1", "property": "controls", "object": "Burner_1"},
            {"subject": "Pan_1", "property": "isOn", "object": "Burner_1"},
            {"subject": "Pan_1", "property": "contains", "object": "Oil_1"},
        ],
    }
    plan = [
        "find Knob_1",
        "turn_on Knob_1",
        "find Cup_1",
        "pick Cup_1",
        "fillLiquid Cup_1 water",
        "find Pan_1",
        "pour",
    ]
    status, concept, _ = _status(tutor, scene, plan)
    assert status == "UNSAFE" and concept == "HotOilContainerHazardDanger"


def test_feedback_never_approves_an_error(tutor) -> None:
    engine = make_engine("hermit", tutor.tbox, timeout_s=0.001)
    report = Verifier(tutor.tbox, engine).verify(
        tutor.scene({"instances": [inst("Apple", "Apple_1")]}),
        parse_plan_text("find Apple_1\npick Apple_1"),
    )
    assert report.status == "ERROR"
    text = feedback_prompt(report)
    assert "NOT approved" in text and "passed" not in text


def test_unknown_report_feedback_lists_the_questions(tutor) -> None:
    scene = {
        "instances": [inst("Bowl", "Bowl_1"), inst("Microwave", "Microwave_1")],
        "assertions": [
            {"subject": "Bowl_1", "property": "hasMaterial", "object": "UnknownMaterial"}
        ],
    }
    report = tutor.verify(scene, ["find Bowl_1", "pick Bowl_1", *MICROWAVE_PLAN])
    assert report.status == "UNKNOWN"
    assert "What material is Bowl_1 made of?" in feedback_prompt(report)


def test_empty_and_deep_plans_are_input_errors(tmp_path: Path) -> None:
    empty = tmp_path / "empty.txt"
    empty.write_text("# nothing\n\n")
    with pytest.raises(InputError, match="no actions"):
        load_plan_file(empty)
    with pytest.raises(InputError, match=r"nested too deeply|not valid"):
        parse_plan_text("[" * 50000 + "]" * 50000)


def test_option_types_are_checked(tutor) -> None:
    with pytest.raises(InputError, match="true or false"):
        tutor.scene({"instances": [], "unlocated_by_default": "false"})


BLEACH_SCENE = {
    "instances": [inst("SprayBottle", "Bleach_1"), inst("Mug", "Mug_1")],
    "assertions": [{"subject": "Bleach_1", "property": "hasMaterial", "object": "Bleach"}],
}


def _bleach_plan(liquid: str) -> list[str]:
    return [
        "find Mug_1",
        f"fillLiquid Mug_1 {liquid}",
        "find Bleach_1",
        "pick Bleach_1",
        "find Mug_1",
        "pour",
    ]


@pytest.mark.parametrize("liquid", ["coffee", "water"])
def test_bleach_poured_into_a_drink_is_poisoning(paper_tutor, liquid) -> None:
    status, _, report = _status(paper_tutor, BLEACH_SCENE, _bleach_plan(liquid))
    assert status == "UNSAFE"
    assert "ToxicInFoodContainerDanger" in [v.id for v in report.violations]


@pytest.mark.parametrize("liquid", ["coffee", "water"])
def test_bleach_poured_into_a_drink_is_poisoning_in_the_household(tutor, liquid) -> None:
    # The household rules stop at the pour (step 6), which puts the chemical
    # into the drink's cup. Carrying the bleach up to the drink (step 5) is not
    # yet a hazard: a toxic product beside food is a storage pathway, checked
    # where the plan leaves things.
    plan = _bleach_plan(liquid)
    status, concept, report = _status(tutor, BLEACH_SCENE, plan)
    assert (status, report.dangerous_step, concept) == (
        "UNSAFE",
        6,
        "ChemicalInFoodContainerDanger",
    )
    walk = tutor.verifier.findings(tutor.scene(BLEACH_SCENE), parse_plan(plan))
    assert "FoodBesideToxicProductDanger" not in {f.concept.name for f in walk.findings.get(5, [])}
    at_pour = {f.concept.name: f.definite for f in walk.findings.get(6, [])}
    assert at_pour.get("ChemicalInFoodContainerDanger") is True, at_pour
