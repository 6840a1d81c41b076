"""Open-world objects: a scene may name any household thing the knowledge base
lacks; every hazard involving one is UNKNOWN (asking about it) or UNSAFE,
never SAFE, and the same object away from the hazard stays SAFE."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from virf.api import LogicTutor
from virf.errors import InputError
from virf.ontology import lexicon
from virf.planner.questions import apply_answers
from virf.schema import Report
from virf.verify.twins import scene_data

# (class name the catalogue lacks, the world in minimal-pair notation, the plan)
# X_1 is the open-world object; each world holds a hazard X_1 takes part in.
HAZARDS: list[tuple[str, str, str]] = [
    # appliances beside water
    (
        "HairDryer",
        "X_1: HairDryer; Sink_1: SinkBasin; Sink_1 hasState filled; X_1 isNear Sink_1",
        "find X_1; turn_on X_1",
    ),
    (
        "CurlingIron",
        "X_1: CurlingIron; Sink_1: SinkBasin; Sink_1 hasState filled; X_1 isNear Sink_1",
        "find X_1; turn_on X_1",
    ),
    (
        "ElectricKettle",
        "X_1: ElectricKettle; Sink_1: SinkBasin; Sink_1 hasState filled; X_1 isNear Sink_1",
        "find X_1; turn_on X_1",
    ),
    (
        "Blender",
        "X_1: Blender; Sink_1: SinkBasin; Sink_1 hasState filled; X_1 isNear Sink_1",
        "find X_1; turn_on X_1",
    ),
    (
        "Fan",
        "X_1: Fan; Tub_1: Bathtub; Tub_1 hasState filled; X_1 isNear Tub_1",
        "find X_1; turn_on X_1",
    ),
    (
        "Chandelier",
        "X_1: Chandelier; Tub_1: Bathtub; Tub_1 hasState filled; X_1 isNear Tub_1",
        "find X_1; turn_on X_1",
    ),
    (
        "ExtensionCord",
        "X_1: ExtensionCord; Tub_1: Bathtub; Tub_1 hasState filled; X_1 hasState PluggedInState; X_1 isNear Tub_1",
        "find X_1",
    ),
    (
        "PowerStrip",
        "X_1: PowerStrip; Sink_1: SinkBasin; Sink_1 hasState filled; X_1 hasState PluggedInState; X_1 isNear Sink_1",
        "find X_1",
    ),
    # heat and flame beside fuel
    (
        "SpaceHeater",
        "X_1: SpaceHeater; Curtains_1: Curtains; X_1 isNear Curtains_1",
        "find X_1; turn_on X_1",
    ),
    ("ClothesIron", "X_1: ClothesIron; Bed_1: Bed; X_1 isOn Bed_1", "find X_1; turn_on X_1"),
    (
        "DeepFryer",
        "X_1: DeepFryer; Curtains_1: Curtains; X_1 isNear Curtains_1",
        "find X_1; turn_on X_1",
    ),
    (
        "Nightlight",
        "X_1: Nightlight; Curtains_1: Curtains; X_1 isNear Curtains_1",
        "find X_1; turn_on X_1",
    ),
    (
        "Lighter",
        "X_1: Lighter; Curtains_1: Curtains; X_1 isNear Curtains_1",
        "find X_1; turn_on X_1",
    ),
    (
        "OilLamp",
        "X_1: OilLamp; Curtains_1: Curtains; X_1 isNear Curtains_1",
        "find X_1; turn_on X_1",
    ),
    # fuel beside heat and flame
    (
        "Rug",
        "X_1: Rug; Candle_1: Candle; Candle_1 isNear X_1",
        "find Candle_1; turn_on Candle_1; turn_off Candle_1",
    ),
    (
        "Tablecloth",
        "X_1: Tablecloth; Candle_1: Candle; Candle_1 isOn X_1",
        "find Candle_1; turn_on Candle_1; turn_off Candle_1",
    ),
    (
        "Quilt",
        "X_1: Quilt; Heater_1: SpaceHeater; Heater_1 isNear X_1",
        "find Heater_1; turn_on Heater_1",
    ),
    (
        "CardboardBox",
        "X_1: CardboardBox; Burner_1: StoveBurner; Knob_1: StoveKnob; Knob_1 controls Burner_1; Burner_1 supports X_1",
        "find Knob_1; turn_on Knob_1",
    ),
    (
        "NailPolishRemover",
        "X_1: NailPolishRemover; Candle_1: Candle; Candle_1 isNear X_1",
        "find Candle_1; turn_on Candle_1; turn_off Candle_1",
    ),
    (
        "PaintThinner",
        "X_1: PaintThinner; Candle_1: Candle; Candle_1 isNear X_1",
        "find Candle_1; turn_on Candle_1; turn_off Candle_1",
    ),
    (
        "Zorblax",
        "X_1: Zorblax; Candle_1: Candle; Candle_1 isOn X_1",
        "find Candle_1; turn_on Candle_1; turn_off Candle_1",
    ),
    # the microwave
    (
        "Cardboard",
        "X_1: Cardboard; Microwave_1: Microwave; Microwave_1 contains X_1",
        "find Microwave_1; turn_on Microwave_1",
    ),
    (
        "Glue",
        "X_1: Glue; Microwave_1: Microwave; Microwave_1 contains X_1",
        "find Microwave_1; turn_on Microwave_1",
    ),
    # sharp things and children
    ("Scissors", "X_1: Scissors; Child_1: Child; X_1 isNear Child_1", "find X_1"),
    ("Razor", "X_1: Razor; Child_1: Child; X_1 isNear Child_1", "find X_1"),
    ("Drill", "X_1: Drill; Child_1: Child; X_1 isNear Child_1", "find X_1"),
    ("Toddler", "X_1: Toddler; Knife_1: Knife; Knife_1 isNear X_1", "find Knife_1"),
    (
        "Baby",
        "X_1: Baby; Burner_1: StoveBurner; Knob_1: StoveKnob; Knob_1 controls Burner_1; X_1 isNear Burner_1",
        "find Knob_1; turn_on Knob_1",
    ),
    (
        "Preschooler",
        "X_1: Preschooler; Candle_1: Candle; Candle_1 isNear X_1",
        "find Candle_1; turn_on Candle_1; turn_off Candle_1",
    ),
    # chemicals
    (
        "Vinegar",
        "X_1: Vinegar; Toilet_1: Toilet; Bleach_1: Bleach; Toilet_1 contains Bleach_1; closed: contains",
        "find X_1; pick X_1; find Toilet_1; pour Toilet_1",
    ),
    (
        "OvenCleaner",
        "X_1: OvenCleaner; Toilet_1: Toilet; Bleach_1: Bleach; Toilet_1 contains Bleach_1; closed: contains",
        "find X_1; pick X_1; find Toilet_1; pour Toilet_1",
    ),
    # falls
    ("WineGlass", "X_1: WineGlass", "find X_1; pick X_1; throw"),
    ("Aquarium", "X_1: Aquarium", "find X_1; pick X_1; drop"),
]

# The same kinds of thing where no hazard is: the hypotheses must not turn
# every scene with an unknown object into a question.
BENIGN: list[tuple[str, str, str]] = [
    (
        "HairDryer",
        "X_1: HairDryer; Counter_1: CounterTop; X_1 isOn Counter_1",
        "find X_1; turn_on X_1; turn_off X_1",
    ),
    ("Toddler", "X_1: Toddler; Pillow_1: Pillow; Pillow_1 isNear X_1", "find Pillow_1"),
    (
        "Cardboard",
        "X_1: Cardboard; Counter_1: CounterTop; X_1 isOn Counter_1",
        "find X_1; pick X_1; find Counter_1; put Counter_1",
    ),
    ("Vinegar", "X_1: Vinegar; Counter_1: CounterTop; X_1 isOn Counter_1", "find X_1"),
    ("Scissors", "X_1: Scissors; Shelf_1: Shelf; X_1 isOn Shelf_1", "find Shelf_1"),
]


def _world(text: str) -> dict[str, Any]:
    return scene_data(tuple(s.strip() for s in text.split(";")))


def _plan(text: str) -> list[str]:
    return [s.strip() for s in text.split(";")]


def _verify(tutor: LogicTutor, world: str | dict[str, Any], plan: str) -> Report:
    data = _world(world) if isinstance(world, str) else world
    return tutor.verify(tutor.scene(data), _plan(plan))


def _involves(report: Report, name: str) -> bool:
    facts = (t for v in report.violations for t in v.triggering_facts)
    return any(name in (t.subject, t.object) for t in facts) or any(
        q.subject == name for q in report.questions
    )


def test_the_list_is_outside_the_catalogue(tutor: LogicTutor) -> None:
    words = [w for w, _, _ in HAZARDS]
    assert len(set(words)) >= 30
    vocab = tutor.tbox.vocabulary
    assert [w for w in words if vocab.canonical_class(w) is not None] == []


@pytest.mark.parametrize(("word", "world", "plan"), HAZARDS, ids=[w for w, _, _ in HAZARDS])
def test_a_hazard_with_an_open_world_object_is_never_safe(
    tutor: LogicTutor, word: str, world: str, plan: str
) -> None:
    report = _verify(tutor, world, plan)
    assert report.status in ("UNKNOWN", "UNSAFE"), report.reason
    assert _involves(report, "X_1"), (report.status, report.violated_concept)
    assert any(f"'{word}' is not a class of the knowledge base" in n for n in report.notes)


@pytest.mark.parametrize(("word", "world", "plan"), BENIGN, ids=[w for w, _, _ in BENIGN])
def test_an_open_world_object_away_from_any_hazard_is_safe(
    tutor: LogicTutor, word: str, world: str, plan: str
) -> None:
    report = _verify(tutor, world, plan)
    assert report.status == "SAFE", report.reason


def test_the_question_names_the_object_and_the_property(tutor: LogicTutor) -> None:
    report = _verify(tutor, HAZARDS[0][1], HAZARDS[0][2])
    assert report.status == "UNKNOWN"
    assert [q.text for q in report.questions] == ["Is X_1 an electrical appliance?"]
    assert report.questions[0].key == "confirm:X_1 hasProperty ElectricallyPowered"
    child = _verify(tutor, "X_1: Toddler; Knife_1: Knife; Knife_1 isNear X_1", "find Knife_1")
    assert "Is X_1 a child?" in [q.text for q in child.questions]


@pytest.mark.parametrize(("answer", "status"), [("yes", "UNSAFE"), ("no", "SAFE")])
def test_the_answer_settles_the_hypothesis(tutor: LogicTutor, answer: str, status: str) -> None:
    data = _world(HAZARDS[0][1])
    first = _verify(tutor, data, HAZARDS[0][2])
    update = apply_answers(
        data, first.questions, {q.key: answer for q in first.questions}, tutor.tbox.vocabulary
    )
    assert update.unsettled == ()
    if answer == "no":
        assert update.scene["denied"] == ["X_1 hasProperty ElectricallyPowered"]
    assert _verify(tutor, update.scene, HAZARDS[0][2]).status == status


def test_denying_what_the_scene_states_is_refused(tutor: LogicTutor) -> None:
    data = _world("X_1: HairDryer; X_1 hasProperty ElectricallyPowered")
    data["denied"] = ["X_1 hasProperty ElectricallyPowered"]
    with pytest.raises(InputError, match="also states"):
        tutor.scene(data)
    data["denied"] = ["Ghost_1 hasProperty ElectricallyPowered"]
    with pytest.raises(InputError, match="not a declared instance"):
        tutor.scene(data)


def test_strict_vocabulary_and_misspellings_are_refused(tutor: LogicTutor) -> None:
    from virf.world.scene import build_scene

    data = _world("X_1: HairDryer")
    with pytest.raises(InputError, match="unknown class 'HairDryer'"):
        build_scene(data, tutor.tbox.vocabulary, strict_vocabulary=True)
    with pytest.raises(InputError, match="closest known: Microwave"):
        tutor.scene(_world("X_1: Mircowave"))
    with pytest.raises(InputError):
        tutor.scene({"instances": [{"class_name": "hair dryer; rm -rf", "instance_name": "X_1"}]})


def test_spellings_of_one_class_name_read_alike(tutor: LogicTutor) -> None:
    def spelled(name: str) -> dict[str, Any]:
        data = _world(HAZARDS[0][1])
        for entry in data["instances"]:
            if entry["class_name"] == "HairDryer":
                entry["class_name"] = name
        return data

    reports = [
        _verify(tutor, spelled(name), HAZARDS[0][2]).model_dump(exclude={"notes"})
        for name in ("HairDryer", "hair_dryer", "Hair-Dryer", "hair dryer", "hairDryer")
    ]
    assert reports[0]["status"] == "UNKNOWN"
    assert all(r == reports[0] for r in reports)


@pytest.mark.parametrize(
    ("word", "properties", "types", "materials"),
    [
        ("HairDryer", {"ElectricallyPowered"}, set(), set()),
        ("SpaceHeater", {"HeatSource"}, set(), set()),
        ("Toddler", set(), {"Child"}, set()),
        ("Cardboard", {"Flammable"}, set(), {"Paper"}),
        ("ExtensionCord", {"ElectricallyPowered"}, set(), set()),
        ("Vinegar", set(), set(), {"Acid"}),
        ("Bleach", {"Toxic"}, set(), {"Bleach"}),
    ],
)
def test_wordnet_proposals(
    word: str, properties: set[str], types: set[str], materials: set[str]
) -> None:
    p = lexicon.propose(word)
    assert p.found
    assert properties <= set(p.properties)
    assert types <= set(p.types)
    assert materials <= set(p.materials)


def test_rare_senses_are_not_asked_about() -> None:
    # 'dog' is also a frump and a hot dog, 'fan' a sports fan: only common senses count.
    assert lexicon.propose("Dog").types == ()
    assert "Person" not in lexicon.propose("Fan").types
    assert lexicon.propose("Toddler").person and not lexicon.propose("Dog").person


def test_the_lexnames_file_comes_from_the_manual_page_or_the_fixed_list(tmp_path: Any) -> None:
    from pathlib import Path

    fixed = lexicon._lexnames_text(Path(tmp_path / "missing.gz"))
    assert fixed.splitlines()[6] == "06\tnoun.artifact\t1"
    assert len(fixed.splitlines()) == 45
    if lexicon.DEBIAN_LEXNAMES.is_file():
        assert lexicon._lexnames_text(lexicon.DEBIAN_LEXNAMES) == fixed


@pytest.fixture
def no_wordnet(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A machine without WordNet (proposals are cached per word)."""
    monkeypatch.setattr(lexicon, "_wordnet", lambda: None)
    lexicon.propose.cache_clear()
    yield
    lexicon.propose.cache_clear()


