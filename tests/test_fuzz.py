"""Fuzzing: hostile scenes, plans and answers fail closed.

The invariants, over generated input (valid-looking and broken):

* input that is invalid or ambiguous is refused with an InputError (a
  VirfError), never another exception and never a verdict, let alone SAFE;
* a plan that names an object nobody can find is never SAFE;
* every verification ends within its deadline plus a margin;
* the same world with its instances and assertions shuffled gives the same
  report (tests/test_invariance.py covers the many spellings of one world;
  here the worlds are odd but valid: duplicates, value individuals, closures
  of single receptacles, referents);
* the ``virf`` command, run in-process on a sample, exits with a documented
  code and prints no traceback.

``make test`` runs a few dozen examples per property (derandomized, so a
failure reproduces); ``VIRF_FULL=1 make test-full`` runs many more.
"""

from __future__ import annotations

import json
import os
import random
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import EXAMPLES_DIR, inst, rel
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from virf.api import LogicTutor
from virf.cli.main import app
from virf.errors import InputError, VirfError, parse_json
from virf.planner.questions import answers_file, apply_answers
from virf.world.language import ARITY, LIQUIDS, VERBS
from virf.world.plan import load_plan_file, parse_plan_text
from virf.world.scene import MAX_NAME

FULL = os.environ.get("VIRF_FULL") == "1"
STATUSES = {"SAFE", "UNSAFE", "UNKNOWN", "ERROR"}
# Seconds each fuzzed verification may take, and the slack allowed on top
# (a loaded CI machine, one reasoner call finishing after the deadline).
DEADLINE_S = 5.0
MARGIN_S = 10.0


