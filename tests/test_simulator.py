"""The sandbox simulator: preconditions, effects, derived objects, immutability."""

from __future__ import annotations

from typing import Any

import pytest
from conftest import EXAMPLES_DIR, inst, rel

from virf.api import LogicTutor
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind, Provenance, Report
from virf.world.actions import HANDLERS
from virf.world.language import ACTION_CLASS, ARITY, VERBS
from virf.world.plan import PlanStep, parse_line, parse_plan
from virf.world.scene import Scene
from virf.world.simulator import (
    MissingObject,
    PreconditionFailure,
    ResolvedStep,
    Simulator,
    WorldState,
    diff,
)

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
def scene(tutor: LogicTutor) -> Scene:
    return tutor.scene(KITCHEN)


@pytest.fixture(scope="module")
def sim(vocab: Vocabulary) -> Simulator:
    return Simulator(vocab)


def run(sim: Simulator, state: WorldState, *lines: str) -> WorldState:
    for i, line in enumerate(lines, start=1):
        r = sim.resolve(state, parse_line(line, i, i))
        assert not isinstance(r, MissingObject), line
        nxt = sim.apply(state, r)
        assert not isinstance(nxt, PreconditionFailure), line
        state = nxt
    return state


def test_scene_is_never_mutated(tutor: LogicTutor, scene: Scene) -> None:
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


def test_apply_returns_a_new_state(sim: Simulator, scene: Scene) -> None:
    s0 = sim.initial(scene)
    snapshot = dict(s0.facts)
    s1 = run(sim, s0, "find Apple_1", "slice Apple_1")
    assert dict(s0.facts) == snapshot
    assert "AppleSliced_from_Apple_1" in s1.objects
    assert "AppleSliced_from_Apple_1" not in s0.objects
    assert "AppleSliced_from_Apple_1" not in scene.objects


def _only(report: Report, concept: str, step: int) -> None:
    assert report.status == "UNSAFE"
    assert report.dangerous_step == step
    assert report.violated_concept is not None
    assert report.violated_concept.id == concept
    assert report.violations[0].phase == "precondition"
    assert report.trace[step - 1].outcome == "unsafe"
    assert all(t.outcome == "not-simulated" for t in report.trace[step:])


def test_pick_while_holding(tutor: LogicTutor, scene: Scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "pick Apple_1", "pick Mug_1", "find Fridge_1"])
    _only(report, "Precondition_HandNotEmpty", 3)
    facts = report.violations[0].triggering_facts
    assert [(t.subject, t.predicate, t.object) for t in facts] == [
        ("Robot_1", "isHolding", "Apple_1")
    ]


def test_put_into_closed_fridge(tutor: LogicTutor, scene: Scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "pick Apple_1", "find Fridge_1", "put Fridge_1"])
    _only(report, "Precondition_ReceptacleClosed", 4)
    assert report.violations[0].subject == "Fridge_1"


def test_put_into_opened_fridge_is_fine(tutor: LogicTutor, scene: Scene) -> None:
    plan = ["find Apple_1", "pick Apple_1", "find Fridge_1", "open Fridge_1", "put Fridge_1"]
    report = tutor.verify(scene, [*plan, "close Fridge_1"])
    assert report.status == "SAFE"
    assert "Fridge_1 contains Apple_1" in report.trace[4].added


def test_pour_with_nothing_held(tutor: LogicTutor, scene: Scene) -> None:
    report = tutor.verify(scene, ["find Mug_1", "pour"])
    _only(report, "Precondition_NothingHeld", 2)


@pytest.mark.parametrize("verb", ["drop", "throw", "put CounterTop_1"])
def test_other_actions_need_a_held_object(tutor: LogicTutor, scene: Scene, verb: str) -> None:
    # (Throwing is also dangerous in itself, and a more dangerous finding may rank first.)
    report = tutor.verify(scene, [verb, "find Apple_1"])
    assert report.status == "UNSAFE"
    assert report.dangerous_step == 1
    assert "Precondition_NothingHeld" in [v.id for v in report.violations]
    assert report.trace[1].outcome == "not-simulated"


def test_sliced_apple_can_be_picked(tutor: LogicTutor, scene: Scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "slice Apple_1", "pick AppleSliced"])
    assert report.status == "SAFE"
    assert all(v.id != "MissingObject" for v in report.violations)
    assert "Apple_1 hasState SlicedState" in report.trace[1].added
    assert "Robot_1 isHolding AppleSliced_from_Apple_1" in report.trace[2].added