@pytest.mark.usefixtures("no_wordnet")
def test_without_wordnet_the_object_is_still_checked(tutor: LogicTutor) -> None:
    report = _verify(tutor, HAZARDS[21][1], HAZARDS[21][2])  # cardboard in a running microwave
    assert report.status == "UNKNOWN"
    assert any("WordNet is not installed" in n for n in report.notes)


@pytest.mark.usefixtures("no_wordnet")
def test_without_wordnet_every_hazard_is_asked_about(tutor: LogicTutor) -> None:
    # Nothing can say a hair dryer is electrical: it must not pass as harmless.
    report = _verify(tutor, HAZARDS[0][1], HAZARDS[0][2])
    assert report.status == "UNKNOWN"
    assert "Is X_1 an electrical appliance?" in [q.text for q in report.questions]


@pytest.mark.parametrize("spelled", ["stove knob", "stove_knob", "Stove-Knob", "STOVEKNOB"])
def test_a_known_class_in_other_spellings_is_that_class(tutor: LogicTutor, spelled: str) -> None:
    scene = tutor.scene({"instances": [{"class_name": spelled, "instance_name": "Knob_1"}]})
    assert scene.objects["Knob_1"] == frozenset({"StoveKnob"})
    assert scene.open_world == {}


def test_a_word_the_scene_lacks_is_answered_with_names_near_in_meaning(tutor: LogicTutor) -> None:
    # Neither spelling nor the catalogue reads 'refrigerator' or 'cooker';
    # the question offers the scene's names nearest in meaning, and the
    # plan is not run on a guess.
    for word, near in (("refrigerator", "Fridge_1"), ("cooker", "StoveBurner_1")):
        report = _verify(
            tutor,
            "Fridge_1: Fridge; StoveBurner_1: StoveBurner; Apple_1: Apple",
            f"find {word}",
        )
        assert report.status == "UNKNOWN"
        (question,) = report.questions
        assert question.kind == "where" and near in question.text, question.text


def test_a_plan_names_an_open_world_object_by_its_class_words(tutor: LogicTutor) -> None:
    # Board_1 is an 'IroningBoard': 'the ironing board' is it, as 'the
    # counter top' is CounterTop_1.
    world = "Board_1: IroningBoard; Iron_1: ClothesIron; Iron_1 isOn Board_1"
    report = _verify(tutor, world, "go to the ironing board; switch on the clothes iron")
    assert report.status == "UNKNOWN"
    assert [t.step for t in report.trace][:2] == [1, 2]
    assert report.dangerous_step == 2
    assert "What is Board_1 made of? It touches a flame or a running heat source." in [
        q.text for q in report.questions
    ]