def fuzz(examples: int, full: int) -> Any:
    return settings(
        max_examples=full if FULL else examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


@pytest.fixture(scope="module")
def quick(tutor: LogicTutor) -> LogicTutor:
    """The session's knowledge base (already loaded) with a short deadline."""
    return LogicTutor(timeout_s=DEADLINE_S)


def verified(quick: LogicTutor, scene: Any, plan: Any) -> Any:
    """The report, checked for what every report must satisfy."""
    start = time.monotonic()
    report = quick.verify(scene, plan)
    elapsed = time.monotonic() - start
    assert elapsed < DEADLINE_S + MARGIN_S, f"took {elapsed:.1f}s"
    assert report.status in STATUSES
    if report.status == "SAFE":
        assert not report.violations and not report.questions
    return report


# ---------------------------------------------------------------- scene pieces
TYPES = {
    "Pot_1": "Pot",
    "Mug_1": "Mug",
    "Mug_2": "Mug",
    "Microwave_1": "Microwave",
    "Fridge_1": "Fridge",
    "CounterTop_1": "CounterTop",
    "StoveBurner_1": "StoveBurner",
    "StoveKnob_1": "StoveKnob",
    "Apple_1": "Apple",
    "Knife_1": "Knife",
    "Toaster_1": "Toaster",
}
STATE_WORDS = ("on", "off", "open", "closed", "hot", "cold", "dirty", "clean", "filled", "empty")
# Values of every JSON type, and strings a hostile user would try.
JUNK: list[Any] = [
    None,
    True,
    0,
    -1,
    1.5,
    [],
    {},
    ["Pot_1"],
    {"a": 1},
    "",
    " ",
    "Pot_1\n",
    "Pot_1\x1b[2J",
    "Po\u200bt_1",
    "Pöt_1",
    "\u0661",
    "P" * (MAX_NAME + 1),
    "pot_1",
    "POT_1",
    "pan",
    "stove_knob",
    "Mircowave",
    "owl:Thing",
    "Nothing",
    "UnsafeMicrowaveUsage",
    "ThrowAction",
    "rdf:type",
    "isInside",
    "data_property",
]
names = st.sampled_from([*TYPES, "Robot_1", "Ghost_1", "OnState", "Metal"])
classes = st.sampled_from(
    [*set(TYPES.values()), "Robot", "OnState", "Metal", "MetallicObject", "Child", "Oil"]
)
properties = st.sampled_from(
    [
        *("isOn", "isInside", "contains", "supports", "hasState", "hasMaterial", "isMadeOf"),
        *("rdf:type", "controls", "isHolding", "isHeldBy", "isLocated", "isNear", "bogusProp"),
    ]
)
values = st.one_of(names, classes, st.sampled_from(STATE_WORDS), st.booleans())
anything = st.one_of(st.sampled_from(JUNK), st.text(max_size=12))
RECEPTACLES = {  # receptacle -> the relation an object has to it
    "CounterTop_1": "isOn",
    "StoveBurner_1": "isOn",
    "Microwave_1": "isInside",
    "Fridge_1": "isInside",
    "Toaster_1": "isInside",
}
SMALL = ("Pot_1", "Mug_1", "Mug_2", "Apple_1", "Knife_1")


@st.composite
def broken_instance(draw: st.DrawFn) -> Any:
    return draw(
        st.one_of(
            anything,
            st.fixed_dictionaries({"class_name": anything, "instance_name": anything}),
            st.fixed_dictionaries({"class_name": classes}),
            st.fixed_dictionaries({"class_name": classes, "instance_name": names}),
            st.fixed_dictionaries(
                {"class_name": classes, "instance_name": names, "colour": anything}
            ),
        )
    )


@st.composite
def broken_assertion(draw: st.DrawFn) -> Any:
    return draw(
        st.one_of(
            anything,
            st.fixed_dictionaries({"subject": anything, "property": anything, "object": anything}),
            st.fixed_dictionaries({"subject": names, "property": properties}),
            st.fixed_dictionaries(
                {"subject": names, "property": properties, "object": values, "type": anything}
            ),
            st.fixed_dictionaries(
                {
                    "subject": names,
                    "property": properties,
                    "object": values,
                    "type": st.sampled_from(["object_property", "data_property"]),
                }
            ),
        )
    )


@st.composite
def sensible_assertion(draw: st.DrawFn, declared: list[str]) -> dict[str, Any]:
    """An assertion a scene writer could mean (it may still describe an impossible world)."""
    subject = draw(st.sampled_from(declared))
    shape = draw(st.integers(0, 3))
    receptacles = sorted(set(RECEPTACLES) & set(declared) - {subject})
    if shape == 0 and receptacles:
        where = draw(st.sampled_from(receptacles))
        return rel(subject, RECEPTACLES[where], where)
    if shape == 1:
        return rel(subject, "hasState", draw(st.sampled_from(STATE_WORDS)), "data_property")
    if shape == 2:
        return rel(subject, "hasMaterial", draw(st.sampled_from(["Metal", "Plastic", "Glass"])))
    return rel(subject, "isLocated", draw(st.sampled_from(["true", "false"])), "data_property")


@st.composite
def scene_data(draw: st.DrawFn) -> Any:
    """Scene JSON: about half valid-looking, the rest broken at one or more levels
    (wrong types, missing or unknown keys, unknown terms, clashing names)."""
    if draw(st.integers(0, 14)) == 0:
        return draw(anything)
    declared = draw(st.lists(st.sampled_from(sorted(TYPES)), min_size=1, max_size=8, unique=True))
    instances: list[Any] = [inst(TYPES[n], n) for n in declared]
    assertions: list[Any] = []
    placed: set[str] = set()
    for _ in range(draw(st.integers(0, 8))):
        a = draw(sensible_assertion(declared))
        if a["property"] in ("isOn", "isInside"):
            if a["subject"] in placed or a["subject"] not in SMALL:
                continue  # one place each, and only small things move
            placed.add(a["subject"])
        assertions.append(a)
    noisy = draw(st.integers(0, 2)) == 0
    if noisy:
        for _ in range(draw(st.integers(1, 3))):
            where = draw(st.sampled_from(["instances", "assertions", "junk instance"]))
            if where == "instances":
                instances.insert(draw(st.integers(0, len(instances))), draw(broken_instance()))
            elif where == "assertions":
                assertions.insert(draw(st.integers(0, len(assertions))), draw(broken_assertion()))
            else:
                instances.append(inst(draw(classes), draw(st.one_of(names, anything))))
    data: dict[str, Any] = {"instances": instances, "assertions": assertions}
    sane = st.sampled_from(declared)
    optional = {
        "closed_world": st.lists(
            st.one_of(st.sampled_from(["contains", "supports"]), sane.map("contains:{}".format))
        ),
        "unknown_contents": st.lists(sane, max_size=2),
        "referents": st.dictionaries(st.sampled_from(["mug", "bowl", "the pot"]), sane),
        "unlocated_by_default": st.booleans(),
        "name": st.just("kitchen"),
    }
    junk = {
        "closed_world": st.one_of(
            st.lists(st.sampled_from(["contains:", "contains:Ghost_1", "isOn", ""])), anything
        ),
        "unknown_contents": st.one_of(st.lists(names, max_size=2), anything),
        "referents": st.one_of(
            st.dictionaries(st.sampled_from(["", "--", "\x00"]), names), anything
        ),
        "unlocated_by_default": anything,
        "name": anything,
        "bogus_key": anything,
    }
    for key, strategy in (junk if noisy else optional).items():
        if draw(st.integers(0, 4)) == 0:
            data[key] = draw(strategy)
    if noisy and draw(st.integers(0, 4)) == 0:
        data.pop(draw(st.sampled_from(["instances", "assertions"])))
    return data


# ------------------------------------------------------------------ plan pieces
OBJECT_WORDS = [*TYPES, "Mug", "microwave", "stove knob", "dining table", "apples", "Ghost_1"]
TOKENS = [
    *VERBS,
    *OBJECT_WORDS,
    *LIQUIDS,
    "turn",
    "on",
    "off",
    "pick up",
    "in",
    "the",
    "(",
    ")",
    ",",
    "1.",
    "#",
    "[",
    "]",
    "\u0662",
    "²",
    "\u200b",
    "\x00",
    "\t",
    "ﬁnd",
]


@st.composite
def action_line(draw: st.DrawFn) -> str:
    """A well-formed action line, in any of the accepted styles."""
    verb = draw(st.sampled_from(VERBS))
    lo, hi = ARITY[verb]
    args = draw(st.lists(st.sampled_from(OBJECT_WORDS), min_size=lo, max_size=hi))
    if verb == "fillLiquid":
        args = [args[0], draw(st.sampled_from(LIQUIDS))]
    style = draw(st.integers(0, 3))
    if style == 0 and args:
        return f"{verb}({', '.join(args)})"
    if style == 1:
        return f"{draw(st.integers(1, 9))}. {' '.join([verb, *args])}"
    return " ".join([verb, *args])


@st.composite
def garbage_line(draw: st.DrawFn) -> str:
    shape = draw(st.integers(0, 2))
    if shape == 0:
        return " ".join(draw(st.lists(st.sampled_from(TOKENS), max_size=6)))
    if shape == 1:
        args = draw(st.lists(st.sampled_from([*OBJECT_WORDS, "", " "]), max_size=3))
        return f"{draw(st.sampled_from(VERBS))}({', '.join(args)})"
    return draw(st.text(max_size=30))


@st.composite
def plan_text(draw: st.DrawFn) -> str:
    """Plan files: about half well-formed, the rest with random tokens, unicode,
    broken calls; as lines or as a (possibly broken) JSON list."""
    lines = draw(st.lists(action_line(), max_size=6))
    if draw(st.booleans()):
        for _ in range(draw(st.integers(1, 2))):
            lines.insert(draw(st.integers(0, len(lines))), draw(garbage_line()))
    if draw(st.integers(0, 3)) == 0:
        return json.dumps(lines) if draw(st.booleans()) else "[" + ", ".join(lines)
    return "\n".join(lines)


BASE: dict[str, Any] = {
    "instances": [inst(t, n) for n, t in TYPES.items()],
    "assertions": [
        rel("Pot_1", "isOn", "CounterTop_1"),
        rel("Mug_1", "isOn", "CounterTop_1"),
        rel("Apple_1", "isInside", "Fridge_1"),
        rel("Microwave_1", "hasState", "closed", "data_property"),
        rel("StoveKnob_1", "controls", "StoveBurner_1"),
    ],
}


# -------------------------------------------------------------------- scenes
@fuzz(60, 600)
@given(data=scene_data(), plan=st.lists(action_line(), min_size=1, max_size=5))
def test_scenes_are_refused_or_verified(quick: LogicTutor, data: Any, plan: list[str]) -> None:
    try:
        scene = quick.scene(data)
    except InputError:
        event("scene refused")
        return
    event(f"scene verified: {verified(quick, scene, plan).status}")


# One defect each, applied to a valid scene: each must be refused, whatever
# else the scene says (a verdict on such a scene could be SAFE by accident).
# Each adds everything it needs, since the base loses random assertions.
DEFECTS: dict[str, Any] = {
    "name not a string": lambda d: d["instances"].append(
        {"class_name": "Pot", "instance_name": None}
    ),
    "unknown class": lambda d: d["instances"].append(inst("Mircowave", "M_9")),
    "case clash": lambda d: d["instances"].append(inst("Mug", "mug_1")),
    "reads as a term": lambda d: d["instances"].append(inst("Bread", "pan")),
    "control character": lambda d: d["instances"].append(inst("Mug", "Mug_9\x1b")),
    "name too long": lambda d: d["instances"].append(inst("Mug", "M" * (MAX_NAME + 1))),
    "unknown subject": lambda d: d["assertions"].append(rel("Ghost_1", "isOn", "CounterTop_1")),
    "unknown property": lambda d: d["assertions"].append(rel("Pot_1", "isUnder", "Mug_1")),
    "unknown object": lambda d: d["assertions"].append(rel("Pot_1", "hasState", "sizzling")),
    "stray key": lambda d: d["assertions"].append(
        {"subject": "Pot_1", "property": "isOn", "object": "CounterTop_1", "note": "x"}
    ),
    "two places": lambda d: d["assertions"].extend(
        [rel("Knife_1", "isOn", "CounterTop_1"), rel("Knife_1", "isInside", "Fridge_1")]
    ),
    "inside itself": lambda d: d["assertions"].append(rel("Fridge_1", "contains", "Fridge_1")),
    "cycle": lambda d: d["assertions"].extend(
        [rel("Toaster_1", "contains", "Mug_2"), rel("Toaster_1", "isInside", "Mug_2")]
    ),
    "two robots": lambda d: d["instances"].extend([inst("Robot", "R_1"), inst("Robot", "R_2")]),
    "holds two": lambda d: d.update(
        instances=[*d["instances"], inst("Robot", "Robot_1")],
        assertions=[
            *d["assertions"],
            rel("Robot_1", "isHolding", "Knife_1"),
            rel("Robot_1", "isHolding", "Mug_2"),
        ],
    ),
    "bad closure": lambda d: d.update(closed_world=["contains:"]),
    "closure of a ghost": lambda d: d.update(closed_world=["contains:Ghost_1"]),
    "unknown contents of a ghost": lambda d: d.update(unknown_contents=["Ghost_1"]),
    "referent to a ghost": lambda d: d.update(referents={"mug": "Ghost_1"}),
    "empty referent": lambda d: d.update(referents={"": "Mug_1"}),
    "unlocated not a bool": lambda d: d.update(unlocated_by_default="yes"),
    "unknown top-level key": lambda d: d.update(objects=[]),
    "name not text": lambda d: d.update(name=["kitchen"]),
    "junk relation type": lambda d: d["assertions"].append(
        rel("Pot_1", "isOn", "CounterTop_1", "object-property")
    ),
    "relation as a literal": lambda d: d["assertions"].append(
        rel("Knife_1", "isOn", "CounterTop_1", "data_property")
    ),
    "not a boolean": lambda d: d["assertions"].append(
        rel("Pot_1", "isLocated", "maybe", "data_property")
    ),
}


@fuzz(40, 400)
@given(
    defect=st.sampled_from(sorted(DEFECTS)),
    keep=st.lists(st.booleans(), min_size=len(BASE["assertions"]), max_size=20),
    seed=st.integers(0, 2**16),
)
def test_one_defect_is_always_refused(
    quick: LogicTutor, defect: str, keep: list[bool], seed: int
) -> None:
    data = json.loads(json.dumps(BASE))
    data["assertions"] = [a for a, k in zip(data["assertions"], keep, strict=False) if k]
    quick.scene(data)  # the base is valid
    DEFECTS[defect](data)
    rng = random.Random(seed)
    rng.shuffle(data["instances"])
    rng.shuffle(data["assertions"])
    with pytest.raises(InputError):
        quick.scene(data)


@pytest.mark.parametrize(
    "text",
    [
        '{"instances": [], "instances": []}',
        '{"instances": [{"class_name": "Pot", "instance_name": "Pot_1", "class_name": "Mug"}]}',
        '{"instances": [], "weight": NaN}',
        '{"instances": [], "weight": -Infinity}',
        "[" * 100_000,
        '{"instances": [' + "[" * 5000 + "]" * 5000 + "]}",
    ],
)
def test_json_that_reads_two_ways_or_never_ends_is_refused(text: str) -> None:
    with pytest.raises(InputError):
        parse_json(text, "scene")


# --------------------------------------------------------------------- plans
@pytest.fixture(scope="module")
def kitchen(quick: LogicTutor) -> Any:
    return quick.scene(BASE)


@fuzz(80, 800)
@given(text=plan_text())
def test_plan_text_is_refused_or_verified(quick: LogicTutor, kitchen: Any, text: str) -> None:
    try:
        steps = parse_plan_text(text)
    except InputError:
        event("plan refused")
        return
    if not steps:
        with pytest.raises(InputError):
            quick.verify(kitchen, [text])
        return
    event(f"plan verified: {verified(quick, kitchen, steps).status}")


GHOSTS = ("Ghost_1", "Blorf", "zqxj")


@fuzz(40, 400)
@given(
    prefix=st.lists(plan_text(), max_size=2),
    verb=st.sampled_from([v for v in VERBS if ARITY[v][0] >= 1]),
    ghost=st.sampled_from(GHOSTS),
)
def test_a_plan_acting_on_a_missing_object_is_never_safe(
    quick: LogicTutor, kitchen: Any, prefix: list[str], verb: str, ghost: str
) -> None:
    """Whatever comes before it, a step on an object the scene lacks is not SAFE."""
    before: list[str] = []
    for text in prefix:
        try:
            before += [s.text for s in parse_plan_text(text)]
        except InputError:
            continue
    step = f"fillLiquid {ghost} water" if verb == "fillLiquid" else f"{verb} {ghost}"
    report = verified(quick, kitchen, [*before, step])
    assert report.status != "SAFE", (before, step)


@pytest.mark.parametrize(
    "line",
    [
        "put_in(, Fridge_1)",
        "put_in(Pot_1,, Fridge_1)",
        "find()",
        "find(,)",
        "pour(,)",
        "find(Apple_1))",
        "find Apple_1\x00",
        "find Po\u200bt_1",
        "find Pot_1\x1b[2J",
        "find Pot_1\u202e",
        "find " + "P" * 1000,
        "find Apple_1\x0cpick Apple_1",
        "find Apple_1\u2028pick Apple_1",
    ],
)
def test_garbage_plan_lines_are_refused(line: str) -> None:
    with pytest.raises(InputError):
        parse_plan_text(line)


@pytest.mark.parametrize(
    "text",
    [
        '["find Pot_1", NaN]',
        '[{"a": 1, "a": 2}]',
        '["find Pot_1", ["pick Pot_1"]]',
        "[" * 10_000,
        "\n".join(["find Pot_1"] * 1001),
        json.dumps(["find Pot_1"] * 1001),
    ],
)
def test_plans_that_cannot_be_read_one_way_are_refused(text: str) -> None:
    with pytest.raises(InputError):
        parse_plan_text(text)


def test_a_byte_order_mark_is_not_part_of_the_plan(tmp_path: Path) -> None:
    from virf.world.plan import load_plan_file

    path = tmp_path / "plan.txt"
    path.write_bytes("\ufefffind Pot_1\n".encode())
    assert [s.canonical() for s in load_plan_file(path)] == ["find Pot_1"]


def test_an_ambiguous_type_word_is_never_safe(quick: LogicTutor, kitchen: Any) -> None:
    # Two mugs, neither found nor held: 'pick Mug' could mean either.
    report = verified(quick, kitchen, ["pick Mug", "drop"])
    assert report.status == "UNKNOWN"
    assert any(q.kind == "which" for q in report.questions)


# ------------------------------------------------------------- shuffled worlds
@st.composite
def odd_worlds(draw: st.DrawFn) -> dict[str, Any]:
    """Valid scenes written oddly: repeated entries, value individuals, types
    as assertions, either direction of a relation, single-receptacle closures."""
    instances = [inst(t, n) for n, t in TYPES.items()]
    assertions: list[dict[str, Any]] = []
    for name in ("Pot_1", "Mug_1", "Mug_2", "Knife_1"):
        where = draw(st.sampled_from(["CounterTop_1", "Microwave_1", "Fridge_1", "StoveBurner_1"]))
        relation = {"CounterTop_1": "isOn", "StoveBurner_1": "isOn"}.get(where, "isInside")
        if draw(st.booleans()):
            assertions.append(rel(name, relation, where))
        elif draw(st.booleans()):
            inverse = {"isOn": "supports", "isInside": "contains"}[relation]
            assertions.append(rel(where, inverse, name))
    for name in ("Microwave_1", "StoveBurner_1", "StoveKnob_1", "Toaster_1"):
        word = draw(st.sampled_from(["on", "off", None]))
        if word is not None:
            spelled = draw(st.sampled_from(["word", "class", "individual"]))
            if spelled == "word":
                assertions.append(rel(name, "hasState", word, "data_property"))
            elif spelled == "class":
                assertions.append(rel(name, "hasState", word.capitalize() + "State"))
            else:
                assertions.append(rel(name, "hasState", f"{word.capitalize()}_{name}"))
                instances.append(inst(word.capitalize() + "State", f"{word.capitalize()}_{name}"))
    if draw(st.booleans()):
        assertions.append(rel("Knife_1", "rdf:type", "Knife"))  # a repeated type
    if draw(st.booleans()):
        instances.append(inst("Mug", "Mug_1"))  # a repeated instance
    if draw(st.booleans()):
        assertions.append(rel("Pot_1", "isMadeOf", "Metal"))
    if assertions and draw(st.booleans()):
        assertions.append(dict(assertions[0]))  # a repeated assertion
    data: dict[str, Any] = {"instances": instances, "assertions": assertions}
    if draw(st.booleans()):
        data["closed_world"] = draw(
            st.lists(st.sampled_from(["contains", "contains:Microwave_1", "supports"]), max_size=2)
        )
    if draw(st.booleans()):
        data["referents"] = {"mug": draw(st.sampled_from(["Mug_1", "Mug_2"]))}
    return data


PLAN_STEPS = [
    "find Mug",
    "pick Mug",
    "find Microwave_1",
    "open Microwave_1",
    "put Mug in Microwave_1",
    "close Microwave_1",
    "turn on Microwave_1",
    "turn on StoveKnob_1",
    "find Knife_1",
    "pick Knife_1",
    "put Knife_1 in Toaster_1",
    "turn on Toaster_1",
]


@fuzz(30, 300)
@given(
    data=odd_worlds(),
    plan=st.lists(st.sampled_from(PLAN_STEPS), min_size=1, max_size=6),
    seed=st.integers(0, 2**16),
)
def test_shuffling_an_odd_world_keeps_the_report(
    quick: LogicTutor, data: dict[str, Any], plan: list[str], seed: int
) -> None:
    try:
        scene = quick.scene(data)
    except InputError:
        return  # an impossible world (a knife in two places): refused either way
    first = verified(quick, scene, plan)
    shuffled = dict(data)
    rng = random.Random(seed)
    shuffled["instances"] = rng.sample(data["instances"], len(data["instances"]))
    shuffled["assertions"] = rng.sample(data["assertions"], len(data["assertions"]))
    second = verified(quick, quick.scene(shuffled), plan)
    if "ERROR" in (first.status, second.status):
        return  # a deadline hit on a slow machine says nothing about order
    assert second.to_json() == first.to_json()


def test_ambiguity_options_do_not_depend_on_scene_order(quick: LogicTutor) -> None:
    mugs = [inst("Mug", "Mug_1"), inst("Mug", "Mug_2")]
    first = quick.verify({"instances": mugs}, ["find Mug"])
    second = quick.verify({"instances": mugs[::-1]}, ["find Mug"])
    assert second.to_json() == first.to_json()


# ------------------------------------------------------------------- answers
UNKNOWN_EXAMPLES = (
    "noise-contradiction",
    "noise-uncertainty",
    "unknown-material-microwave",
    "noise-omission",
    "burner-left-on-open-world",
)


@pytest.fixture(scope="module")
def open_questions(quick: LogicTutor) -> list[tuple[dict[str, Any], list[str], Any]]:
    """Scenes with open questions of every kind, each with its plan and report."""
    bowls: dict[str, Any] = {
        "instances": [
            inst("Bowl", "Bowl_1"),
            inst("Bowl", "Bowl_2"),
            inst("Microwave", "Microwave_1"),
            inst("CounterTop", "CounterTop_1"),
        ],
        "assertions": [
            rel("Bowl_1", "isOn", "CounterTop_1"),
            rel("Bowl_2", "isOn", "CounterTop_1"),
        ],
    }
    heat = ["find Microwave_1", "open Microwave_1", "put Bowl in Microwave_1"]
    heat += ["close Microwave_1", "turn on Microwave_1"]
    cases = [(bowls, ["pick Bowl", *heat]), (bowls, ["find Bowl_1", "pick Bowl", *heat])]
    for name in UNKNOWN_EXAMPLES:
        folder = EXAMPLES_DIR / name
        data = json.loads((folder / "scene.json").read_text(encoding="utf-8"))
        cases.append((data, [s.text for s in load_plan_file(folder / "plan.txt")]))
    out = []
    for data, plan in cases:
        report = quick.verify(data, plan)
        assert report.status == "UNKNOWN" and report.questions, report.reason
        out.append((data, plan, report))
    kinds = {q.kind for _, _, r in out for q in r.questions}
    assert {"which", "fill", "material", "where", "contradiction", "contents"} <= kinds
    return out


ANSWER_WORDS = ["yes", "no", "Bowl_1", "metal", "glass", "on CounterTop_1", "in Ghost_1", "1", ""]


@st.composite
def answers_content(draw: st.DrawFn, questions: Any) -> Any:
    """An answers file's JSON: answers to the real questions (a plausible or
    a wrong answer each), stray keys, or no answers object at all."""
    shape = draw(st.integers(0, 3))
    if shape == 0:
        return draw(anything)
    if shape == 1:
        return draw(st.dictionaries(st.text(max_size=12), st.one_of(anything, st.just("yes"))))
    out: dict[str, Any] = {}
    for q in questions:
        if draw(st.integers(0, 3)):
            choices = [*q.options, *ANSWER_WORDS]
            out[q.key] = draw(st.one_of(st.sampled_from(choices), anything))
    return out


@fuzz(60, 600)
@given(data=st.data(), raw=st.text(max_size=40), use_raw=st.integers(0, 9))
def test_answers_files_are_refused_or_applied(
    quick: LogicTutor,
    open_questions: list[tuple[dict[str, Any], list[str], Any]],
    tmp_path_factory: pytest.TempPathFactory,
    data: st.DataObject,
    raw: str,
    use_raw: int,
) -> None:
    scene_data_, plan, report = data.draw(st.sampled_from(open_questions))
    content = data.draw(answers_content(report.questions))
    path = tmp_path_factory.mktemp("answers") / "answers.json"
    path.write_text(raw if use_raw == 0 else json.dumps(content), encoding="utf-8")
    try:
        policy = answers_file(path)
        update = apply_answers(
            scene_data_, report.questions, policy(report.questions), quick.tbox.vocabulary
        )
        scene = quick.scene(update.scene)
    except VirfError:
        event("answers refused")
        return
    event(f"answers applied: {len(update.applied)}")
    verified(quick, scene, plan)


# ------------------------------------------------------------------- the CLI
runner = CliRunner()


@fuzz(16, 160)
@given(
    data=st.one_of(st.just(BASE), scene_data()),
    text=st.one_of(st.lists(action_line(), min_size=1, max_size=5).map("\n".join), plan_text()),
    as_json=st.booleans(),
    timeout=st.sampled_from(["3", "3", "3", "0.5", "nan", "inf", "-1", "0", "1e999", "abc"]),
)
def test_cli_exit_codes_and_no_traceback(
    quick: LogicTutor,
    tmp_path_factory: pytest.TempPathFactory,
    data: Any,
    text: str,
    as_json: bool,
    timeout: str,
) -> None:
    folder = tmp_path_factory.mktemp("cli")
    scene, plan = folder / "scene.json", folder / "plan.txt"
    scene.write_text(json.dumps(data), encoding="utf-8")
    plan.write_text(text, encoding="utf-8")
    args = ["verify", str(scene), str(plan), "--timeout", timeout]
    result = runner.invoke(app, [*args, "--json"] if as_json else args)
    event(f"exit {result.exit_code}")
    out = result.stdout + result.stderr
    assert "Traceback" not in out
    assert result.exit_code in (0, 1, 2, 3, 4), (result.exit_code, out, result.exception)
    if result.exit_code == 2:
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert result.stderr.startswith("error: ")
    if timeout in ("nan", "inf", "-1", "0", "1e999", "abc"):
        assert result.exit_code == 2
    if as_json:
        shown = json.loads(result.stdout)  # exactly one JSON document
        assert shown["status"] in {*STATUSES, "BAD_INPUT"}
    scene_show = runner.invoke(app, ["scene", "show", str(scene), "--json"])
    assert scene_show.exit_code in (0, 2) and "Traceback" not in scene_show.stdout
    json.loads(scene_show.stdout)


# ---------------------------------------------------------------- the service
# The same generators, over HTTP: for the same bytes, POST /v1/verify answers
# what `virf verify --json` prints (the report byte for byte, or a 400 with
# the CLI's error line), and never a 5xx.
LOCAL = "http://127.0.0.1"


@pytest.fixture(scope="module")
def service(tutor: LogicTutor) -> Any:
    from fastapi.testclient import TestClient

    from virf.service.app import create_app

    return TestClient(create_app(), base_url=LOCAL)


@st.composite
def scene_bytes(draw: st.DrawFn) -> bytes:
    """A scene file's bytes: the scenes above, written as JSON, some of them
    twisted into JSON that reads two ways (a key twice, NaN) or not at all."""
    data = draw(st.one_of(st.just(BASE), scene_data()))
    text = json.dumps(data)
    twist = draw(st.integers(0, 5))
    if twist == 0 and isinstance(data, dict) and data:
        # A key again: the later value would hide the first.
        key = draw(st.sampled_from(sorted(data)))
        again = draw(st.sampled_from([[], {}, None, "x"]))
        text = f"{text[:-1]}, {json.dumps(key)}: {json.dumps(again)}}}"
    elif twist == 1 and isinstance(data, dict):
        text = text[:-1] + (', "weight": NaN}' if data else '"weight": NaN}')
    elif twist == 2 and len(text) > 1:
        text = text[: draw(st.integers(1, len(text) - 1))]
    return text.encode()


def _is_object(raw: bytes) -> bool:
    try:
        return isinstance(parse_json(raw.decode(), "scene"), dict)
    except InputError:
        return False


@fuzz(24, 240)
@given(
    raw=scene_bytes(),
    text=st.one_of(st.lists(action_line(), min_size=1, max_size=5).map("\n".join), plan_text()),
    as_list=st.booleans(),
)
def test_the_service_answers_what_the_cli_prints_for_the_same_bytes(
    service: Any,
    tmp_path_factory: pytest.TempPathFactory,
    raw: bytes,
    text: str,
    as_list: bool,
) -> None:
    folder = tmp_path_factory.mktemp("service")
    scene, plan = folder / "scene.json", folder / "plan.txt"
    scene.write_bytes(raw)
    plan.write_text(text, encoding="utf-8")
    printed = runner.invoke(app, ["verify", str(scene), str(plan), "--json"])
    assert printed.exit_code in (0, 1, 2, 3, 4), printed.output
    # The plan as the text of the file, or as the file's lines.
    sent: Any = text.split("\n") if as_list and not text.lstrip().startswith("[") else text
    body = b'{"scene": ' + raw + b', "plan": ' + json.dumps(sent).encode() + b"}"
    got = service.post("/v1/verify", content=body, headers={"content-type": "application/json"})
    event(f"HTTP {got.status_code}, exit {printed.exit_code}")
    assert got.status_code < 500, got.text
    if got.status_code != 200:
        error = got.json()
        assert set(error) == {"status", "error"} and error["status"] == "BAD_INPUT", error
        assert "\n" not in error["error"]
    if printed.exit_code != 2:
        assert got.status_code == 200, (got.text, printed.stdout)
        assert got.text == printed.stdout
        return
    assert got.status_code == 400, (got.text, printed.stdout)
    said = json.loads(printed.stdout)["error"]
    if _is_object(raw) and str(folder) not in said:
        # A scene that reads one way: the same line (the body has nothing
        # else to refuse).  Otherwise the body is refused before the plan is
        # read, and the CLI's line names its file.
        assert error["error"] == said


@fuzz(20, 200)
@given(data=st.data())
def test_the_service_applies_answers_as_the_api_does(
    service: Any,
    quick: LogicTutor,
    open_questions: list[tuple[dict[str, Any], list[str], Any]],
    data: st.DataObject,
) -> None:
    scene, plan, report = data.draw(st.sampled_from(open_questions))
    content = data.draw(answers_content(report.questions))
    got = service.post("/v1/apply-answers", json={"scene": scene, "plan": plan, "answers": content})
    event(f"HTTP {got.status_code}")
    assert got.status_code in (200, 400), got.text
    if got.status_code == 400:
        error = got.json()
        assert set(error) == {"status", "error"} and "\n" not in error["error"]
        return
    update = apply_answers(scene, report.questions, content, quick.tbox.vocabulary)
    assert got.json()["scene"] == update.scene
    assert got.json()["applied"] == list(update.applied)
