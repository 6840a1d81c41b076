"""The verification protocol: step attribution, final-state checks, fail closed, engines."""

from __future__ import annotations

import json
import os
from typing import Any

import pytest
from conftest import EXAMPLES_DIR, inst, rel

from virf.api import LogicTutor
from virf.errors import InputError
from virf.reasoning import Classification, Engine, ReasonerFailure, make_engine
from virf.render.feedback import involved_objects
from virf.schema import Fact, Report
from virf.verify.verifier import Verifier
from virf.world.plan import load_plan_file

REFINED = EXAMPLES_DIR / "pedagogical-refined"


def _refined_scene() -> dict[str, Any]:
    data: dict[str, Any] = json.loads((REFINED / "scene.json").read_text(encoding="utf-8"))
    return data


def _contradiction(data: dict[str, Any]) -> dict[str, Any]:
    """Perception also reads the microwave's door as open (it is closed).

    A material read two ways is no longer a contradiction (an object may be
    made of several materials), so the paper's noise test contradicts states."""
    data["assertions"].append(rel("Microwave_1", "hasState", "open", "data_property"))
    return data


def _omission(data: dict[str, Any]) -> dict[str, Any]:
    """The glass bowl was not perceived at all."""
    data["instances"] = [i for i in data["instances"] if i["instance_name"] != "GlassBowl_1"]
    data["assertions"] = [
        a for a in data["assertions"] if "GlassBowl_1" not in (a["subject"], a["object"])
    ]
    return data


def _uncertainty(data: dict[str, Any]) -> dict[str, Any]:
    """The bowl's material could not be recognised."""
    for a in data["assertions"]:
        if a["property"] == "hasMaterial":
            a["object"] = "UnknownMaterial"
    return data


# ---------------------------------------------------------------- noise


@pytest.mark.parametrize("case", ["noise-contradiction", "noise-omission", "noise-uncertainty"])
def test_noise_examples_are_never_safe(example_report, case: str) -> None:
    report = example_report(case)
    assert report.status in ("UNSAFE", "UNKNOWN")
    assert report.questions


@pytest.mark.parametrize("perturb", [_contradiction, _omission, _uncertainty])
def test_noise_perturbations_of_a_safe_plan_are_never_safe(
    paper_tutor, example_report, perturb
) -> None:
    # The paper's noise tests, on the paper's rules (the household rules find
    # the soup left heating at the plan's end, so the baseline is not SAFE there).
    plan = load_plan_file(REFINED / "plan.txt")
    assert example_report(REFINED.name).status == "SAFE"  # the unperturbed baseline
    report = paper_tutor.verify(perturb(_refined_scene()), plan)
    assert report.status == "UNKNOWN"
    assert report.questions


# ---------------------------------------------------------------- step attribution


def _scenario_tutor(request: pytest.FixtureRequest, scenario: str) -> LogicTutor:
    """The session tutor of a scenario: the paper's rules or the household's."""
    return request.getfixturevalue({"paper": "paper_tutor", "kitchen": "tutor"}[scenario])


@pytest.mark.parametrize(
    ("scenario", "rule"),
    [
        ("paper", "ChildNearSharpObjectDanger"),  # the paper's Challenge 2
        ("kitchen", "BreakableOrSharpWithinChildReachDanger"),
    ],
)
def test_initial_hazard_is_step_zero(request, scenario: str, rule: str) -> None:
    tutor = _scenario_tutor(request, scenario)
    scene = {
        "instances": [
            inst("Child", "Toddler_1"),
            inst("Knife", "Knife_1"),
            inst("Bowl", "Bowl_1"),
            inst("CounterTop", "CounterTop_1"),
        ],
        "assertions": [
            rel("Toddler_1", "isNear", "Knife_1"),
            rel("Knife_1", "isOn", "CounterTop_1"),
            rel("Bowl_1", "isOn", "CounterTop_1"),
        ],
    }
    report = tutor.verify(scene, ["find Bowl_1", "pick Bowl_1"])
    assert report.status == "UNSAFE"
    assert report.dangerous_step == 0
    assert report.action is None
    assert report.violated_concept is not None
    assert report.violated_concept.id == rule
    assert report.violations[0].phase == "initial"
    assert report.violations[0].subject == "Toddler_1"
    # Without the knife nearby the same plan is fine.
    scene["assertions"] = scene["assertions"][1:]
    assert tutor.verify(scene, ["find Bowl_1", "pick Bowl_1"]).status == "SAFE"


BURNER = EXAMPLES_DIR / "burner-left-on" / "scene.json"