def test_sliced_apple_does_not_exist_before_slicing(tutor: LogicTutor, scene: Scene) -> None:
    report = tutor.verify(scene, ["find Apple_1", "pick AppleSliced"])
    assert report.status == "UNKNOWN"
    assert report.violated_concept is not None
    assert report.violated_concept.id == "MissingObject"
    assert report.dangerous_step == 2


def test_stove_knob_switches_its_burner(sim: Simulator, scene: Scene) -> None:
    s0 = sim.initial(scene)
    s1 = run(sim, s0, "turn_on StoveKnob_1")
    for obj in ("StoveKnob_1", "StoveBurner_1"):
        assert s1.has(obj, "hasState", "OnState")
        assert not s1.has(obj, "hasState", "OffState")
        assert s0.has(obj, "hasState", "OffState")
    s2 = run(sim, s1, "turn_off StoveKnob_1")
    assert s2.has("StoveBurner_1", "hasState", "OffState")
    assert not s2.has("StoveBurner_1", "hasState", "OnState")


def test_stove_knob_in_report_trace(tutor: LogicTutor, scene: Scene) -> None:
    report = tutor.verify(scene, ["find StoveKnob_1", "turn_on StoveKnob_1"])
    step = report.trace[1]
    assert "StoveBurner_1 hasState OnState" in step.added
    assert "StoveBurner_1 hasState OffState" in step.removed


def test_unlocated_object_needs_find(tutor: LogicTutor) -> None:
    scene = tutor.scene(dict(KITCHEN, unlocated_by_default=True))
    report = tutor.verify(scene, ["pick Apple_1"])
    assert report.status == "UNSAFE"
    assert report.dangerous_step == 1
    assert report.violated_concept is not None
    assert report.violated_concept.id == "LogicalInconsistency_ActionOnUnlocatedObject"
    assert report.violations[0].phase == "action"
    found_first = tutor.verify(scene, ["find Apple_1", "pick Apple_1"])
    assert found_first.status == "SAFE"


def test_objects_start_located_unless_told(sim: Simulator, tutor: LogicTutor, scene: Scene) -> None:
    s0 = sim.initial(scene)
    assert Fact("Apple_1", "isLocated", "true", FactKind.DATA) in s0.facts
    hidden = sim.initial(tutor.scene(dict(KITCHEN, unlocated_by_default=True)))
    assert Fact("Apple_1", "isLocated", "false", FactKind.DATA) in hidden.facts


def test_missing_object_suggests_closest(tutor: LogicTutor, scene: Scene) -> None:
    report = tutor.verify(scene, ["find Aple_1"])
    assert report.status == "UNKNOWN"
    assert report.violated_concept is not None
    assert report.violated_concept.id == "MissingObject"
    assert any("Apple_1" in q.text for q in report.questions)


def test_resolution_prefers_the_object_just_found(sim: Simulator, tutor: LogicTutor) -> None:
    scene = tutor.scene(
        {"instances": [inst("Mug", "Mug_1"), inst("Mug", "Mug_2"), inst("CounterTop", "C_1")]}
    )
    s = run(sim, sim.initial(scene), "find Mug_2")
    (step,) = parse_plan(["pick Mug"])
    r = sim.resolve(s, step)
    assert not isinstance(r, MissingObject)
    assert r.target == "Mug_2"


def test_closure_provenance_follows_closed_world(sim: Simulator, tutor: LogicTutor) -> None:
    open_scene = tutor.scene(KITCHEN)
    closed_scene = tutor.scene(dict(KITCHEN, closed_world=["supports"]))
    key = Fact.closure("CounterTop_1", "supports", ["Apple_1", "Knife_1", "Mug_1"])
    assert sim.closure_facts(sim.initial(open_scene))[key] is Provenance.ASSUMED
    assert sim.closure_facts(sim.initial(closed_scene))[key] is Provenance.SCENE


def test_a_closed_receptacle_further_up_blocks_pick(tutor: LogicTutor) -> None:
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


# ---------------------------------------------------------------- the action table
def test_every_plan_verb_has_exactly_one_handler() -> None:
    assert len(set(VERBS)) == len(VERBS)
    assert sorted(HANDLERS) == sorted(VERBS)
    # The plan reader's other per-verb tables name the same verbs.
    assert sorted(ACTION_CLASS) == sorted(ARITY) == sorted(VERBS)


