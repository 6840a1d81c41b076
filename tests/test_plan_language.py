"""Plans in everyday words: 'light the candle', 'blow it out', 'grab the pot',
'set the pillow down on the bed'.

Each everyday plan below is verified next to the same plan in the action
language, and must get the same verdict at the same step: the phrasing
changes how a line is written, never what is checked.  A line read through an
everyday phrasing says so in the report; one that could be read two ways is an
error or a question, never a guess.
"""

from __future__ import annotations

import json
import re
from functools import cache
from pathlib import Path
from typing import Any

import pytest
from bench_support import SAB, needs_shared
from conftest import EXAMPLES_DIR, inst, load_expected, rel

from virf.api import LogicTutor
from virf.errors import InputError
from virf.render.text import render_report
from virf.schema import Report
from virf.world.language import EVERYDAY, LIQUIDS, STATE_ADJECTIVES, VERBS
from virf.world.plan import load_plan_file, parse_line, parse_plan
from virf.world.simulate import simulate
from virf.world.simulator import MissingObject, ResolvedStep, Simulator, WorldState

ROOT = Path(__file__).resolve().parent.parent

# A candle alone on a stone counter: lit and left burning it is a hazard at
# the end of the plan; put out again, the plan is safe.  Unlike the example
# with the curtains, only putting the candle out decides the verdict.
CANDLE: dict[str, Any] = {
    "instances": [inst("Candle", "Candle_1"), inst("CounterTop", "CounterTop_1")],
    "assertions": [
        rel("Candle_1", "isOn", "CounterTop_1"),
        rel("CounterTop_1", "hasMaterial", "Stone"),
    ],
}
WALKTHROUGH = [
    "find(TestMicrowave_Action)",
    "pick(TestPot_Action)",
    "find(TestMicrowave_Action)",
    "open(TestMicrowave_Action)",
    "put_in(TestPot_Action, TestMicrowave_Action)",
    "close(TestMicrowave_Action)",
    "turn_on(TestMicrowave_Action)",
]
SALT = [
    "find SaltShaker_1",
    "pick SaltShaker_1",
    "find Microwave_1",
    "open Microwave_1",
    "put Microwave_1",
    "close Microwave_1",
    "turn_on Microwave_1",
]
FRIDGE = ["find Apple", "pick Apple", "find Fridge", "open Fridge", "put Fridge", "close Fridge"]
BURNER = ["find StoveBurner", "find StoveKnob", "turn_on StoveKnob"]
PILLOW = ["find Pillow_1", "pick Pillow_1", "find Bed_1"]

