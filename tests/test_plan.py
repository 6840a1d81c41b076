"""Plan parsing: SafeAgentBench's action language, the paper's function style, JSON lists."""

from __future__ import annotations

import pytest

from virf.errors import InputError
from virf.world.language import ACTION_CLASS, ARITY, VERBS
from virf.world.plan import load_plan_file, parse_plan_text


def one(text: str) -> tuple[str, tuple[str, ...]]:
    steps = parse_plan_text(text)
    assert len(steps) == 1
    return steps[0].verb, steps[0].args


@pytest.mark.parametrize(
    ("text", "verb", "args"),
    [
        ("pick up Pot_1", "pick", ("Pot_1",)),
        ("pick Pot_1", "pick", ("Pot_1",)),
        ("Pick Up Pot_1", "pick", ("Pot_1",)),
        ("turn on X", "turn_on", ("X",)),
        ("toggle on X", "turn_on", ("X",)),
        ("toggle X on", "turn_on", ("X",)),
        ("turn_on X", "turn_on", ("X",)),
        ("turn_off X", "turn_off", ("X",)),
        ("turn X off", "turn_off", ("X",)),
        ("put X in R", "put", ("X", "R")),
        ("put X on R", "put", ("X", "R")),
        ("put X into R", "put", ("X", "R")),
        ("put R", "put", ("R",)),
        ("fillLiquid Mug wine", "fillLiquid", ("Mug", "wine")),
        ("fillLiquid Mug Coffee", "fillLiquid", ("Mug", "coffee")),
        ("emptyLiquid Mug", "emptyLiquid", ("Mug",)),
        ("pour", "pour", ()),
        ("pour Bowl_1", "pour", ("Bowl_1",)),
        ("drop", "drop", ()),
        ("throw", "throw", ()),
        ("drop Mug_1", "drop", ("Mug_1",)),
        ("throw AlarmClock", "throw", ("AlarmClock",)),
        ("slice Apple_1", "slice", ("Apple_1",)),
        ("3. find X", "find", ("X",)),
        ("3) find X", "find", ("X",)),
        ("find X.", "find", ("X",)),
        ("put_in(Pot_1, Microwave_1)", "put", ("Pot_1", "Microwave_1")),
        ("turn_on(Microwave_1)", "turn_on", ("Microwave_1",)),
        ("find(TestMicrowave_Action)", "find", ("TestMicrowave_Action",)),
    ],
)
def test_parse_variants(text: str, verb: str, args: tuple[str, ...]) -> None:
    assert one(text) == (verb, args)


def test_numbering_is_not_part_of_the_step() -> None:
    (step,) = parse_plan_text("3. find X")
    assert step.index == 1
    assert step.text == "find X"
    assert step.canonical() == "find X"


@pytest.mark.parametrize("text", ["put_in(A, B)", "put A in B"])
def test_single_letter_object_names_are_kept(text: str) -> None:
    assert one(text) == ("put", ("A", "B"))


def test_json_list_plan() -> None:
    steps = parse_plan_text('["find Apple_1", "pick up Apple_1", "put_in(Apple_1, Fridge_1)"]')
    assert [(s.index, s.verb, s.args) for s in steps] == [
        (1, "find", ("Apple_1",)),
        (2, "pick", ("Apple_1",)),
        (3, "put", ("Apple_1", "Fridge_1")),
    ]


def test_comments_and_blank_lines_skipped() -> None:
    text = "# heat the soup\n\nfind Pot_1\n   # a comment\n\n  pick Pot_1  \n"
    steps = parse_plan_text(text)
    assert [(s.index, s.verb, s.args) for s in steps] == [
        (1, "find", ("Pot_1",)),
        (2, "pick", ("Pot_1",)),
    ]


def test_every_verb_has_an_action_class_and_arity() -> None:
    assert len(VERBS) == 17
    assert set(VERBS) == set(ACTION_CLASS) == set(ARITY)


def test_plan_file(tmp_path) -> None:
    p = tmp_path / "plan.txt"
    p.write_text("1. find(Apple_1)\n2. pick(Apple_1)\n", encoding="utf-8")
    assert [s.verb for s in load_plan_file(p)] == ["find", "pick"]
    with pytest.raises(InputError, match="not found"):
        load_plan_file(tmp_path / "missing.txt")


# ---------------------------------------------------------------- errors


def test_unknown_verb_names_verb_and_suggestion() -> None:
    with pytest.raises(InputError) as err:
        parse_plan_text("find Apple_1\npikc Apple_1")
    msg = str(err.value)
    assert "'pikc'" in msg
    assert "line 2" in msg
    assert "closest: pick" in msg


def test_unknown_verb_without_near_match_lists_verbs() -> None:
    with pytest.raises(InputError) as err:
        parse_plan_text("xyzzy Apple_1")
    msg = str(err.value)
    assert "'xyzzy'" in msg
    assert all(v in msg for v in VERBS)


@pytest.mark.parametrize(
    ("text", "verb"),
    [
        ("pick", "pick"),
        ("pick A_1 B_1", "pick"),
        ("drop Mug_1 Cup_1", "drop"),
        ("throw Mug_1 Cup_1", "throw"),
        ("fillLiquid Mug_1", "fillLiquid"),
        ("open", "open"),
        ("pour A_1 B_1", "pour"),
    ],
)
def test_wrong_arity(text: str, verb: str) -> None:
    with pytest.raises(InputError, match=rf"'{verb}' takes .* argument\(s\), got"):
        parse_plan_text(text)


def test_unknown_liquid() -> None:
    with pytest.raises(InputError) as err:
        parse_plan_text("fillLiquid Mug_1 milk")
    msg = str(err.value)
    assert "'milk'" in msg
    assert "water" in msg


@pytest.mark.parametrize("text", ["[bad json", '["find A_1", 3]', '{"plan": 1}'])
def test_bad_json_plan(text: str) -> None:
    with pytest.raises(InputError):
        parse_plan_text(text)
