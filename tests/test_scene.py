"""Scene input: the paper's Appendix C ABox format, errors with suggestions, material defaults."""

from __future__ import annotations

from typing import Any

import pytest
from conftest import inst, rel

from virf.errors import InputError
from virf.ontology.build import load_catalogue
from virf.schema import Fact, FactKind, Provenance
from virf.world.scene import build_scene, load_scene_file

FOOD_CATEGORIES = {"Fruit", "Vegetable", "BakedGood", "EggFood", "Meat", "Beverage", "Condiment"}
NO_MATERIAL_TYPES = sorted(
    name
    for name, info in load_catalogue()["types"].items()
    if not info.get("materials")
    and not info.get("typical_materials")
    and not info.get("material_variants")
    and info["category"] not in FOOD_CATEGORIES
)
# Types whose AI2-THOR instances differ in material (a vase is ceramic, glass
# or metal): each material only some have is a possibility.
VARYING_TYPES = sorted(
    name for name, info in load_catalogue()["types"].items() if info.get("material_variants")
)

APPENDIX_C: dict[str, Any] = {
    "instances": [
        inst("Microwave", "Microwave_1"),
        inst("Pot", "Pot_1"),
        inst("MetallicObject", "Pot_1"),
        inst("CounterTop", "CounterTop_1"),
        inst("Metal", "Metal_for_Pot_1"),
    ],
    "assertions": [
        rel("Pot_1", "isMadeOf", "Metal_for_Pot_1"),
        rel("Microwave_1", "hasState", "closed", "data_property"),
        rel("Pot_1", "isOn", "CounterTop_1"),
    ],
}


def test_appendix_c_abox_loads(tutor) -> None:
    scene = tutor.scene(APPENDIX_C)
    facts = scene.facts
    assert facts[Fact("Microwave_1", "hasState", "ClosedState")] is Provenance.SCENE
    assert facts[Fact("CounterTop_1", "supports", "Pot_1")] is Provenance.SCENE
    # isMadeOf == hasMaterial; the user's material individual stands for Metal,
    # and 'typed MetallicObject' says no more than 'made of metal'.
    assert Fact("Pot_1", "hasMaterial", "Metal") in facts
    assert Fact("Pot_1", "type", "Pot", FactKind.TYPE) in facts
    assert not any("Metal_for_Pot_1" in (f.subject, f.object) for f in facts)
    assert scene.spelling[Fact("Pot_1", "hasMaterial", "Metal")] in {
        Fact("Pot_1", "isMadeOf", "Metal_for_Pot_1"),
        Fact("Pot_1", "type", "MetallicObject", FactKind.TYPE),
    }
    # isOn is stored once, as its inverse.
    assert not any(f.predicate == "isOn" for f in facts)
    # The material individual is not a physical object in the scene.
    assert set(scene.objects) == {"Microwave_1", "Pot_1", "CounterTop_1", scene.agent}
    assert scene.objects["Pot_1"] == frozenset({"Pot"})
    assert tutor.engine.consistent(facts)


def test_scene_order_and_default_agent(tutor) -> None:
    scene = tutor.scene(APPENDIX_C)
    assert scene.order == ("Microwave_1", "Pot_1", "CounterTop_1")
    assert scene.agent == "Robot_1"
    assert Fact("Robot_1", "type", "Robot", FactKind.TYPE) in scene.facts


def _error(tutor, data: Any) -> str:
    with pytest.raises(InputError) as err:
        build_scene(data, tutor.tbox.vocabulary)
    return str(err.value)


def test_unknown_class_suggests_closest(tutor) -> None:
    msg = _error(tutor, {"instances": [inst("Mircowave", "Microwave_1")]})
    assert "'Mircowave'" in msg
    assert "Microwave" in msg.split("closest", 1)[1]


def test_unknown_property_suggests_closest(tutor) -> None:
    data = {
        "instances": [inst("Microwave", "Microwave_1")],
        "assertions": [rel("Microwave_1", "hasStat", "OnState")],
    }
    msg = _error(tutor, data)
    assert "'hasStat'" in msg
    assert "hasState" in msg.split("closest", 1)[1]