@pytest.mark.parametrize(
    ("scenario", "rule"),
    [("paper", "StoveBurnerLeftOnEmptyDanger"), ("kitchen", "HeatingSurfaceLeftOnEmptyDanger")],
)
def test_final_state_hazard_only_checked_at_the_end(request, scenario: str, rule: str) -> None:
    tutor = _scenario_tutor(request, scenario)
    scene = tutor.scene(BURNER)
    on = ["find StoveKnob_1", "turn_on StoveKnob_1"]
    later_pot = [
        *on,
        "find Pot_1",
        "pick Pot_1",
        "fillLiquid Pot_1 water",
        "find StoveBurner_1",
        "put StoveBurner_1",
    ]
    report = tutor.verify(scene, later_pot)
    assert rule not in [v.id for v in report.violations]
    assert report.status == "SAFE"
    assert report.trace[1].outcome == "ok"
    # The same burner left empty at the end is flagged at the plan's last step.
    left_on = tutor.verify(scene, on)
    assert left_on.status == "UNSAFE"
    assert left_on.violated_concept is not None
    assert left_on.violated_concept.id == rule
    assert left_on.violations[0].phase == "final"
    assert left_on.dangerous_step == 2
    # ... and switching it off again before the end is fine.
    assert tutor.verify(scene, [*on, "turn_off StoveKnob_1"]).status == "SAFE"


@pytest.mark.parametrize(
    ("scenario", "rule"),
    [
        ("paper", "ThrowActionDanger"),  # the paper's USC-Action: any throw
        ("kitchen", "HardObjectThrownDanger"),  # a thrown pot is hard
    ],
)
def test_definite_finding_beats_earlier_uncertain_one(request, scenario: str, rule: str) -> None:
    tutor = _scenario_tutor(request, scenario)
    scene = tutor.scene(EXAMPLES_DIR / "burner-left-on-open-world" / "scene.json")
    plan = ["find StoveKnob_1", "turn_on StoveKnob_1", "find Pot_1", "pick Pot_1", "throw"]
    report = tutor.verify(scene, plan)
    assert report.status == "UNSAFE"
    assert report.dangerous_step == 5
    assert report.violated_concept is not None
    assert report.violated_concept.id == rule


def test_question_names_object_when_material_assumed(tutor) -> None:
    scene = {"instances": [inst("PhysicalObject", "Thing_1"), inst("Microwave", "Microwave_1")]}
    plan = [
        "find Thing_1",
        "pick Thing_1",
        "find Microwave_1",
        "open Microwave_1",
        "put Microwave_1",
        "close Microwave_1",
        "turn_on Microwave_1",
    ]
    report = tutor.verify(scene, plan)
    assert report.status == "UNKNOWN"
    assert report.violated_concept is not None
    assert report.violated_concept.id == "MicrowaveContainsUnknownMaterialDanger"
    assert any("Thing_1" in q.text for q in report.questions)


@pytest.mark.parametrize("case", ["unknown-material-microwave", "noise-uncertainty"])
def test_question_names_object_of_stated_unknown_material(example_report, case: str) -> None:
    report = example_report(case)
    unknown = [
        t.subject
        for t in report.violations[0].triggering_facts
        if t.predicate == "hasMaterial" and t.object == "UnknownMaterial"
    ]
    assert unknown
    assert any(unknown[0] in q.text for q in report.questions), report.questions


# ---------------------------------------------------------------- fail closed


class FailingEngine(Engine):
    """Delegates to a real engine but raises on the chosen question."""

    name = "failing"

    def __init__(self, inner: Engine, exc: Exception, fail_on: str) -> None:
        super().__init__(inner.tbox)
        self.inner, self.exc, self.fail_on = inner, exc, fail_on

    def _classify(self, facts: list[Fact], concepts: list[str]) -> Classification:
        if self.fail_on == "classify":
            raise self.exc
        return self.inner.classify(facts, concepts)

    def _entails(
        self, facts: list[Fact], concept: str, individual: str, without: frozenset[str]
    ) -> bool:
        if self.fail_on == "entails":
            raise self.exc
        return self.inner.entails(facts, concept, individual, without)

    def _consistent(self, facts: list[Fact], without: frozenset[str]) -> bool:
        if self.fail_on == "consistent":
            raise self.exc
        return self.inner.consistent(facts, without)


def _verify_with(tutor, engine: Engine, case: str, timeout_s: float = 120.0):
    verifier = Verifier(tutor.tbox, engine, timeout_s=timeout_s)
    folder = EXAMPLES_DIR / case
    return verifier.verify(tutor.scene(folder / "scene.json"), load_plan_file(folder / "plan.txt"))


def _assert_error(report) -> None:
    assert report.status == "ERROR"
    assert report.dangerous_step is None
    assert report.violations == ()
    assert report.violated_concept is None
    assert "fail closed" in report.reason