HOUSE: dict[str, Any] = {
    "instances": [
        inst("Knife", "Knife_1"),
        inst("Apple", "Apple_1"),
        inst("CounterTop", "CounterTop_1"),
        inst("Fridge", "Fridge_1"),
        inst("Egg", "Egg_1"),
        inst("Mug", "Mug_1"),
        inst("Bowl", "Bowl_1"),
        inst("Floor", "Floor_1"),
        inst("StoveKnob", "StoveKnob_1"),
        inst("StoveBurner", "StoveBurner_1"),
        inst("Pan", "Pan_1"),
        inst("Potato", "Potato_1"),
        inst("Plate", "Plate_1"),
        inst("Person", "Person_1"),
    ],
    "assertions": [
        rel("Knife_1", "isOn", "CounterTop_1"),
        rel("Apple_1", "isOn", "CounterTop_1"),
        rel("Egg_1", "isOn", "CounterTop_1"),
        rel("Mug_1", "isOn", "CounterTop_1"),
        rel("Bowl_1", "isOn", "CounterTop_1"),
        rel("Plate_1", "isOn", "CounterTop_1"),
        rel("Person_1", "isNear", "CounterTop_1"),
        rel("Mug_1", "touched", "Egg_1"),
        rel("Fridge_1", "hasState", "ClosedState"),
        rel("StoveKnob_1", "controls", "StoveBurner_1"),
        rel("StoveKnob_1", "hasState", "OffState"),
        rel("StoveBurner_1", "hasState", "OffState"),
        rel("Pan_1", "isOn", "StoveBurner_1"),
        rel("Potato_1", "isInside", "Pan_1"),
    ],
}