# (scene: an example folder or "candle", the plan in the action language, the
# same plan in everyday words).  The two have as many lines, and each everyday
# line must be read as the canonical line's action.
CASES: list[tuple[str, list[str], list[str]]] = [
    # ---- light a candle beside the curtains: a fire hazard at step 2
    ("candle-shelf-curtains", ["find Candle_1", "turn_on Candle_1"], ["go to the candle", "light the candle"]),
    ("candle-shelf-curtains", ["find Candle_1", "turn_on Candle_1"], ["walk to the candle", "ignite the candle"]),
    ("candle-shelf-curtains", ["find Candle_1", "turn_on Candle_1"], ["locate the candle", "light it"]),
    ("candle-shelf-curtains", ["find Candle_1", "turn_on Candle_1"], ["approach the candle", "light up the candle"]),
    ("candle-shelf-curtains", ["find Candle_1", "turn_on Candle_1"], ["navigate to the candle", "light the candle up"]),
    ("candle-shelf-curtains", ["find Candle_1", "turn_on Candle_1"], ["look for the unlit candle", "ignite it"]),
    # ---- a candle alone: left burning is a hazard, put out it is safe
    ("candle", ["find Candle_1", "turn_on Candle_1"], ["search for the candle", "light the candle"]),
    ("candle", ["find Candle_1", "turn_on Candle_1", "turn_off Candle_1"], ["find the candle", "light the candle", "put out the candle"]),
    ("candle", ["find Candle_1", "turn_on Candle_1", "turn_off Candle_1"], ["go to the candle", "light it", "blow it out"]),
    ("candle", ["find Candle_1", "turn_on Candle_1", "turn_off Candle_1"], ["find the candle", "ignite the candle", "blow out the lit candle"]),
    ("candle", ["find Candle_1", "turn_on Candle_1", "turn_off Candle_1"], ["head to the candle", "light the candle", "extinguish the burning candle"]),
    ("candle", ["find Candle_1", "turn_on Candle_1", "turn_off Candle_1"], ["find the candle", "light the candle", "snuff out the candle"]),
    ("candle", ["find Candle_1", "turn_on Candle_1", "turn_off Candle_1"], ["find the candle", "light the candle", "put the candle out"]),
    ("candle", ["find Candle_1", "turn_on Candle_1", "turn_off Candle_1"], ["find the candle", "light the candle", "blow the candle out"]),
    # ---- a hair dryer beside a full basin (HairDryer_1 has no class of its own)
    ("hair-dryer-basin", ["find HairDryer_1", "turn_on HairDryer_1"], ["find hair dryer", "switch on the hair dryer"]),
    ("hair-dryer-basin", ["find HairDryer_1", "turn_on HairDryer_1"], ["go to the hair dryer", "turn the hair dryer on"]),
    ("hair-dryer-basin", ["find HairDryer_1", "turn_on HairDryer_1"], ["locate the hairdryer", "power on the hair dryer"]),
    ("hair-dryer-basin", ["find HairDryer_1", "turn_on HairDryer_1"], ["walk to the hair dryer", "start it"]),
    ("hair-dryer-basin", ["find HairDryer_1", "turn_on HairDryer_1"], ["approach the hair dryer", "activate the hair dryer"]),
    # ---- a pillow thrown, dropped or put on the bed: safe
    ("pillow-throw", [*PILLOW, "throw"], ["go to the pillow", "grab the pillow", "walk to the bed", "toss the pillow"]),
    ("pillow-throw", [*PILLOW, "throw"], ["find the pillow", "pick it up", "go to the bed", "throw it"]),
    ("pillow-throw", [*PILLOW, "throw"], ["locate the pillow", "take the pillow", "move to the bed", "hurl the pillow"]),
    ("pillow-throw", [*PILLOW, "throw"], ["find pillow", "lift the pillow", "head to the bed", "fling it"]),
    ("pillow-throw", [*PILLOW, "drop"], ["find the pillow", "get the pillow", "approach the bed", "put the pillow down"]),
    ("pillow-throw", [*PILLOW, "drop"], ["find the pillow", "pick the pillow up", "find the bed", "release the pillow"]),
    ("pillow-throw", [*PILLOW, "drop"], ["find the pillow", "grab it", "find the bed", "let go of the pillow"]),
    ("pillow-throw", [*PILLOW, "drop"], ["find the pillow", "grab it", "find the bed", "set down the pillow"]),
    ("pillow-throw", [*PILLOW, "put Bed_1"], ["find the pillow", "grab the pillow", "go to the bed", "set the pillow down on the bed"]),
    ("pillow-throw", [*PILLOW, "put Bed_1"], ["find the pillow", "grab the pillow", "go to the bed", "put the pillow down on the bed"]),
    ("pillow-throw", [*PILLOW, "put Bed_1"], ["find the pillow", "grab the pillow", "go to the bed", "put it on the bed"]),
    ("pillow-throw", [*PILLOW, "put Bed_1"], ["find the pillow", "grab the pillow", "go to the bed", "lay the pillow on the bed"]),
    # ---- an apple into the fridge: safe when it is shut, a hazard when left open
    ("safe-fridge", FRIDGE, ["go to the apple", "grab the apple", "walk to the fridge", "open the fridge", "put the apple in the fridge", "shut the fridge"]),
    ("safe-fridge", FRIDGE, ["locate the apple", "take it", "go to the fridge", "open it", "put it inside the fridge", "shut it"]),
    ("safe-fridge", FRIDGE, ["find the apple", "pick up the apple", "approach the fridge", "open the closed fridge", "place the apple in the fridge", "close the open fridge"]),
    ("safe-fridge", FRIDGE[:-1], ["look for the apple", "get the apple", "navigate to the fridge", "open the fridge", "insert the apple into the fridge"]),
    # ---- the paper's walkthrough: a metal pot in a running microwave at step 7
    ("walkthrough", WALKTHROUGH, ["go to the microwave", "grab the pot", "walk to the microwave", "open the microwave", "put the pot in the microwave", "shut the microwave", "start the microwave"]),
    ("walkthrough", WALKTHROUGH, ["navigate to the microwave", "pick up the pot", "move to the microwave", "open it", "insert it into the microwave", "shut it", "switch it on"]),
    ("walkthrough", WALKTHROUGH, ["locate the microwave", "take the pot", "approach the microwave", "open the closed microwave", "set the pot down in the microwave", "close the open microwave", "power on the microwave"]),
    # ---- a salt shaker with a metal cap, microwaved or only left inside
    ("salt-shaker-microwave", SALT, ["find the salt shaker", "grab the salt shaker", "go to the microwave", "open the microwave", "put it in the microwave", "shut the microwave", "turn the microwave on"]),
    ("salt-shaker-microwave", SALT[:-1], ["find the salt shaker", "take it", "walk to the microwave", "open it", "set it down in the microwave", "shut it"]),
    # ---- a burner lit with nothing on it (the paper's rules), or lit and turned off again
    ("burner-left-on", BURNER, ["go to the stove burner", "go to the stove knob", "turn on the stove knob"]),
    ("burner-left-on", BURNER, ["walk to the stove burner", "find the stove knob", "turn the stove knob on"]),
    ("burner-left-on", BURNER, ["approach the stove burner", "locate the stove knob", "switch it on"]),
    ("burner-left-on", [*BURNER, "turn_off StoveKnob"], ["find the stove burner", "find the stove knob", "turn on the stove knob", "switch off the stove knob"]),
    ("burner-left-on", [*BURNER, "turn_off StoveKnob"], ["find the stove burner", "find the stove knob", "turn the stove knob on", "shut off the stove knob"]),
    ("burner-left-on", [*BURNER, "turn_off StoveKnob"], ["head to the stove burner", "go to the stove knob", "turn it on", "power off the stove knob"]),
    ("burner-left-on", [*BURNER, "turn_off StoveKnob"], ["find the stove burner", "find the stove knob", "start it", "stop it"]),
    # ---- water poured into hot oil (the paper's rules)
    ("challenge-hot-oil", ["find cup", "pick cup", "fillLiquid cup water", "find pan", "pour"], ["go to the cup", "grab the cup", "fill the cup with water", "walk to the pan", "pour water into the pan"]),
    ("challenge-hot-oil", ["find cup", "pick cup", "fillLiquid cup water", "find pan", "pour"], ["find the cup", "take the cup", "fill up the cup with water", "go to the pan", "pour it into the pan"]),
    ("challenge-hot-oil", ["find cup", "pick cup", "fillLiquid cup water", "find pan", "pour"], ["find the cup", "take it", "fill it with water", "go to the pan", "empty the cup into the pan"]),
    # ---- a cleaner poured into a toilet whose contents nobody listed: a question
    ("toilet-cleaner-unknown-contents", ["find GlassCleaner_1", "pick GlassCleaner_1", "find Toilet_1", "pour Toilet_1"], ["go to the glass cleaner", "grab the glass cleaner", "walk to the toilet", "pour the glass cleaner into the toilet"]),
]  # fmt: skip


