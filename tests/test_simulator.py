"""The sandbox simulator: preconditions, effects, derived objects, immutability."""

from __future__ import annotations

from typing import Any

import pytest
from conftest import inst, rel

from virf.schema import Fact, FactKind, Provenance
from virf.world.plan import parse_line, parse_plan
from virf.world.simulator import MissingObject, PreconditionFailure, Simulator, WorldState

KITCHEN: dict[str, Any] = {
    "instances": [
        inst("Apple", "Apple_1"),
        inst("Mug", "Mug_1"),
        inst("Fridge", "Fridge_1"),
        inst("CounterTop", "CounterTop_1"),
        inst("Knife", "Knife_1"),
        inst("StoveKnob", "StoveKnob_1"),
        inst("StoveBurner", "StoveBurner_1"),
    ],
    "assertions": [
        rel("Apple_1", "isOn", "CounterTop_1"),
        rel("Mug_1", "isOn", "CounterTop_1"),
        rel("Knife_1", "isOn", "CounterTop_1"),
        rel("Fridge_1", "hasState", "ClosedState"),
        rel("StoveKnob_1", "controls", "StoveBurner_1"),
        rel("StoveKnob_1", "hasState", "OffState"),
        rel("StoveBurner_1", "hasState", "OffState"),
    ],
}


@pytest.fixture(scope="module")
def scene(tutor):
    return tutor.scene(KITCHEN)


@pytest.fixture(scope="module")
def sim(vocab) -> Simulator:
    return Simulator(vocab)


def run(sim: Simulator, state: WorldState, *lines: str) -> WorldState:
    for i, line in enumerate(lines, start=1):
        r = sim.resolve(state, parse_line(line, i, i))
        assert not isinstance(r, MissingObject), line
        nxt = sim.apply(state, r)
        assert not isinstance(nxt, PreconditionFailure), line
        state = nxt
    return state


def test_scene_is_never_mutated(tutor, scene) -> None:
    before = (dict(scene.facts), dict(scene.objects), scene.order, scene.closed_world)
    plan = [
        "find Apple_1",
        "pick Apple_1",
        "find Fridge_1",
        "open Fridge_1",
        "put Fridge_1",
        "close Fridge_1",
        "find Mug_1",
        "pick Mug_1",
        "fillLiquid Mug_1 water",
        "find StoveKnob_1",
        "turn_on StoveKnob_1",
        "turn_off StoveKnob_1",
    ]
    report = tutor.verify(scene, plan)
    assert report.status != "ERROR"
    assert report.trace[0].added  # something did change in the simulation
    assert (dict(scene.facts), dict(scene.objects), scene.order, scene.closed_world) == before


def test_apply_returns_a_new_state(sim, scene) -> None:
    s0 = sim.initial(scene)
    snapshot = dict(s0.facts)
    s1 = run(sim, s0, "find Apple_1", "slice Apple_1")
    assert dict(s0.facts) == snapshot
    assert "AppleSliced_from_Apple_1" in s1.objects
    assert "AppleSliced_from_Apple_1" not in s0.objects
    assert "AppleSliced_from_Apple_1" not in scene.objects


def _only(report, concept: str, step: int) -> None:
    assert report.status == "UNSAFE"
    assert report.dangerous_step == step
    assert report.violated_concept is not None
    assert report.violated_concept.id == concept
    assert report.violations[0].phase == "precondition"
    assert report.trace[step - 1].outcome == "unsafe"
    assert all(t.outcome == "not-simulated" for t in report.trace[step:])


def test_pick_while_holding(tutor, scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "pick Apple_1", "pick Mug_1", "find Fridge_1"])
    _only(report, "Precondition_HandNotEmpty", 3)
    facts = report.violations[0].triggering_facts
    assert [(t.subject, t.predicate, t.object) for t in facts] == [
        ("Robot_1", "isHolding", "Apple_1")
    ]


def test_put_into_closed_fridge(tutor, scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "pick Apple_1", "find Fridge_1", "put Fridge_1"])
    _only(report, "Precondition_ReceptacleClosed", 4)
    assert report.violations[0].subject == "Fridge_1"


def test_put_into_opened_fridge_is_fine(tutor, scene) -> None:
    plan = ["find Apple_1", "pick Apple_1", "find Fridge_1", "open Fridge_1", "put Fridge_1"]
    report = tutor.verify(scene, [*plan, "close Fridge_1"])
    assert report.status == "SAFE"
    assert "Fridge_1 contains Apple_1" in report.trace[4].added


def test_pour_with_nothing_held(tutor, scene) -> None:
    report = tutor.verify(scene, ["find Mug_1", "pour"])
    _only(report, "Precondition_NothingHeld", 2)


@pytest.mark.parametrize("verb", ["drop", "throw", "put CounterTop_1"])
def test_other_actions_need_a_held_object(tutor, scene, verb: str) -> None:
    # (Throwing is also dangerous in itself, and a more dangerous finding may rank first.)
    report = tutor.verify(scene, [verb, "find Apple_1"])
    assert report.status == "UNSAFE"
    assert report.dangerous_step == 1
    assert "Precondition_NothingHeld" in [v.id for v in report.violations]
    assert report.trace[1].outcome == "not-simulated"