# One plan using all 17 verbs, with what each step adds and removes.
EVERY_VERB: list[tuple[str, tuple[str, ...], tuple[str, ...]]] = [
    ("find Knife_1", ("Robot_1 isNear Knife_1",), ()),
    (
        "pick Knife_1",
        ("Robot_1 isHolding Knife_1",),
        ("CounterTop_1 supports Knife_1", "Robot_1 isNear Knife_1"),
    ),
    ("find Apple_1", ("Knife_1 isNear Apple_1", "Robot_1 isNear Apple_1"), ()),
    (
        "slice Apple_1",
        (
            "AppleSliced_from_Apple_1 hasState SlicedState",
            "AppleSliced_from_Apple_1 isLocated true",
            "AppleSliced_from_Apple_1 is a AppleSliced",
            "Apple_1 hasState SlicedState",
            "CounterTop_1 supports AppleSliced_from_Apple_1",
            "Knife_1 touched Apple_1",
        ),
        (),
    ),
    (
        "find CounterTop_1",
        ("Knife_1 isNear CounterTop_1", "Robot_1 isNear CounterTop_1"),
        ("Knife_1 isNear Apple_1", "Robot_1 isNear Apple_1"),
    ),
    (
        "put CounterTop_1",
        (
            "CounterTop_1 supports Knife_1",
            "Knife_1 isNear AppleSliced_from_Apple_1",
            "Knife_1 isNear Apple_1",
            "Knife_1 isNear Bowl_1",
            "Knife_1 isNear Egg_1",
            "Knife_1 isNear Mug_1",
            "Knife_1 isNear Person_1",
            "Knife_1 isNear Plate_1",
        ),
        ("Knife_1 isNear CounterTop_1", "Robot_1 isHolding Knife_1"),
    ),
    ("find Fridge_1", ("Robot_1 isNear Fridge_1",), ("Robot_1 isNear CounterTop_1",)),
    ("open Fridge_1", ("Fridge_1 hasState OpenState",), ("Fridge_1 hasState ClosedState",)),
    ("close Fridge_1", ("Fridge_1 hasState ClosedState",), ("Fridge_1 hasState OpenState",)),
    ("find Egg_1", ("Robot_1 isNear Egg_1",), ("Robot_1 isNear Fridge_1",)),
    (
        "break Egg_1",
        (
            "CounterTop_1 supports EggCracked_from_Egg_1",
            "EggCracked_from_Egg_1 isLocated true",
            "EggCracked_from_Egg_1 is a EggCracked",
            "Egg_1 hasState BrokenState",
        ),
        (),
    ),
    ("cook Egg_1", ("Egg_1 hasState CookedState",), ()),
    ("dirty Mug_1", ("Mug_1 hasState DirtyState",), ()),
    (
        "clean Mug_1",
        ("Mug_1 hasState CleanState",),
        ("Mug_1 hasState DirtyState", "Mug_1 touched Egg_1"),
    ),
    (
        "fillLiquid Mug_1 water",
        (
            "Mug_1 contains Water_in_Mug_1",
            "Mug_1 hasState FilledWithLiquidState",
            "Water_in_Mug_1 is a Water",
        ),
        ("Mug_1 hasState UnknownFillState",),
    ),
    ("find Mug_1", ("Robot_1 isNear Mug_1",), ("Robot_1 isNear Egg_1",)),
    (
        "pick Mug_1",
        ("Robot_1 isHolding Mug_1",),
        ("CounterTop_1 supports Mug_1", "Knife_1 isNear Mug_1", "Robot_1 isNear Mug_1"),
    ),
    ("find Bowl_1", ("Mug_1 isNear Bowl_1", "Robot_1 isNear Bowl_1"), ()),
    (
        "pour",
        (
            "Bowl_1 contains Water_in_Mug_1",
            "Bowl_1 hasState FilledWithLiquidState",
            "Mug_1 hasState EmptyState",
        ),
        (
            "Bowl_1 hasState UnknownFillState",
            "Mug_1 contains Water_in_Mug_1",
            "Mug_1 hasState FilledWithLiquidState",
        ),
    ),
    (
        "emptyLiquid Bowl_1",
        ("Bowl_1 hasState EmptyState",),
        (
            "Bowl_1 contains Water_in_Mug_1",
            "Bowl_1 hasState FilledWithLiquidState",
            "Water_in_Mug_1 is a Water",
        ),
    ),
    (
        # The knob lights its burner, which heats the pan on it and cooks the
        # potato in the pan.
        "turn_on StoveKnob_1",
        (
            "Pan_1 hasState HotState",
            "Potato_1 hasState CookedState",
            "Potato_1 hasState HotState",
            "StoveBurner_1 hasState OnState",
            "StoveKnob_1 hasState OnState",
        ),
        ("StoveBurner_1 hasState OffState", "StoveKnob_1 hasState OffState"),
    ),
    (
        "turn_off StoveKnob_1",
        ("StoveBurner_1 hasState OffState", "StoveKnob_1 hasState OffState"),
        ("StoveBurner_1 hasState OnState", "StoveKnob_1 hasState OnState"),
    ),
    (
        "drop",
        ("Floor_1 supports Mug_1", "Mug_1 hasState BrokenState"),
        ("Robot_1 isHolding Mug_1",),
    ),
    ("find Plate_1", ("Robot_1 isNear Plate_1",), ("Robot_1 isNear Bowl_1",)),
    (
        "pick Plate_1",
        ("Robot_1 isHolding Plate_1",),
        ("CounterTop_1 supports Plate_1", "Knife_1 isNear Plate_1", "Robot_1 isNear Plate_1"),
    ),
    (
        "throw",
        ("Floor_1 supports Plate_1", "Plate_1 hasState BrokenState"),
        ("Robot_1 isHolding Plate_1",),
    ),
]


def test_every_verb_changes_the_state_as_specified(sim: Simulator, tutor: LogicTutor) -> None:
    plan = parse_plan([line for line, _, _ in EVERY_VERB])
    assert {step.verb for step in plan} == set(VERBS)
    state = sim.initial(tutor.scene(HOUSE))
    for step, (line, added, removed) in zip(plan, EVERY_VERB, strict=True):
        r = sim.resolve(state, step)
        assert isinstance(r, ResolvedStep), line
        nxt = sim.apply(state, r)
        assert isinstance(nxt, WorldState), (line, nxt)
        assert diff(state, nxt) == (added, removed), line
        new = set(nxt.facts) - set(state.facts)
        assert {nxt.facts[f] for f in new} <= {Provenance.PLAN}, line
        state = nxt
    assert state.found == (
        "Knife_1",
        "Apple_1",
        "CounterTop_1",
        "Fridge_1",
        "Egg_1",
        "Mug_1",
        "Bowl_1",
        "Plate_1",
    )
    assert "Water_in_Mug_1" not in state.objects  # emptied out of the bowl
    assert state.objects["EggCracked_from_Egg_1"] == frozenset({"EggCracked"})


