"""What a finding needs, read off the fast engine's model
(:mod:`virf.reasoning.necessity`): each claim is checked by asking the
engine without the item, and twin worlds that add a second way to the
finding take the claim away."""

from __future__ import annotations

import pytest

from virf.api import LogicTutor
from virf.reasoning.fast import FastEngine
from virf.schema import Fact, FactKind


def t(x: str, cls: str) -> Fact:
    return Fact(x, "type", cls, FactKind.TYPE)


def r(x: str, p: str, y: str) -> Fact:
    return Fact(x, p, y, FactKind.OBJECT)


@pytest.fixture(scope="module")
def engine(tutor: LogicTutor) -> FastEngine:
    return FastEngine(tutor.tbox)


def needs(engine: FastEngine, facts: list[Fact], concept: str, x: str) -> set[str]:
    """The facts (rendered) and axiom ids the proof names as needed, each
    checked: without it the finding is not entailed."""
    order = [*sorted(facts), *sorted(engine.tbox.vocabulary.background)]
    found = engine.proof(facts, concept, x, order=order)
    assert found is not None
    for f in found.needed_facts:
        assert not engine.entails([g for g in facts if g != f], concept, x)
    for a in found.needed_axioms:
        assert not engine.entails(facts, concept, x, without={a})
    return {f.render() for f in found.needed_facts} | set(found.needed_axioms)


def test_a_stated_material_and_the_catalogue_are_two_ways(engine: FastEngine) -> None:
    knife = [t("Knife_1", "Knife")]
    stated = r("Knife_1", "hasMaterial", "Metal")
    alone = needs(engine, knife, "ConductiveObject", "Knife_1")
    assert {"Knife_1 is a Knife", "KIT-Knife-material-Metal", "MAT-Metal-Conductive"} <= alone
    both = needs(engine, [*knife, stated], "ConductiveObject", "Knife_1")
    assert "MAT-Metal-Conductive" in both  # every way goes through it
    assert not {"KIT-Knife-material-Metal", stated.render(), "Knife_1 is a Knife"} & both


def running_microwave(*inside: Fact) -> list[Fact]:
    """A running microwave, and the facts ``inside`` it."""
    return [t("Microwave_1", "Microwave"), r("Microwave_1", "hasState", "OnState"), *inside]


def spoon_in_a_bowl() -> list[Fact]:
    """A running microwave, a bowl in it, a spoon in the bowl."""
    return running_microwave(
        r("Microwave_1", "contains", "Bowl_1"),
        t("Bowl_1", "Bowl"),
        r("Bowl_1", "contains", "Spoon_1"),
        t("Spoon_1", "Spoon"),
    )


def test_a_path_of_containment_is_needed_unless_there_is_another(engine: FastEngine) -> None:
    nested = spoon_in_a_bowl()
    hazard = "MetalInRunningMicrowaveDanger"
    one = needs(engine, nested, hazard, "Microwave_1")
    assert {"Microwave_1 contains Bowl_1", "Bowl_1 contains Spoon_1"} <= one
    direct = r("Microwave_1", "contains", "Spoon_1")
    two = needs(engine, [*nested, direct], hazard, "Microwave_1")
    assert "Spoon_1 is a Spoon" in two
    assert not {"Microwave_1 contains Bowl_1", "Bowl_1 contains Spoon_1", direct.render()} & two


def test_a_negation_needs_what_refutes_it_unless_another_successor_does(
    engine: FastEngine,
) -> None:
    """'supports some (PhysicalObject and not Cookware)': a knife is not
    cookware because cutlery and cookware are disjoint kinds."""
    burner = [t("StoveBurner_1", "StoveBurner")]
    knife = [r("StoveBurner_1", "supports", "Knife_1"), t("Knife_1", "Knife")]
    hazard = "ObjectLeftOnHeatingSurfaceDanger"
    one = needs(engine, burner + knife, hazard, "StoveBurner_1")
    assert {"KIT-KitchenwareKinds", "Knife_1 is a Knife", "StoveBurner_1 supports Knife_1"} <= one
    apple = [r("StoveBurner_1", "supports", "Apple_1"), t("Apple_1", "Apple")]
    two = needs(engine, burner + knife + apple, hazard, "StoveBurner_1")
    assert "StoveBurner_1 is a StoveBurner" in two
    assert not {"KIT-KitchenwareKinds", "Knife_1 is a Knife", "Apple_1 is a Apple"} & two


def test_a_closure_bounds_an_empty_surface(engine: FastEngine) -> None:
    """'max 0 supports PhysicalObject' is proved from the closure fact that
    nothing stands on the burner: the proof names it (the search then tests
    it), and what it names as needed is."""
    empty = Fact.closure("StoveBurner_1", "supports", [])
    lit = [t("StoveBurner_1", "StoveBurner"), r("StoveBurner_1", "hasState", "OnState"), empty]
    hazard = "HeatingSurfaceLeftOnEmptyDanger"
    order = [*sorted(lit), *sorted(engine.tbox.vocabulary.background)]
    found = engine.proof(lit, hazard, "StoveBurner_1", order=order)
    assert found is not None
    assert empty in found.facts
    assert "StoveBurner_1 hasState OnState" in needs(engine, lit, hazard, "StoveBurner_1")