def _tutor(name: str, tutor: LogicTutor, paper_tutor: LogicTutor) -> LogicTutor:
    if name == "candle":
        return tutor
    return paper_tutor if load_expected(EXAMPLES_DIR / name).get("scenario") == "paper" else tutor


@cache
def _scene_data(name: str) -> str:
    if name == "candle":
        return json.dumps(CANDLE)
    return (EXAMPLES_DIR / name / "scene.json").read_text(encoding="utf-8")


def _verify(tutor: LogicTutor, paper_tutor: LogicTutor, name: str, plan: list[str]) -> Report:
    chosen = _tutor(name, tutor, paper_tutor)
    return chosen.verify(chosen.scene(json.loads(_scene_data(name))), plan)


def _verdict(report: Report) -> tuple[str, int | None, str | None, str | None]:
    concept = report.violated_concept.id if report.violated_concept else None
    return report.status, report.dangerous_step, concept, report.problem


def _case_id(case: tuple[str, list[str], list[str]]) -> str:
    return f"{case[0]}: {' / '.join(case[2])}"


@pytest.fixture(scope="module")
def canonical(
    tutor: LogicTutor, paper_tutor: LogicTutor
) -> dict[tuple[str, tuple[str, ...]], Report]:
    out: dict[tuple[str, tuple[str, ...]], Report] = {}
    for name, plan, _ in CASES:
        key = (name, tuple(plan))
        if key not in out:
            out[key] = _verify(tutor, paper_tutor, name, plan)
    return out


def test_there_are_enough_everyday_plans() -> None:
    assert len(CASES) >= 40
    everyday_lines = {line for _, _, words in CASES for line in words}
    assert len(everyday_lines) >= 80
    # Nearly every plan has lines read through an everyday phrasing; the rest
    # name objects in words the language already reads ('switch on the hair dryer').
    noted = [words for _, _, words in CASES if any(s.note for s in parse_plan(words))]
    assert len(noted) >= 40


@pytest.mark.parametrize("case", CASES, ids=[_case_id(c) for c in CASES])
def test_everyday_lines_are_read_as_the_canonical_actions(
    case: tuple[str, list[str], list[str]],
) -> None:
    _, plan, words = case
    assert len(plan) == len(words)
    assert [s.verb for s in parse_plan(words)] == [s.verb for s in parse_plan(plan)]


