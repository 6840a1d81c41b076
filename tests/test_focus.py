"""The objects an instruction names, and the constraint narrowed to them.

Pure tests: no model is loaded.  Each case pairs instructions that differ only
in what they name, in one scene, so the focus can only come from the words.
"""

from __future__ import annotations

import pytest
from conftest import inst, rel

from virf.ontology.tbox import Vocabulary
from virf.planner.constraint import plan_constraint
from virf.planner.focus import Focus, named_objects
from virf.world.scene import Scene, build_scene


@pytest.fixture(scope="module")
def room(vocab: Vocabulary) -> Scene:
    """A kitchen corner no test elsewhere uses: two mugs, eggs in a fridge, a
    knob controlling a burner, a kettle on the counter, and a harp nobody
    declared anything about."""
    return build_scene(
        {
            "instances": [
                inst("Robot", "Robot_1"),
                inst("Mug", "Mug_1"),
                inst("Mug", "Mug_2"),
                inst("Egg", "Egg_1"),
                inst("Fridge", "Fridge_1"),
                inst("StoveBurner", "StoveBurner_1"),
                inst("StoveKnob", "StoveKnob_1"),
                inst("Kettle", "Kettle_1"),
                inst("CounterTop", "CounterTop_1"),
                inst("Harp", "Harp_1"),
                inst("Sink", "Sink_1"),
            ],
            "assertions": [
                rel("Egg_1", "isInside", "Fridge_1"),
                rel("StoveKnob_1", "controls", "StoveBurner_1"),
                rel("Kettle_1", "isOn", "CounterTop_1"),
            ],
        },
        vocab,
    )


@pytest.mark.parametrize(
    ("instruction", "expected"),
    [
        # A type names every instance, in any case or number.
        ("Rinse the mugs.", {"Mug_1", "Mug_2"}),
        ("rinse the MUG", {"Mug_1", "Mug_2"}),
        # An instance names itself; the fridge holding the egg comes with it.
        ("Boil Egg_1.", {"Egg_1", "Fridge_1"}),
        ("Boil the eggs.", {"Egg_1", "Fridge_1"}),
        # The knob that controls the named burner comes with it.
        ("Turn on the StoveBurner.", {"StoveBurner_1", "StoveKnob_1"}),
        ("Turn on the stove burner.", {"StoveBurner_1", "StoveKnob_1"}),
        # 'stove' names no type: it is a word of two objects' names.
        ("Turn on the stove.", {"StoveBurner_1", "StoveKnob_1"}),
        # ... but 'top' is a word that says where, never what.
        ("Put it on top.", set()),
        ("Fill the kettle.", {"Kettle_1", "CounterTop_1"}),
        # An object the catalogue does not know is named like any other.
        ("Play the harp.", {"Harp_1"}),
        ("Sing a song.", set()),
    ],
)
def test_an_instruction_names_what_its_words_say(
    vocab: Vocabulary, room: Scene, instruction: str, expected: set[str]
) -> None:
    assert named_objects(instruction, room, vocab) == expected


def test_the_robot_is_never_in_focus(vocab: Vocabulary, room: Scene) -> None:
    assert "Robot_1" not in named_objects("Robot_1, rinse the mug.", room, vocab)


def test_a_focused_constraint_offers_only_lines_about_named_objects(
    vocab: Vocabulary, room: Scene
) -> None:
    focus = Focus.of("Put the egg in the sink.", room, vocab)
    assert focus.objects == {"Egg_1", "Fridge_1", "Sink_1"}
    lines = focus.constraint().lines()
    assert lines and all(line.split()[1] in focus.objects for line in lines)
    # Every line about those objects the whole scene allows is still there.
    whole = plan_constraint(room, vocab)
    assert set(lines) == {line for line in whole.lines() if line.split()[1] in focus.objects}
    assert {"find Egg_1", "pick Egg_1", "open Fridge_1", "put Sink_1"} <= set(lines)
    assert "turn_on StoveKnob_1" not in lines


def test_an_instruction_naming_nothing_leaves_every_line(vocab: Vocabulary, room: Scene) -> None:
    focus = Focus.of("Make yourself useful.", room, vocab)
    assert focus.objects == frozenset()
    assert focus.constraint() == plan_constraint(room, vocab)


def test_a_correction_widens_the_focus_with_its_objects(vocab: Vocabulary, room: Scene) -> None:
    focus = Focus.of("Rinse the mug.", room, vocab)
    assert "turn_off StoveKnob_1" not in focus.constraint().lines()
    wider = focus.widen(["find Mug_1", "turn_off StoveKnob_1", "put the moon"])
    assert wider.objects == focus.objects | {"StoveKnob_1"}
    assert "turn_off StoveKnob_1" in wider.constraint().lines()
    # Without a focus there is nothing to widen: every line is allowed already.
    everything = Focus.of("Sing a song.", room, vocab)
    assert everything.widen(["turn_off StoveKnob_1"]) == everything