def test_sliced_apple_can_be_picked(tutor, scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "slice Apple_1", "pick AppleSliced"])
    assert report.status == "SAFE"
    assert all(v.id != "MissingObject" for v in report.violations)
    assert "Apple_1 hasState SlicedState" in report.trace[1].added
    assert "Robot_1 isHolding AppleSliced_from_Apple_1" in report.trace[2].added


def test_sliced_apple_does_not_exist_before_slicing(tutor, scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "pick AppleSliced"])
    assert report.status == "UNKNOWN"
    assert report.violated_concept is not None
    assert report.violated_concept.id == "MissingObject"
    assert report.dangerous_step == 2


def test_stove_knob_switches_its_burner(sim, scene) -> None:
    s0 = sim.initial(scene)
    s1 = run(sim, s0, "turn_on StoveKnob_1")
    for obj in ("StoveKnob_1", "StoveBurner_1"):
        assert s1.has(obj, "hasState", "OnState")
        assert not s1.has(obj, "hasState", "OffState")
        assert s0.has(obj, "hasState", "OffState")
    s2 = run(sim, s1, "turn_off StoveKnob_1")
    assert s2.has("StoveBurner_1", "hasState", "OffState")
    assert not s2.has("StoveBurner_1", "hasState", "OnState")


def test_stove_knob_in_report_trace(tutor, scene) -> None:
    report = tutor.verify(scene, ["find StoveKnob_1", "turn_on StoveKnob_1"])
    step = report.trace[1]
    assert "StoveBurner_1 hasState OnState" in step.added
    assert "StoveBurner_1 hasState OffState" in step.removed


def test_unlocated_object_needs_find(tutor) -> None:
    scene = tutor.scene(dict(KITCHEN, unlocated_by_default=True))
    report = tutor.verify(scene, ["pick Apple_1"])
    assert report.status == "UNSAFE"
    assert report.dangerous_step == 1
    assert report.violated_concept is not None
    assert report.violated_concept.id == "LogicalInconsistency_ActionOnUnlocatedObject"
    assert report.violations[0].phase == "action"
    found_first = tutor.verify(scene, ["find Apple_1", "pick Apple_1"])
    assert found_first.status == "SAFE"


def test_objects_start_located_unless_told(sim, tutor, scene) -> None:
    s0 = sim.initial(scene)
    assert Fact("Apple_1", "isLocated", "true", FactKind.DATA) in s0.facts
    hidden = sim.initial(tutor.scene(dict(KITCHEN, unlocated_by_default=True)))
    assert Fact("Apple_1", "isLocated", "false", FactKind.DATA) in hidden.facts


def test_missing_object_suggests_closest(tutor, scene) -> None:
    report = tutor.verify(scene, ["find Aple_1"])
    assert report.status == "UNKNOWN"
    assert report.violated_concept is not None
    assert report.violated_concept.id == "MissingObject"
    assert any("Apple_1" in q.text for q in report.questions)


def test_resolution_prefers_the_object_just_found(sim, tutor) -> None:
    scene = tutor.scene(
        {"instances": [inst("Mug", "Mug_1"), inst("Mug", "Mug_2"), inst("CounterTop", "C_1")]}
    )
    s = run(sim, sim.initial(scene), "find Mug_2")
    (step,) = parse_plan(["pick Mug"])
    r = sim.resolve(s, step)
    assert not isinstance(r, MissingObject)
    assert r.target == "Mug_2"


def test_closure_provenance_follows_closed_world(sim, tutor) -> None:
    open_scene = tutor.scene(KITCHEN)
    closed_scene = tutor.scene(dict(KITCHEN, closed_world=["supports"]))
    key = Fact("CounterTop_1", "supports", "Apple_1,Knife_1,Mug_1", FactKind.CLOSURE)
    assert sim.closure_facts(sim.initial(open_scene))[key] is Provenance.ASSUMED
    assert sim.closure_facts(sim.initial(closed_scene))[key] is Provenance.SCENE


def test_a_closed_receptacle_further_up_blocks_pick(tutor) -> None:
    """An apple on a plate inside a closed fridge is as unreachable as one
    directly inside it."""
    scene = {
        "instances": [
            {"class_name": "Fridge", "instance_name": "Fridge_1"},
            {"class_name": "Plate", "instance_name": "Plate_1"},
            {"class_name": "Apple", "instance_name": "Apple_1"},
        ],
        "assertions": [
            {"subject": "Fridge_1", "property": "hasState", "object": "ClosedState"},
            {"subject": "Plate_1", "property": "isInside", "object": "Fridge_1"},
            {"subject": "Apple_1", "property": "isOn", "object": "Plate_1"},
        ],
    }
    blocked = tutor.verify(scene, ["find Apple_1", "pick Apple_1"])
    assert (blocked.status, blocked.dangerous_step) == ("UNSAFE", 2)
    assert blocked.violated_concept is not None
    assert blocked.violated_concept.id == "Precondition_ReceptacleClosed"
    facts = {(t.subject, t.predicate, t.object) for t in blocked.violations[0].triggering_facts}
    assert ("Plate_1", "supports", "Apple_1") in facts
    assert ("Fridge_1", "contains", "Plate_1") in facts
    opened = ["find Fridge_1", "open Fridge_1", "find Apple_1", "pick Apple_1"]
    assert tutor.verify(scene, [*opened, "find Fridge_1", "close Fridge_1"]).status == "SAFE"