def test_the_proofs_model_answers_what_can_go(engine: FastEngine) -> None:
    """The oracle answers questions about the proof's facts with some left
    out: still entailed (a second path to the spoon), not (the only path,
    or both), or unknown; each answer it gives is the engine's."""
    nested = spoon_in_a_bowl()
    direct = r("Microwave_1", "contains", "Spoon_1")
    hazard = "MetalInRunningMicrowaveDanger"
    facts = [*nested, direct]
    order = [*sorted(facts), *sorted(engine.tbox.vocabulary.background)]
    found = engine.proof(facts, hazard, "Microwave_1", order=order)
    assert found is not None and found.oracle is not None
    oracle = found.oracle
    asked = 0
    for out in ([], [nested[2]], [direct], [nested[2], direct], [nested[1]], [t("Bowl_1", "Bowl")]):
        removed = oracle.mask(out, ())
        assert removed is not None
        answer = oracle.decide(removed)
        if answer is not None:
            asked += 1
            assert answer == engine.entails(
                [f for f in facts if f not in out], hazard, "Microwave_1"
            )
    assert oracle.decide(0) is True
    assert oracle.decide(oracle.mask([nested[2]], ()) or 0) is True  # the direct path
    # Both paths out: neither was needed alone, but without them the graph
    # derives not even the query's positive skeleton, so the least model of
    # the rest is a model where the finding is false (the loop above held
    # that answer to the engine's).
    assert oracle.decide(oracle.mask([nested[2], direct], ()) or 0) is False
    assert oracle.decide(oracle.mask([nested[1]], ()) or 0) is False  # the microwave's state
    # An axiom the spoon's metal rests on, left out: the finding goes.
    assert oracle.decide(oracle.mask((), ["KIT-Spoon-material-Metal"]) or 0) is False
    assert asked >= 4


def oracle_agrees(engine: FastEngine, facts: list[Fact], concept: str, x: str) -> int:
    """Every answer the proof's oracle gives, with one fact or one axiom
    left out, is the engine's; how many it gave."""
    axioms = sorted(engine.tbox.vocabulary.background)
    found = engine.proof(facts, concept, x, order=[*sorted(facts), *axioms])
    assert found is not None and found.oracle is not None
    oracle, given = found.oracle, 0
    for f in facts:
        answer = oracle.decide(oracle.mask([f], ()) or 0)
        if answer is not None:
            given += 1
            assert answer == engine.entails([g for g in facts if g != f], concept, x), f.render()
    for a in axioms:
        removed = oracle.mask((), [a])
        answer = None if removed is None else oracle.decide(removed)
        if answer is not None:
            given += 1
            assert answer == engine.entails(facts, concept, x, without={a}), a
    return given


def test_a_negation_through_a_definition_rests_on_it(engine: FastEngine) -> None:
    """'hasTarget some (SurfaceReceptacle and not FoodContactItem)': the
    floor is refuted as a food-contact item through that class's
    definition, a disjunction of kinds; without the definition the
    negation no longer holds, and the oracle must not say it does."""
    pour = [
        t("Step5_pour", "PourAction"),
        r("Step5_pour", "hasPatient", "Mug_1"),
        t("Mug_1", "Mug"),
        r("Mug_1", "contains", "Coffee_in_Mug_1"),
        t("Coffee_in_Mug_1", "Coffee"),
        r("Step5_pour", "hasTarget", "Floor_1"),
        t("Floor_1", "Floor"),
    ]
    hazard = "StainingLiquidOntoSurfaceDanger"
    assert oracle_agrees(engine, pour, hazard, "Step5_pour") > 100
    burner = [
        t("StoveBurner_1", "StoveBurner"),
        r("StoveBurner_1", "supports", "Knife_1"),
        t("Knife_1", "Knife"),
    ]
    assert oracle_agrees(engine, burner, "ObjectLeftOnHeatingSurfaceDanger", "StoveBurner_1") > 100


def test_reach_through_a_shelf_rests_on_its_chain(engine: FastEngine) -> None:
    """A lit candle on a shelf beside the curtains: the curtains are near
    the flame only through 'isOn o isNear'; without that chain axiom the
    finding goes, and the oracle must not say otherwise."""
    shelf = [
        t("Candle_1", "Candle"),
        r("Candle_1", "hasState", "OnState"),
        t("Shelf_1", "Shelf"),
        t("Curtains_1", "Curtains"),
        r("Candle_1", "isOn", "Shelf_1"),
        r("Shelf_1", "isNear", "Curtains_1"),
    ]
    hazard = "EasilyIgnitedNearIgnitionSourceDanger"
    assert not engine.entails(shelf, hazard, "Curtains_1", without={"MECH-ReachThroughSupport"})
    assert oracle_agrees(engine, shelf, hazard, "Curtains_1") > 100


def test_a_negation_inside_a_filler_at_each_of_two_objects(engine: FastEngine) -> None:
    """'encloses some (ConductiveObject or NonFoodItem)', NonFoodItem read
    through 'not FoodItem': with two non-food objects in a running
    microwave, leaving out either one's facts keeps the finding, through
    the other's refutation.  The oracle says so itself (it asked the engine
    for each before), and every answer it gives is the engine's."""
    oven = running_microwave(
        r("Microwave_1", "contains", "Book_1"),
        t("Book_1", "Book"),
        r("Microwave_1", "contains", "Candle_1"),
        t("Candle_1", "Candle"),
    )
    hazard = "ItemLeftInHeatingApplianceDanger"
    assert engine.entails(oven, hazard, "Microwave_1")
    order = [*sorted(oven), *sorted(engine.tbox.vocabulary.background)]
    found = engine.proof(oven, hazard, "Microwave_1", order=order)
    assert found is not None and found.oracle is not None
    for gone in (oven[2:4], oven[4:6]):
        removed = found.oracle.mask(gone, ())
        assert removed is not None and found.oracle.decide(removed) is True
        assert engine.entails([f for f in oven if f not in gone], hazard, "Microwave_1")
    both = found.oracle.mask(oven[2:], ())
    assert both is not None and found.oracle.decide(both) is not True
    assert oracle_agrees(engine, oven, hazard, "Microwave_1") > 100