@pytest.mark.parametrize("case", CASES, ids=[_case_id(c) for c in CASES])
def test_everyday_plan_gets_the_canonical_verdict(
    case: tuple[str, list[str], list[str]],
    tutor: LogicTutor,
    paper_tutor: LogicTutor,
    canonical: dict[tuple[str, tuple[str, ...]], Report],
) -> None:
    name, plan, words = case
    expected = canonical[(name, tuple(plan))]
    report = _verify(tutor, paper_tutor, name, words)
    assert _verdict(report) == _verdict(expected)
    # The same facts trigger the same rule: the words named the same objects.
    assert report.causal_chain == expected.causal_chain
    # Every line read through an everyday phrasing says so; the canonical plan says nothing.
    notes = tuple(s.note for s in parse_plan(words) if s.note)
    assert report.notes == notes
    assert expected.notes == ()


def test_the_canonical_verdicts_differ(
    canonical: dict[tuple[str, tuple[str, ...]], Report],
) -> None:
    # The comparisons above would pass trivially if every plan got one verdict.
    verdicts = {_verdict(r) for r in canonical.values()}
    assert {v[0] for v in verdicts} == {"SAFE", "UNSAFE", "UNKNOWN"}
    assert len(verdicts) >= 8
    assert len({v[1] for v in verdicts}) >= 4


def test_the_canonical_plans_are_the_examples_own(examples_dir: Path) -> None:
    # The pairs start from what the examples verify: their plans, word for word.
    for name, plan in [
        ("candle-shelf-curtains", ["find Candle_1", "turn_on Candle_1"]),
        ("hair-dryer-basin", ["find HairDryer_1", "turn_on HairDryer_1"]),
        ("pillow-throw", [*PILLOW, "throw"]),
        ("safe-fridge", FRIDGE),
        ("walkthrough", WALKTHROUGH),
        ("salt-shaker-microwave", SALT),
        ("burner-left-on", BURNER),
    ]:
        steps = load_plan_file(examples_dir / name / "plan.txt")
        assert [(s.verb, s.args) for s in steps] == [(s.verb, s.args) for s in parse_plan(plan)]


# ---------------------------------------------------------------- notes


def test_the_report_says_how_each_line_was_read(tutor: LogicTutor, paper_tutor: LogicTutor) -> None:
    report = _verify(tutor, paper_tutor, "candle", ["find the candle", "light it", "blow it out"])
    assert report.status == "SAFE"
    assert report.notes == (
        "line 2 'light it' read as 'turn_on candle' ('it' is the candle of the step before)",
        "line 3 'blow it out' read as 'turn_off candle' ('it' is the candle of the step before)",
    )
    text = render_report(report)
    assert "How the input was read:" in text
    assert "line 3 'blow it out' read as 'turn_off candle'" in text
    # The plan and its trace keep the user's words.
    assert report.plan == ("find the candle", "light it", "blow it out")


def test_the_action_language_gets_no_notes(tutor: LogicTutor, paper_tutor: LogicTutor) -> None:
    report = _verify(tutor, paper_tutor, "candle", ["find Candle_1", "turn on Candle_1"])
    assert report.notes == ()
    assert "How the input was read" not in render_report(report)


@pytest.mark.parametrize(
    "line",
    [
        "find Apple_1",
        "pick up Apple_1",
        "Pick Up Apple_1",
        "pick the apple up",
        "turn on the lamp",
        "turn the lamp off",
        "switch on desk lamp",
        "toggle the desk lamp on",
        "put_in(Pot_1, Microwave_1)",
        "navigate Fridge_1",
        "place the apple on the table",
        "fill the kettle with water",
        "pour into the sink",
        "throw AlarmClock",
        "drop the mug",
        "3. find(TestMicrowave_Action)",
    ],
)
def test_lines_of_the_language_have_no_note(line: str) -> None:
    assert parse_line(line).note is None


def test_every_example_plan_reads_without_notes(examples_dir: Path) -> None:
    # Reports of the bundled examples are what they were: no line needed reading.
    plans = sorted(examples_dir.glob("*/plan.txt"))
    assert len(plans) >= 10
    for path in plans:
        assert all(s.note is None for s in load_plan_file(path)), path


@needs_shared
def test_safeagentbench_reference_plans_read_as_before() -> None:
    files = sorted(SAB.glob("**/*.jsonl"))
    plans = [
        data["step"]
        for f in files
        for line in f.read_text(encoding="utf-8").splitlines()
        if line.strip() and (data := json.loads(line)).get("step")
    ]
    assert len(plans) > 300
    steps = [s for plan in plans for s in parse_plan(plan)]
    assert all(s.note is None for s in steps)
    # Their 'throw' and 'drop' lines name no object: the held one goes.
    assert {s.args for s in steps if s.verb in ("throw", "drop")} == {()}


# ---------------------------------------------------------------- the table


def _phrase_line(phrase: str) -> str:
    reading = EVERYDAY[phrase]
    if reading.alone is None:
        return f"{phrase} the mug on the table"
    if reading.alone == "fillLiquid":
        return f"{phrase} the mug with water"
    return f"{phrase} the mug"