def test_unknown_subject_individual_suggests_closest(tutor) -> None:
    data = {
        "instances": [inst("Pot", "Pot_1"), inst("CounterTop", "CounterTop_1")],
        "assertions": [rel("Pot1", "isOn", "CounterTop_1")],
    }
    msg = _error(tutor, data)
    assert "'Pot1'" in msg
    assert "Pot_1" in msg.split("closest", 1)[1]


def test_unknown_object_individual_suggests_closest(tutor) -> None:
    data = {
        "instances": [inst("Pot", "Pot_1"), inst("CounterTop", "CounterTop_1")],
        "assertions": [rel("Pot_1", "isOn", "CounterTop1")],
    }
    msg = _error(tutor, data)
    assert "'CounterTop1'" in msg
    assert "CounterTop_1" in msg.split("closest", 1)[1]


@pytest.mark.parametrize("name", ["1Pot", "Pot 1", "Pot/1", ""])
def test_bad_instance_name(tutor, name: str) -> None:
    msg = _error(tutor, {"instances": [inst("Pot", name)]})
    assert f"'{name}'" in msg


def test_instance_named_like_ontology_term(tutor) -> None:
    assert "ontology term" in _error(tutor, {"instances": [inst("Pot", "Metal")]})


@pytest.mark.parametrize(
    "data",
    [
        [],
        {"assertions": []},
        {"instances": [], "extra": 1},
        {"instances": [{"class_name": "Pot"}]},
        {"instances": [inst("Pot", "Pot_1")], "closed_world": ["isNear"]},
        {"instances": [inst("Pot", "Pot_1")], "assertions": [rel("Pot_1", "isLocated", "maybe")]},
        {
            "instances": [inst("Pot", "Pot_1")],
            "assertions": [rel("Pot_1", "hasState", "OnState", "weird_property")],
        },
    ],
)
def test_malformed_scene_structure(tutor, data: Any) -> None:
    _error(tutor, data)


def test_malformed_json_file(tmp_path, vocab) -> None:
    p = tmp_path / "scene.json"
    p.write_text('{"instances": [\n', encoding="utf-8")
    with pytest.raises(InputError, match="not valid JSON"):
        load_scene_file(p, vocab)


def test_missing_scene_file(tmp_path, vocab) -> None:
    with pytest.raises(InputError, match="not found"):
        load_scene_file(tmp_path / "nope.json", vocab)


def test_scene_file_name(tmp_path, vocab) -> None:
    case = tmp_path / "my-case"
    case.mkdir()
    (case / "scene.json").write_text('{"instances": []}', encoding="utf-8")
    assert load_scene_file(case / "scene.json", vocab).name == "my-case"


# ---------------------------------------------------------------- materials


def test_mug_gets_default_ceramic(tutor) -> None:
    scene = tutor.scene({"instances": [inst("Mug", "Mug_1")]})
    materials = {f: p for f, p in scene.facts.items() if f.predicate == "hasMaterial"}
    assert materials == {Fact("Mug_1", "hasMaterial", "Ceramic"): Provenance.DEFAULT}


def test_stated_material_overrides_default(tutor) -> None:
    scene = tutor.scene(
        {"instances": [inst("Mug", "Mug_1")], "assertions": [rel("Mug_1", "hasMaterial", "Glass")]}
    )
    materials = {f: p for f, p in scene.facts.items() if f.predicate == "hasMaterial"}
    assert materials == {Fact("Mug_1", "hasMaterial", "Glass"): Provenance.SCENE}


def test_strict_material_needs_no_default(tutor) -> None:
    # Every pot is metal by the TBox: no default and no unknown-material marker.
    scene = tutor.scene({"instances": [inst("Pot", "Pot_1")]})
    assert not any(f.predicate == "hasMaterial" for f in scene.facts)


def test_food_gets_no_material_marker(tutor) -> None:
    scene = tutor.scene({"instances": [inst("Apple", "Apple_1")]})
    assert not any(f.predicate == "hasMaterial" for f in scene.facts)


@pytest.mark.parametrize("cls", ["PhysicalObject", *NO_MATERIAL_TYPES])
def test_unknown_material_is_assumed(tutor, cls: str) -> None:
    scene = tutor.scene({"instances": [inst(cls, "Thing_1")]})
    materials = {f: p for f, p in scene.facts.items() if f.predicate == "hasMaterial"}
    assert materials == {Fact("Thing_1", "hasMaterial", "UnknownMaterial"): Provenance.ASSUMED}