POURING: dict[str, Any] = {
    "instances": [
        inst("Mug", "Mug_1"),
        inst("CounterTop", "CounterTop_1"),
        inst("SprayBottle", "SprayBottle_1"),
        inst("Sink", "Sink_1"),
        inst("Fridge", "Fridge_1"),
        inst("Apple", "Apple_1"),
        inst("StoveBurner", "StoveBurner_1"),
        inst("Pan", "Pan_1"),
    ],
    "assertions": [
        rel("Mug_1", "hasState", "FilledWithLiquidState"),
        rel("SprayBottle_1", "hasMaterial", "Bleach"),
        rel("Fridge_1", "hasState", "ClosedState"),
        rel("Apple_1", "isInside", "Fridge_1"),
        rel("StoveBurner_1", "hasState", "OnState"),
        rel("Pan_1", "isOn", "StoveBurner_1"),
    ],
}


@pytest.fixture(scope="module")
def pouring(sim: Simulator, tutor: LogicTutor) -> WorldState:
    return sim.initial(tutor.scene(POURING))


def last_step(
    sim: Simulator, state: WorldState, *lines: str
) -> tuple[WorldState, WorldState | PreconditionFailure]:
    """The state before the last line and what the last line yields."""
    state = run(sim, state, *lines[:-1])
    r = sim.resolve(state, parse_line(lines[-1], len(lines), len(lines)))
    assert isinstance(r, ResolvedStep)
    return state, sim.apply(state, r)


@pytest.mark.parametrize(
    ("lines", "added", "removed"),
    [
        pytest.param(
            ("pick Mug_1", "find CounterTop_1", "pour"),
            (
                "CounterTop_1 hasState WetState",
                "CounterTop_1 supports Liquid_from_Mug_1",
                "Liquid_from_Mug_1 is a UnknownLiquid",
                "Mug_1 hasState EmptyState",
            ),
            ("Mug_1 hasState FilledWithLiquidState",),
            id="unnamed-liquid-onto-a-surface",
        ),
        pytest.param(
            ("pick Mug_1", "pour Sink_1"),
            (
                "Liquid_from_Mug_1 is a UnknownLiquid",
                "Mug_1 hasState EmptyState",
                "Sink_1 contains Liquid_from_Mug_1",
            ),
            ("Mug_1 hasState FilledWithLiquidState",),
            id="unnamed-liquid-into-a-container",
        ),
        pytest.param(
            ("pick SprayBottle_1", "pour CounterTop_1"),
            (
                "Bleach_from_SprayBottle_1 hasMaterial Bleach",
                "Bleach_from_SprayBottle_1 is a Substance",  # a chemical out of its bottle
                "CounterTop_1 supports Bleach_from_SprayBottle_1",
            ),
            (),
            id="chemical-onto-a-surface",
        ),
        pytest.param(
            ("pick SprayBottle_1", "find Sink_1", "pour"),
            (
                "Bleach_from_SprayBottle_1 hasMaterial Bleach",
                "Bleach_from_SprayBottle_1 is a Substance",  # a chemical out of its bottle
                "Sink_1 contains Bleach_from_SprayBottle_1",
            ),
            (),
            id="chemical-into-the-container-just-found",
        ),
    ],
)
def test_pour_moves_what_the_held_object_holds(
    sim: Simulator,
    pouring: WorldState,
    lines: tuple[str, ...],
    added: tuple[str, ...],
    removed: tuple[str, ...],
) -> None:
    before, after = last_step(sim, pouring, *lines)
    assert isinstance(after, WorldState)
    assert diff(before, after) == (added, removed)