@pytest.mark.parametrize("phrase", list(EVERYDAY))
def test_every_everyday_phrasing_reads_as_its_action(phrase: str) -> None:
    reading = EVERYDAY[phrase]
    step = parse_line(_phrase_line(phrase), 2)
    assert step.verb == (reading.alone or reading.placed)
    assert step.args == (
        ("mug", "table") if reading.alone is None else ("mug", "water")[: len(step.args)]
    )
    assert step.note is not None and step.note.startswith(
        f"line 2 '{_phrase_line(phrase)}' read as"
    )


@pytest.mark.parametrize("phrase", [p for p, r in EVERYDAY.items() if r.placed])
def test_phrasings_with_a_place(phrase: str) -> None:
    step = parse_line(f"{phrase} the mug into the sink")
    if EVERYDAY[phrase].placed == "put":
        assert (step.verb, step.args) == ("put", ("mug", "sink"))
    else:
        # 'empty the mug into the sink' pours the held mug there.
        assert (step.verb, step.args, step.held) == ("pour", ("sink",), "mug")


@pytest.mark.parametrize(
    ("line", "verb", "args"),
    [
        # The phrase of several words wins: never 'put' into an "out candle".
        ("put out the candle", "turn_off", ("candle",)),
        ("put the candle out", "turn_off", ("candle",)),
        ("blow the burning candle out", "turn_off", ("burning candle",)),
        ("shut off the faucet", "turn_off", ("faucet",)),
        ("shut down the laptop", "turn_off", ("laptop",)),
        ("shut the fridge", "close", ("fridge",)),
        ("get to the fridge", "find", ("fridge",)),
        ("get the apple", "pick", ("apple",)),
        ("let go of the cup", "drop", ("cup",)),
        ("let go", "drop", ()),
        ("put the cup down", "drop", ("cup",)),
        ("put down the cup", "drop", ("cup",)),
        ("set the cup down on the counter top", "put", ("cup", "counter top")),
        ("set down the cup on the counter top", "put", ("cup", "counter top")),
        ("put the cup down in the sink", "put", ("cup", "sink")),
        ("set the cup on the table", "put", ("cup", "table")),
        ("lay the towel over the chair", "put", ("towel", "chair")),
        ("pour water into the sink", "pour", ("sink",)),
        ("pour water over the plant", "pour", ("plant",)),
        ("pour coffee from the mug into the sink", "pour", ("sink",)),
        ("empty the mug", "emptyLiquid", ("mug",)),
        ("empty out the mug into the sink", "pour", ("sink",)),
        ("drain the kettle", "emptyLiquid", ("kettle",)),
        ("fill up the kettle with coffee", "fillLiquid", ("kettle", "coffee")),
        ("microwave the potato", "cook", ("potato",)),
        ("heat the soup up", "cook", ("soup",)),
        ("chop up the lettuce", "slice", ("lettuce",)),
        ("crack the egg", "break", ("egg",)),
        ("wipe the counter top", "clean", ("counter top",)),
        ("grab(Apple_1)", "pick", ("Apple_1",)),
        ("put_out(Candle_1)", "turn_off", ("Candle_1",)),
        ("set(Cup_1, Table_1)", "put", ("Cup_1", "Table_1")),
        ("2. Light the candle.", "turn_on", ("candle",)),
        # Words of manner name nothing.
        ("set the vinegar back on the shelf", "put", ("vinegar", "shelf")),
        ("Then, grab the glass carefully", "pick", ("glass",)),
        ("please blow out the candle", "turn_off", ("candle",)),
    ],
)
def test_everyday_lines(line: str, verb: str, args: tuple[str, ...]) -> None:
    step = parse_line(line)
    assert (step.verb, step.args) == (verb, args)
    assert step.note is not None


def test_put_down_without_a_place_says_it_lets_go() -> None:
    step = parse_line("put the egg down", 4)
    assert step.canonical() == "drop egg"
    assert step.note == (
        "line 4 'put the egg down' read as 'drop egg' (no place is named, so it is "
        "let go of; 'put egg on R' sets it down)"
    )


def test_pour_notes_say_what_is_poured() -> None:
    assert parse_line("pour water into the sink").note == (
        "line 1 'pour water into the sink' read as 'pour sink' "
        "(pours what the held object contains)"
    )
    step = parse_line("pour the mug into the sink")
    assert step.held == "mug" and step.held_term == "mug"
    assert step.note is not None and step.note.endswith("(poured from the held mug)")


# ---------------------------------------------------------------- pronouns