@pytest.mark.parametrize("cls", VARYING_TYPES)
def test_possible_materials_are_assumed_and_certain_ones_are_defaults(tutor, cls: str) -> None:
    scene = tutor.scene({"instances": [inst(cls, "Thing_1")]})
    vocab = tutor.tbox.vocabulary
    materials = {f.object: p for f, p in scene.facts.items() if f.predicate == "hasMaterial"}
    possible = set(vocab.possible_materials({cls}))
    typical = set(vocab.typical_materials({cls}))
    assert possible and not possible & typical
    assert {m for m, p in materials.items() if p is Provenance.ASSUMED} == possible
    assert {m for m, p in materials.items() if p is Provenance.DEFAULT} == typical
    # Said once by the scene, the material is what it is: no possibilities.
    stated = tutor.scene(
        {
            "instances": [inst(cls, "Thing_1")],
            "assertions": [rel("Thing_1", "hasMaterial", "Stone")],
        }
    )
    assert {f.object for f in stated.facts if f.predicate == "hasMaterial"} == {"Stone"}


def test_a_material_class_instance_is_a_substance_unless_used_as_a_value(tutor) -> None:
    scene = tutor.scene(
        {
            "instances": [
                inst("Toilet", "Toilet_1"),
                inst("Bleach", "Bleach_1"),
                inst("Metal", "Steel_1"),
                inst("Pot", "Pot_1"),
            ],
            "assertions": [
                rel("Toilet_1", "contains", "Bleach_1"),
                rel("Pot_1", "isMadeOf", "Steel_1"),
            ],
        }
    )
    assert scene.objects["Bleach_1"] == frozenset({"Substance"})
    assert Fact("Bleach_1", "hasMaterial", "Bleach") in scene.facts
    assert "Steel_1" not in scene.objects  # a value: the pot is made of metal
    assert Fact("Pot_1", "hasMaterial", "Metal") in scene.facts


def test_a_receptacle_with_unlisted_contents_is_marked(tutor) -> None:
    open_world = tutor.scene({"instances": [inst("Toilet", "Toilet_1")]})
    marker = Fact("Toilet_1", "hasState", "UnknownContentsState")
    assert open_world.facts[marker] is Provenance.ASSUMED
    listed = tutor.scene({"instances": [inst("Toilet", "Toilet_1")], "closed_world": ["contains"]})
    assert marker not in listed.facts


def test_every_catalogue_type_has_material_knowledge() -> None:
    # AI2-THOR reports salient materials for every non-food type VIRF lists,
    # so the unknown-material marker is for objects of no catalogue type
    # (PhysicalObject above) and for scenes that say "unknown".
    assert NO_MATERIAL_TYPES == []


# ---------------------------------------------------------------- value words and inverses


def test_value_words_and_inverses(tutor) -> None:
    data = {
        "instances": [
            inst("Fridge", "Fridge_1"),
            inst("Apple", "Apple_1"),
            inst("StoveKnob", "StoveKnob_1"),
            inst("StoveBurner", "StoveBurner_1"),
        ],
        "assertions": [
            rel("Fridge_1", "hasState", "open", "data_property"),
            rel("Apple_1", "isInside", "Fridge_1"),
            rel("StoveBurner_1", "isControlledBy", "StoveKnob_1"),
            rel("StoveKnob_1", "hasState", "off", "data_property"),
            rel("Apple_1", "isLocated", "false", "data_property"),
        ],
        "closed_world": ["contains"],
    }
    scene = tutor.scene(data)
    assert Fact("Fridge_1", "hasState", "OpenState") in scene.facts
    assert Fact("Fridge_1", "contains", "Apple_1") in scene.facts
    assert Fact("StoveKnob_1", "controls", "StoveBurner_1") in scene.facts
    assert Fact("StoveKnob_1", "hasState", "OffState") in scene.facts
    assert Fact("Apple_1", "isLocated", "false", FactKind.DATA) in scene.facts
    assert scene.closed_world == frozenset({"contains"})
