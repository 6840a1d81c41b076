"""The scene reader's canonical world, and ``virf scene show``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import EXAMPLES_DIR, inst, rel
from typer.testing import CliRunner

from virf.cli.main import app
from virf.errors import InputError
from virf.schema import Fact, FactKind, Provenance
from virf.world.describe import describe_scene


def test_state_and_material_words_follow_the_property(tutor) -> None:
    scene = tutor.scene(
        {
            "instances": [inst("Mug", "Mug_1"), inst("Plate", "Plate_1")],
            "assertions": [
                rel("Mug_1", "hasState", "unknown", "data_property"),
                rel("Mug_1", "hasMaterial", "unknown"),
                # The paper's noise test writes a material as a state.
                rel("Plate_1", "hasState", "isMetallic"),
            ],
        }
    )
    assert Fact("Mug_1", "hasState", "UnknownFillState") in scene.facts
    assert Fact("Mug_1", "hasMaterial", "UnknownMaterial") in scene.facts
    assert Fact("Plate_1", "hasMaterial", "Metal") in scene.facts
    assert Fact("Plate_1", "hasState", "Metal") not in scene.facts


def test_rdf_type_assertions_declare_individuals(tutor) -> None:
    scene = tutor.scene(
        {
            "instances": [],
            "assertions": [
                {"subject": "Pan_1", "property": "rdf:type", "object": "Pan"},
                {"subject": "Pan_1", "property": "a", "object": "MetallicObject"},
            ],
        }
    )
    assert scene.objects["Pan_1"] == frozenset({"Pan"})
    assert Fact("Pan_1", "hasMaterial", "Metal") in scene.facts
    assert Fact("Pan_1", "type", "Pan", FactKind.TYPE) in scene.facts


def test_any_declared_inverse_is_read_in_one_direction(tutor) -> None:
    scene = tutor.scene(
        {
            "instances": [inst("StoveKnob", "StoveKnob_1"), inst("StoveBurner", "StoveBurner_1")],
            "assertions": [rel("StoveBurner_1", "isControlledBy", "StoveKnob_1")],
        }
    )
    assert scene.facts[Fact("StoveKnob_1", "controls", "StoveBurner_1")] is Provenance.SCENE
    assert not any(f.predicate == "isControlledBy" for f in scene.facts)


def test_a_state_individual_without_a_canonical_one_is_kept(tutor) -> None:
    scene = tutor.scene(
        {
            "instances": [inst("Toaster", "Toaster_1"), inst("State", "Mood_1")],
            "assertions": [rel("Toaster_1", "hasState", "Mood_1")],
        }
    )
    assert Fact("Toaster_1", "hasState", "Mood_1") in scene.facts
    assert Fact("Mood_1", "type", "State", FactKind.TYPE) in scene.facts
    assert "Mood_1" not in scene.objects


@pytest.mark.parametrize(
    ("assertion", "message"),
    [
        (rel("Toaster_1", "hasState", "Fork_1"), "needs a state, material or attribute"),
        (rel("On_1", "hasState", "OnState"), "is a hasState value, not an object"),
        (rel("Toaster_1", "isInside", "OnState"), "must be a declared instance"),
    ],
)
def test_misplaced_values_are_input_errors(tutor, assertion: dict[str, str], message: str) -> None:
    data = {
        "instances": [
            inst("Toaster", "Toaster_1"),
            inst("Fork", "Fork_1"),
            inst("OnState", "On_1"),
        ],
        "assertions": [assertion],
    }
    with pytest.raises(InputError, match=message):
        tutor.scene(data)


def test_describe_scene_keeps_provenance_and_spelling(tutor) -> None:
    world = describe_scene(tutor.scene(EXAMPLES_DIR / "appendix-c-abox" / "scene.json"))
    microwave = world["objects"]["Microwave_1"]
    assert {"value": "OffState", "from": "default"} in microwave["states"]
    closed = next(s for s in microwave["states"] if s["value"] == "ClosedState")
    assert closed["written"] == "Microwave_1 hasState closed"
    assert closed["canonical"] == "Microwave_1 hasState ClosedState"
    assert world["objects"]["CounterTop_1"]["relations"][0]["written"] == "Pot_1 isOn CounterTop_1"
    assert "Pot_1 hasState UnknownFillState" in world["open_world_markers"]


def test_scene_show_cli(tmp_path: Path) -> None:
    runner = CliRunner()
    scene = EXAMPLES_DIR / "appendix-c-abox" / "scene.json"
    shown = runner.invoke(app, ["scene", "show", str(scene)])
    assert shown.exit_code == 0, shown.output
    assert "rewritten as the canonical form" in shown.output
    assert "Pot_1 isOn CounterTop_1  ->  CounterTop_1 supports Pot_1" in shown.output
    as_json = runner.invoke(app, ["scene", "show", str(scene), "--json"])
    assert as_json.exit_code == 0
    assert json.loads(as_json.output)["objects"]["Pot_1"]["types"] == ["Pot"]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"instances": [inst("Toastr", "T_1")]}), encoding="utf-8")
    refused = runner.invoke(app, ["scene", "show", str(bad)])
    assert refused.exit_code == 2
    assert "Toaster" in refused.output.split("closest", 1)[1]


@pytest.mark.parametrize(
    ("prop", "value", "first"),
    [
        ("hasState", "switched on", "OnState"),  # a state word inside a phrase
        ("hasState", "lite", "OnState"),  # near the state word 'lit'
        ("hasState", "swiched off", "OffState"),
        ("hasMaterial", "metl", "Metal"),  # only materials are offered
        ("hasMaterial", "glas", "Glass"),
    ],
)
def test_an_unknown_state_or_material_suggests_one(
    vocab, prop: str, value: str, first: str
) -> None:
    from virf.world.scene import build_scene

    data = {
        "instances": [inst("Candle", "Candle_1")],
        "assertions": [rel("Candle_1", prop, value)],
    }
    with pytest.raises(InputError, match=f"closest known: {first}"):
        build_scene(data, vocab)