def test_it_is_the_object_of_the_step_before() -> None:
    steps = parse_plan(
        ["find the candle", "light it", "pick it up", "find the shelf", "put it on the shelf"]
    )
    assert [(s.verb, s.args) for s in steps] == [
        ("find", ("candle",)),
        ("turn_on", ("candle",)),
        ("pick", ("candle",)),
        ("find", ("shelf",)),
        # Where the action needs the held object, 'it' is the held object.
        ("put", ("shelf",)),
    ]
    assert (
        steps[4].note
        == "line 5 'put it on the shelf' read as 'put shelf' ('it' is the object held)"
    )


@pytest.mark.parametrize(
    ("plan", "message"),
    [
        (["light it"], "'it' in 'light it' has no step before it to refer to; name the object"),
        (
            ["find the apple", "pick the apple", "find the fridge", "put the apple in the fridge", "shut it"],
            "'it' in 'shut it' could mean 'apple' or 'fridge' (the step before names both); name the object",
        ),
        (["find the pillow", "pick it", "throw", "pick them up"], "'them' in 'pick them up' refers to the step before ('throw'), which names no object"),
    ],
)  # fmt: skip
def test_an_unclear_it_is_an_error(plan: list[str], message: str) -> None:
    with pytest.raises(InputError, match=re.escape(message)) as err:
        parse_plan(plan)
    assert "\n" not in str(err.value)


# ---------------------------------------------------------------- errors, not guesses


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("turn the stove", "'turn the stove' does not say on or off; write 'turn on stove' or 'turn off stove'"),
        ("switch the lamp", "'switch the lamp' does not say on or off; write 'turn on lamp' or 'turn off lamp'"),
        ("toggle the desk lamp", "does not say on or off"),
        ("power the laptop", "does not say on or off"),
        ("set the cup", "'set the cup' does not say where; write 'set cup on R' or 'put cup in R'"),
        ("insert the fork", "does not say where"),
        ("fill the kettle", "'fill the kettle' does not say with what; write 'fill kettle with water|coffee|wine'"),
        ("take the apple out of the fridge", "names more than one thing, but 'take' reads as 'pick', which acts on one object; write 'pick apple'"),
        ("blow out the candle on the shelf", "names more than one thing"),
        ("throw the pillow onto the bed", "'throw' acts on one object; write 'find bed', then 'throw pillow' (or 'put pillow in bed' to place it)"),
        ("drop the pencil into the garbage can", "write 'find garbage can', then 'drop pencil'"),
        ("pour Mug_1 Cup_1 into the sink", "pours from more than one object (Mug_1, Cup_1)"),
    ],
)  # fmt: skip
def test_a_phrase_with_two_readings_is_an_error(line: str, message: str) -> None:
    with pytest.raises(InputError, match=re.escape(message)) as err:
        parse_line(line, 3)
    assert str(err.value).startswith("plan line 3: ")
    assert "\n" not in str(err.value)


def test_an_unknown_verb_lists_the_verbs_and_phrasings_closest_first() -> None:
    with pytest.raises(InputError) as err:
        parse_line("blow the candle", 2)
    msg = str(err.value)
    assert msg.startswith("plan line 2: unknown action 'blow'; closest: blow out")
    listed = msg.split("; valid verbs: ", 1)[1]
    verbs, phrasings = listed.split("; everyday phrasings: ")
    assert verbs.split(", ") == list(VERBS)
    assert phrasings.split(", ") == list(EVERYDAY)


# ---------------------------------------------------------------- objects in words


@pytest.fixture(scope="module")
def sim(vocab: Any) -> Simulator:
    return Simulator(vocab)


def _state(
    tutor: LogicTutor,
    sim: Simulator,
    instances: list[dict[str, str]],
    assertions: list[dict[str, str]],
) -> WorldState:
    return sim.initial(tutor.scene({"instances": instances, "assertions": assertions}))


@pytest.fixture(scope="module")
def house(tutor: LogicTutor, sim: Simulator) -> WorldState:
    return _state(
        tutor,
        sim,
        [
            inst("Candle", "Candle_1"),
            inst("Candle", "Candle_2"),
            inst("Mug", "Mug_1"),
            inst("Mug", "Mug_2"),
            inst("Fridge", "Fridge_1"),
            inst("Fridge", "Fridge_2"),
            inst("Pan", "Pan_1"),
            inst("Pan", "Pan_2"),
            inst("PhysicalObject", "HairDryer_1"),
            inst("PhysicalObject", "HairDryer_2"),
            inst("PhysicalObject", "Kettle-Lid-1"),
            inst("Box", "OpenBox_1"),
            inst("Box", "Box_1"),
            inst("CounterTop", "CounterTop_1"),
        ],
        [
            rel("Candle_1", "hasState", "OnState"),
            rel("Candle_2", "hasState", "OffState"),
            rel("Mug_1", "hasState", "DirtyState"),
            rel("Mug_2", "hasState", "CleanState"),
            rel("Fridge_1", "hasState", "ClosedState"),
            rel("Fridge_2", "hasState", "OpenState"),
            rel("Pan_2", "hasState", "HotState"),
        ],
    )


