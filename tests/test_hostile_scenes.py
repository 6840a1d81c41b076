"""Scenes that can be read two ways, or describe impossible worlds, are bad input.

Each case here once verified SAFE, or depended on the order or spelling of
the scene, or hung; now each is a one-line input error."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest
from conftest import inst, rel

from virf.errors import InputError, read_input_file, read_json_file


def scene(
    instances: list[Any], assertions: list[Any] | None = None, **extra: Any
) -> dict[str, Any]:
    return {"instances": instances, "assertions": assertions or [], **extra}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        # A Bread called 'pan' beside a metal Pan_1: 'find Pan' could mean either.
        (scene([inst("Bread", "pan"), inst("Pan", "Pan_1")]), "reads as the ontology term 'Pan'"),
        (scene([inst("Bread", "stove_knob")]), "reads as the ontology term 'StoveKnob'"),
        (scene([inst("Pot", "pot_1"), inst("Pot", "Pot_1")]), "differ only in case"),
        (
            scene(
                [inst("Robot", "R_1"), inst("Mug", "Mug_1"), inst("Cup", "Cup_1")],
                [rel("R_1", "isHolding", "Mug_1"), rel("Cup_1", "isHeldBy", "R_1")],
            ),
            "a robot holds one object",
        ),
        (
            scene(
                [inst("Apple", "Apple_1"), inst("Fridge", "Fridge_1"), inst("CounterTop", "C_1")],
                [rel("Apple_1", "isInside", "Fridge_1"), rel("Apple_1", "isOn", "C_1")],
            ),
            "at once",
        ),
        (scene([inst("Pot", "Pot_1")], [rel("Pot_1", "contains", "Pot_1")]), "itself"),
        (
            scene(
                [inst("Box", "Box_1"), inst("Drawer", "Drawer_1")],
                [rel("Box_1", "contains", "Drawer_1"), rel("Drawer_1", "contains", "Box_1")],
            ),
            "containment cycle",
        ),
        (scene([{"class_name": "Pot", "instance_name": None}]), "must be a string"),
        (scene([{"class_name": "Pot", "instance_name": True}]), "must be a string"),
        (scene([inst("Pot", "Pot_1\n")]), "instance name"),
        (scene([inst("Pot", "P" * 200)]), "at most 128"),
        (scene([inst("Pot", "Pot_1")], unknown_contents=[["Pot_1"]]), "unknown_contents"),
        (scene([inst("Pot", "Pot_1")], closed_world=[""]), "empty entry"),
        (
            scene([inst("Pot", "Pot_1")], [{"subject": "Pot_1", "property": None, "object": "x"}]),
            "string",
        ),
        (
            scene([inst("Pot", "Pot_1")], [rel("Pot_1", "hasState", "hot", "data_property ")]),
            "must be object_property or data_property",
        ),
    ],
)
def test_ambiguous_or_impossible_scenes_are_refused(
    tutor, data: dict[str, Any], message: str
) -> None:
    with pytest.raises(InputError, match=message):
        tutor.scene(data)


def test_scene_size_limits(tutor) -> None:
    from virf.world.scene import MAX_INSTANCES

    many = [inst("Apple", f"Apple_{i}") for i in range(MAX_INSTANCES + 1)]
    with pytest.raises(InputError, match="the limit is"):
        tutor.scene(scene(many))


def test_duplicate_keys_and_nan_are_refused(tmp_path: Path) -> None:
    dup = tmp_path / "dup.json"
    dup.write_text('{"instances": [], "assertions": [], "assertions": []}', encoding="utf-8")
    with pytest.raises(InputError, match="duplicate key 'assertions'"):
        read_json_file(dup, "scene")
    nan = tmp_path / "nan.json"
    nan.write_text('{"instances": [], "weight": NaN}', encoding="utf-8")
    with pytest.raises(InputError, match="NaN is not a JSON number"):
        read_json_file(nan, "scene")


def test_only_regular_files_are_read(tmp_path: Path) -> None:
    fifo = tmp_path / "scene.fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        read_input_file(fifo, "scene")  # would block forever if opened
    with pytest.raises(InputError, match="not a regular file"):
        read_input_file("/dev/zero", "plan")  # would never end
    big = tmp_path / "big.txt"
    big.write_text("find Pot_1\n" * 20, encoding="utf-8")
    with pytest.raises(InputError, match="larger than"):
        read_input_file(big, "plan", limit=100)
    assert json.loads(json.dumps(read_input_file(big, "plan"))).startswith("find Pot_1")


@pytest.mark.parametrize("plan", [[], ["# only a comment", ""], "find Pot_1"])
def test_api_refuses_plans_with_nothing_to_verify(tutor, plan: Any) -> None:
    with pytest.raises(InputError, match="plan"):
        tutor.verify(scene([inst("Pot", "Pot_1")]), plan)


def test_relations_are_not_literals(tutor) -> None:
    data = scene(
        [inst("Pot", "Pot_1"), inst("CounterTop", "C_1")],
        [rel("Pot_1", "isOn", "C_1", "data_property")],
    )
    with pytest.raises(InputError, match="write it with type object_property"):
        tutor.scene(data)
    # The paper's own spelling of a state as a data value stays accepted.
    ok = scene(
        [inst("Fridge", "Fridge_1")], [rel("Fridge_1", "hasState", "closed", "data_property")]
    )
    assert tutor.scene(ok).objects["Fridge_1"] == frozenset({"Fridge"})