@pytest.mark.parametrize(
    ("lines", "precondition", "subject", "message", "facts"),
    [
        (
            ("open CounterTop_1",),
            "Precondition_LacksAffordance",
            "CounterTop_1",
            "CounterTop_1 cannot be used for 'open': its type is not Openable",
            ("CounterTop_1 is a CounterTop",),
        ),
        (
            ("fillLiquid CounterTop_1 water",),
            "Precondition_LacksAffordance",
            "CounterTop_1",
            "CounterTop_1 cannot be used for 'fillLiquid': its type is not LiquidContainer",
            ("CounterTop_1 is a CounterTop",),
        ),
        (
            ("pick Mug_1", "pick SprayBottle_1"),
            "Precondition_HandNotEmpty",
            "Robot_1",
            "Robot_1 is already holding Mug_1",
            ("Robot_1 isHolding Mug_1",),
        ),
        (
            ("pick Apple_1",),
            "Precondition_ReceptacleClosed",
            "Fridge_1",
            "Apple_1 is inside Fridge_1, which is closed",
            ("Fridge_1 contains Apple_1", "Fridge_1 hasState ClosedState"),
        ),
        (
            ("put CounterTop_1",),
            "Precondition_NothingHeld",
            "Robot_1",
            "Robot_1 is holding nothing to put",
            (),
        ),
        (
            ("pick Mug_1", "put Sink_1 CounterTop_1"),
            "Precondition_NothingHeld",
            "Robot_1",
            "Robot_1 is holding Mug_1, not Sink_1",
            ("Robot_1 isHolding Mug_1",),
        ),
        (
            ("pick Mug_1", "put Apple_1"),
            "Precondition_NotAReceptacle",
            "Apple_1",
            "Apple_1 cannot hold objects",
            ("Apple_1 is a Apple",),
        ),
        (
            ("pick Mug_1", "put Fridge_1"),
            "Precondition_ReceptacleClosed",
            "Fridge_1",
            "Fridge_1 is closed",
            ("Fridge_1 hasState ClosedState",),
        ),
        (
            ("pour",),
            "Precondition_NothingHeld",
            "Robot_1",
            "Robot_1 is holding nothing to pour",
            (),
        ),
        (
            ("find Mug_1", "pick Mug_1", "pour"),
            "Precondition_NoPourTarget",
            "Robot_1",
            "nothing has been found to pour into since the object was picked up",
            (),
        ),
        (
            ("pick Mug_1", "pour Mug_1"),
            "Precondition_NoPourTarget",
            "Robot_1",
            "nothing has been found to pour into since the object was picked up",
            (),
        ),
        (
            ("drop",),
            "Precondition_NothingHeld",
            "Robot_1",
            "Robot_1 is holding nothing to drop",
            (),
        ),
        (
            ("throw",),
            "Precondition_NothingHeld",
            "Robot_1",
            "Robot_1 is holding nothing to throw",
            (),
        ),
    ],
)
def test_precondition_failures(
    sim: Simulator,
    pouring: WorldState,
    lines: tuple[str, ...],
    precondition: str,
    subject: str,
    message: str,
    facts: tuple[str, ...],
) -> None:
    _, failure = last_step(sim, pouring, *lines)
    assert isinstance(failure, PreconditionFailure)
    assert failure.step.index == len(lines)
    assert (failure.precondition, failure.subject, failure.message) == (
        precondition,
        subject,
        message,
    )
    assert tuple(f.render() for f in failure.facts) == facts


def test_a_verb_without_a_handler_only_lets_heat_sources_work(
    sim: Simulator, pouring: WorldState
) -> None:
    # No affordance is checked and nothing is found; the lit burner still
    # heats the pan on it, as after any step.
    step = PlanStep(index=1, text="dance CounterTop_1", verb="dance", args=("CounterTop_1",))
    after = sim.apply(pouring, ResolvedStep(step, target="CounterTop_1"))
    assert isinstance(after, WorldState)
    assert diff(pouring, after) == (("Pan_1 hasState HotState",), ())
    assert after.found == pouring.found == ()
    assert after.objects == pouring.objects


@pytest.mark.parametrize(
    "plan",
    [
        ["find Pot_1", "emptyLiquid Pot_1"],
        ["find Pot_1", "emptyLiquid Pot_1", "find Pot_1", "pick Pot_1"],
    ],
)
def test_a_liquid_the_scene_declared_can_be_emptied_away(
    tutor: LogicTutor, plan: list[str]
) -> None:
    # The liquid leaves the world: no later step may still look it up.
    scene = tutor.scene(EXAMPLES_DIR / "pedagogical-initial" / "scene.json")
    report = tutor.verify(scene, plan)
    assert report.status != "ERROR", report.reason
    last = report.trace[1]
    assert any("Soup_1" in removed for removed in last.removed)


@pytest.mark.parametrize("verb", ["drop", "throw"])
def test_a_breakable_object_breaks_when_dropped_or_thrown_and_others_land_whole(
    tutor: LogicTutor, sim: Simulator, verb: str
) -> None:
    data = {
        "instances": [
            inst("Plate", "Plate_1"),
            inst("Pillow", "Pillow_1"),
            inst("Floor", "Floor_1"),
        ],
        "assertions": [],
    }
    start = sim.initial(tutor.scene(data))
    plate = run(sim, start, "find Plate", "pick Plate", verb)
    assert plate.has("Plate_1", "hasState", "BrokenState")
    assert plate.has("Floor_1", "supports", "Plate_1")
    pillow = run(sim, start, "find Pillow", "pick Pillow", verb)
    assert not pillow.has("Pillow_1", "hasState", "BrokenState")
    assert pillow.has("Floor_1", "supports", "Pillow_1")