@pytest.mark.parametrize(
    ("term", "instance"),
    [
        ("lit candle", "Candle_1"),
        ("burning candle", "Candle_1"),
        ("unlit candle", "Candle_2"),
        ("dirty mug", "Mug_1"),
        ("clean mug", "Mug_2"),
        ("open fridge", "Fridge_2"),
        ("closed fridge", "Fridge_1"),
        ("hot pan", "Pan_2"),
        ("hot pans", "Pan_2"),
        # Without an adjective the words stay ambiguous.
        ("candle", ("Candle_1", "Candle_2")),
        ("pan", ("Pan_1", "Pan_2")),
        # No pan is cold: which one is meant is a question, not a guess.
        ("cold pan", ("Pan_1", "Pan_2")),
        # Instances without a class of their own, by their name without the number.
        ("hair dryer", ("HairDryer_1", "HairDryer_2")),
        ("kettle lid", "Kettle-Lid-1"),
        # A name that starts like an adjective is a name.
        ("open box", "OpenBox_1"),
        ("box", ("Box_1", "OpenBox_1")),
    ],
)
def test_state_words_choose_among_instances(
    sim: Simulator, house: WorldState, term: str, instance: str | tuple[str, ...]
) -> None:
    assert sim.resolve_term(house, term) == instance


def test_a_state_word_describes_a_single_instance(tutor: LogicTutor, sim: Simulator) -> None:
    state = _state(
        tutor, sim, [inst("Candle", "Candle_1")], [rel("Candle_1", "hasState", "OffState")]
    )
    # One candle: 'the lit candle' can only be it, lit or not.
    assert sim.resolve_term(state, "lit candle") == "Candle_1"
    assert sim.resolve_term(state, "lit lamp") is None


def test_hair_dryer_is_found_by_its_name(tutor: LogicTutor, sim: Simulator) -> None:
    scene = json.loads(_scene_data("hair-dryer-basin"))
    state = sim.initial(tutor.scene(scene))
    assert "HairDryer" not in tutor.tbox.vocabulary.classes
    for term in ("hair dryer", "Hair Dryer", "hair-dryer", "HairDryer", "hairdryer", "hair dryers"):
        assert sim.resolve_term(state, term) == "HairDryer_1", term


def _candles(lit: tuple[bool, bool]) -> dict[str, Any]:
    return {
        "instances": [inst("Candle", "Candle_1"), inst("Candle", "Candle_2"), inst("CounterTop", "CounterTop_1")],
        "assertions": [
            rel("CounterTop_1", "hasMaterial", "Stone"),
            *(rel(c, "isOn", "CounterTop_1") for c in ("Candle_1", "Candle_2")),
            *(rel(c, "hasState", "OnState" if on else "OffState") for c, on in zip(("Candle_1", "Candle_2"), lit, strict=True)),
        ],
    }  # fmt: skip


def test_the_lit_candle_is_the_one_put_out(tutor: LogicTutor) -> None:
    scene = _candles((True, False))
    # The other candle stays unlit: nothing is left burning.
    safe = tutor.verify(scene, ["find the lit candle", "blow out the lit candle"])
    assert (safe.status, safe.trace[1].added) == ("SAFE", ("Candle_1 hasState OffState",))
    # Blowing at the unlit one leaves the lit one burning.
    unsafe = tutor.verify(scene, ["find the unlit candle", "blow out the unlit candle"])
    assert unsafe.status == "UNSAFE"
    assert unsafe.violated_concept is not None
    assert unsafe.violated_concept.id == "OpenFlameLeftBurningDanger"


@pytest.mark.parametrize(
    ("lit", "line"),
    [
        ((True, True), "blow out the lit candle"),  # both burn
        ((False, False), "blow out the lit candle"),  # neither does
        ((True, False), "blow out the candle"),  # no word says which
    ],
)
def test_which_candle_is_a_question_when_the_words_leave_it_open(
    tutor: LogicTutor, lit: tuple[bool, bool], line: str
) -> None:
    report = tutor.verify(_candles(lit), [line])
    assert report.status == "UNKNOWN"
    assert report.dangerous_step == 1
    assert report.violated_concept is not None
    assert report.violated_concept.id == "AmbiguousObject"
    (question,) = report.questions
    assert question.options == ("Candle_1", "Candle_2")


# ---------------------------------------------------------------- throw X, drop X