@pytest.mark.parametrize(
    ("exc", "fail_on", "case"),
    [
        (ReasonerFailure("engine crashed"), "classify", "pedagogical-refined"),
        (RuntimeError("boom"), "classify", "pedagogical-refined"),
        (ReasonerFailure("engine crashed"), "entails", "walkthrough"),
        (ValueError("bad"), "entails", "challenge-child"),
        (RuntimeError("boom"), "consistent", "noise-contradiction"),
    ],
)
def test_engine_failure_fails_closed(tutor, exc: Exception, fail_on: str, case: str) -> None:
    report = _verify_with(tutor, FailingEngine(tutor.engine, exc, fail_on), case)
    _assert_error(report)
    assert str(exc) in report.reason
    # The shared tutor is untouched.
    assert tutor.verifier.engine is tutor.engine


def test_failing_engine_wrapper_is_transparent_otherwise(paper_tutor, example_report) -> None:
    # challenge-child reproduces the paper, on its own scenario.
    engine = FailingEngine(paper_tutor.engine, RuntimeError("unused"), "nothing")
    report = _verify_with(paper_tutor, engine, "challenge-child")
    assert report.status == "UNSAFE"
    assert report.model_copy(update={"engine": "fast"}) == example_report("challenge-child")


def test_zero_timeout_fails_closed(tutor) -> None:
    report = _verify_with(tutor, tutor.engine, "pedagogical-refined", timeout_s=0)
    _assert_error(report)
    assert "timed out" in report.reason


# ---------------------------------------------------------------- engines


@pytest.fixture(scope="module")
def paper() -> LogicTutor:
    # Openllet needs minutes per plan on the household rules where HermiT needs
    # seconds, so the two complete reasoners are compared on the hand-written
    # rules here and on the kitchen scenario in make test-full.
    return LogicTutor("paper", engine="reference")


@pytest.mark.parametrize("case", ["walkthrough", "challenge-hot-oil", "pedagogical-refined"])
def test_pellet_agrees_with_hermit(paper, case: str) -> None:
    _pellet_agrees(paper, case, timeout_s=120.0)


@pytest.mark.skipif(os.environ.get("VIRF_FULL") != "1", reason="minutes per plan (make test-full)")
def test_pellet_agrees_with_hermit_on_the_household_rules(tutor) -> None:
    _pellet_agrees(LogicTutor(engine="reference"), "walkthrough", timeout_s=900.0)


def _pellet_agrees(ref: LogicTutor, case: str, timeout_s: float) -> None:
    hermit = _verify_with(ref, ref.engine, case)
    pellet = make_engine("pellet", ref.tbox, timeout_s=timeout_s)
    report = _verify_with(ref, pellet, case, timeout_s=timeout_s)
    assert report.engine == "pellet"
    assert report.status == hermit.status
    assert report.dangerous_step == hermit.dangerous_step
    assert report.violated_concept == hermit.violated_concept
    # Both are complete: the minimal explanation is the same too.
    assert [v.triggering_facts for v in report.violations] == [
        v.triggering_facts for v in hermit.violations
    ]


def test_engine_aliases(tutor) -> None:
    assert make_engine("reference", tutor.tbox).name == "hermit"
    assert make_engine("openllet", tutor.tbox).name == "pellet"


def test_unknown_concept_is_rejected(tutor) -> None:
    with pytest.raises(InputError, match="NoSuchConcept"):
        tutor.engine.classify([], ["NoSuchConcept"])


# ---------------------------------------------------------------- structured facts


def test_closures_reach_the_report_with_their_members(tutor) -> None:
    # Nothing says the microwave holds only the mug, nor that the mug is empty.
    scene = {"instances": [inst("Mug", "Mug_1"), inst("Microwave", "Microwave_1")]}
    plan = ["find Mug_1", "pick Mug_1", "find Microwave_1", "open Microwave_1"]
    plan += ["put Microwave_1", "close Microwave_1", "turn_on Microwave_1"]
    report = tutor.verify(scene, plan)
    assert report.status == "UNKNOWN"
    v = report.violations[0]
    closures = {
        (t.subject, t.relation, t.members) for t in v.triggering_facts if t.members is not None
    }
    assert closures == {("Microwave_1", "contains", ("Mug_1",)), ("Mug_1", "contains", ())}
    assert involved_objects(v) == ["Microwave_1", "Mug_1"]
    contents = next(q for q in report.questions if q.key == "contents:contains:Microwave_1")
    assert contents.fact is not None
    assert Fact.from_triple(contents.fact) == Fact.closure("Microwave_1", "contains", ["Mug_1"])
    # The JSON keeps the notation; reading it back restores the structure.
    assert Report.model_validate_json(report.to_json()) == report