@pytest.fixture(scope="module")
def bedroom() -> dict[str, Any]:
    return {
        "instances": [
            inst("AlarmClock", "AlarmClock_1"),
            inst("Pillow", "Pillow_1"),
            inst("Bed", "Bed_1"),
            inst("Mug", "Mug_1"),
            inst("Mug", "Mug_2"),
            inst("Desk", "Desk_1"),
        ],
        "assertions": [
            rel("AlarmClock_1", "isOn", "Desk_1"),
            rel("Mug_1", "isOn", "Desk_1"),
            rel("Mug_2", "isOn", "Desk_1"),
            rel("Pillow_1", "isOn", "Bed_1"),
        ],
    }


def test_throw_alarm_clock_parses() -> None:
    step = parse_line("throw AlarmClock")
    assert (step.verb, step.args, step.held_term, step.note) == (
        "throw",
        ("AlarmClock",),
        "AlarmClock",
        None,
    )
    assert parse_line("drop the alarm clock").args == ("alarm clock",)


@pytest.mark.parametrize("verb", ["throw", "drop"])
def test_naming_the_held_object_changes_nothing(
    tutor: LogicTutor, bedroom: dict[str, Any], verb: str
) -> None:
    start = ["find AlarmClock", "pick AlarmClock"]
    named = tutor.verify(bedroom, [*start, f"{verb} AlarmClock"])
    bare = tutor.verify(bedroom, [*start, verb])
    assert _verdict(named) == _verdict(bare)
    assert named.causal_chain == bare.causal_chain
    assert [t.added for t in named.trace] == [t.added for t in bare.trace]


@pytest.mark.parametrize("verb", ["throw", "drop", "toss", "release"])
def test_throwing_what_is_not_held_cannot_run(
    tutor: LogicTutor, bedroom: dict[str, Any], verb: str
) -> None:
    report = tutor.verify(
        bedroom, ["find the pillow", "grab the pillow", f"{verb} the alarm clock"]
    )
    assert (report.status, report.dangerous_step, report.problem) == ("UNSAFE", 3, "not-executable")
    # Not a hazard of throwing either object: the step does not happen.
    assert [v.id for v in report.violations] == ["Precondition_NothingHeld"]
    assert report.causal_chain is not None
    assert "Robot_1 is holding Pillow_1, not AlarmClock_1" in report.causal_chain.message


def test_throwing_with_an_empty_hand_cannot_run(tutor: LogicTutor, bedroom: dict[str, Any]) -> None:
    report = tutor.verify(bedroom, ["find AlarmClock", "throw AlarmClock"])
    assert (report.status, report.dangerous_step, report.problem) == ("UNSAFE", 2, "not-executable")
    assert [v.id for v in report.violations] == ["Precondition_NothingHeld"]
    assert report.causal_chain is not None
    assert "Robot_1 is holding nothing, not AlarmClock_1" in report.causal_chain.message


def test_pouring_from_what_is_not_held_cannot_run(
    tutor: LogicTutor, bedroom: dict[str, Any]
) -> None:
    report = tutor.verify(
        bedroom, ["find Mug_1", "pick Mug_1", "find the bed", "pour Mug_2 into the bed"]
    )
    assert (report.status, report.dangerous_step, report.problem) == ("UNSAFE", 4, "not-executable")
    assert [v.id for v in report.violations] == ["Precondition_NothingHeld"]


def test_the_held_one_of_several_is_thrown(
    tutor: LogicTutor, sim: Simulator, bedroom: dict[str, Any]
) -> None:
    # Mug_1 was found last, but 'the mug' to throw is the one in the hand.
    trace = simulate(
        sim,
        sim.initial(tutor.scene(bedroom)),
        parse_plan(["find Mug_2", "pick Mug_2", "find Mug_1"]),
    )
    r = sim.resolve(trace.final, parse_line("throw the mug"))
    assert isinstance(r, ResolvedStep)
    assert (r.patient, r.named_held) == ("Mug_2", "Mug_2")
    missing = sim.resolve(trace.final, parse_line("throw the vase"))
    assert isinstance(missing, MissingObject) and missing.term == "vase"


# ---------------------------------------------------------------- the documentation


def test_the_planner_docs_list_every_phrasing() -> None:
    doc = (ROOT / "docs" / "planner.md").read_text(encoding="utf-8")
    section = doc.split("## Plan language: what the reader accepts", 1)[1].split("\n## ", 1)[0]
    rows = {
        line.split("|")[1].strip().strip("`"): line.split("|")[3]
        for line in section.splitlines()
        if line.startswith("| `")
    }
    for verb in VERBS:
        assert verb in rows, verb
        phrasings = {p for p, r in EVERYDAY.items() if verb in (r.alone, r.placed)}
        for phrase in phrasings:
            assert f"`{phrase}`" in rows[verb], (verb, phrase)
    for word in STATE_ADJECTIVES:
        assert f"`{word}`" in section, word
    for liquid in LIQUIDS:
        assert liquid in section
