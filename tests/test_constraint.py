"""Constrained decoding: the plan lines a scene allows, and their grammar.

Pure tests: no model is loaded.  tests/test_local_llm.py compiles the
grammar in llama.cpp and decodes with it; tests/test_planner_clients.py
sends the JSON schema to a served model.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from conftest import inst, rel
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from virf.api import LogicTutor
from virf.bench.safeagentbench import load_tasks
from virf.ontology.tbox import Vocabulary
from virf.planner import ScriptedApprentice
from virf.planner.constraint import (
    MAX_LINES,
    PlanConstraint,
    _literal,
    plan_constraint,
)
from virf.planner.loop import refine
from virf.planner.methods import get_method, run_method
from virf.planner.prompting import REFUSAL, read_after_plan_marker, read_plan
from virf.world.language import LIQUIDS, VERBS
from virf.world.scene import Scene, build_scene, load_scene_data

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


def kitchen(vocab: Vocabulary) -> Scene:
    """A SafeAgentBench kitchen as the agent benchmark builds it."""
    task = load_tasks(EXAMPLES / "agents" / "tasks.jsonl")[0]
    return build_scene(task.scene_data(vocab), vocab, name="kitchen")


def theremin_room(vocab: Vocabulary) -> Scene:
    # A Theremin is no type the catalogue knows: nobody declared what it
    # affords, so the simulator refuses nothing of it, and neither may the grammar.
    return build_scene(
        {
            "instances": [
                inst("Robot", "Robot_1"),
                inst("Theremin", "Theremin_1"),
                inst("Mug", "Mug_1"),
                inst("CounterTop", "CounterTop_1"),
                inst("Apple", "Apple_1"),
            ],
            "assertions": [rel("CounterTop_1", "supports", "Theremin_1")],
        },
        vocab,
        name="theremin",
    )


def test_the_kitchen_offers_each_verb_only_the_objects_that_may_take_it(
    vocab: Vocabulary,
) -> None:
    scene = kitchen(vocab)
    c = plan_constraint(scene, vocab)
    objects = sorted(o for o in scene.order if o != scene.agent)
    assert c.objects_of("find") == tuple(objects)
    assert scene.agent not in c.objects_of("find")
    microwave = next(o for o in objects if o.startswith("Microwave"))
    egg = next(o for o in objects if o.startswith("Egg"))
    assert egg in c.objects_of("pick") and microwave not in c.objects_of("pick")
    assert microwave in c.objects_of("put") and egg not in c.objects_of("put")
    assert microwave in c.objects_of("turn_on") and egg not in c.objects_of("turn_on")
    # The simulator's rule: put refuses only a catalogue type that is no receptacle.
    for name in objects:
        classes = scene.objects[name]
        assert (name in c.objects_of("put")) == vocab.any_is_a(classes, "Receptacle")
    # Verbs keep the language's order; a verb nothing takes is left out.
    assert [v for v, _ in c.takes] == [v for v in VERBS if c.objects_of(v)]


def test_an_open_world_type_takes_every_verb(vocab: Vocabulary) -> None:
    scene = theremin_room(vocab)
    assert scene.open_world.get("Theremin_1") == "Theremin"
    c = plan_constraint(scene, vocab)
    for verb in VERBS:
        assert "Theremin_1" in c.objects_of(verb), verb
    # A catalogue type keeps its own limits beside it.
    assert "Apple_1" not in c.objects_of("turn_on")
    assert "CounterTop_1" not in c.objects_of("pick")
    assert {f"fillLiquid Theremin_1 {liquid}" for liquid in LIQUIDS} <= set(c.lines())


def test_the_constraint_is_deterministic_and_immutable(vocab: Vocabulary) -> None:
    data = load_scene_data(EXAMPLES / "burner-left-on" / "scene.json")
    first = plan_constraint(build_scene(data, vocab), vocab)
    # The same scene with its instances listed in another order.
    shuffled = dict(data, instances=list(reversed(data["instances"])))
    second = plan_constraint(build_scene(shuffled, vocab), vocab)
    assert first == second and hash(first) == hash(second)
    assert first.gbnf() == second.gbnf() and first.gbnf(True) == second.gbnf(True)
    assert all(list(names) == sorted(names) for _, names in first.takes)
    with pytest.raises(AttributeError):
        first.takes = ()  # type: ignore[misc]


@pytest.mark.parametrize("make", [kitchen, theremin_room])
def test_every_allowed_line_reads_back_to_its_step(vocab: Vocabulary, make: Any) -> None:
    scene = make(vocab)
    c = plan_constraint(scene, vocab)
    names = set(scene.order) - {scene.agent}
    lines = c.lines()
    assert lines and len(set(lines)) == len(lines)
    for line in lines:
        got = read_plan(line)
        assert not got.refused and not got.unreadable and len(got.steps) == 1, line
        step = got.steps[0]
        assert step.canonical() == line and step.note is None
        assert step.args[0] in names
    # And all of them at once, as one reply of MAX_LINES lines would be read.
    chunk = lines[:MAX_LINES]
    assert [s.canonical() for s in read_plan("\n".join(chunk)).steps] == list(chunk)


def test_a_name_the_reader_reads_otherwise_is_not_offered(vocab: Vocabulary) -> None:
    # 'find it' is the pronoun for the object of the step before: offering
    # it would put a line in the model's mouth that names another object.
    scene = build_scene({"instances": [inst("Mug", "it"), inst("Mug", "Mug_1")]}, vocab)
    c = plan_constraint(scene, vocab)
    assert all("it" not in names for _, names in c.takes)
    assert "Mug_1" in c.objects_of("find")


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_random_rooms_allow_only_lines_that_read_back(vocab: Vocabulary, data: Any) -> None:
    kinds = ["Mug", "Apple", "Fridge", "StoveKnob", "CounterTop", "Theremin", "Knife", "Sink"]
    chosen = data.draw(st.lists(st.sampled_from(kinds), min_size=1, max_size=6))
    suffix = data.draw(st.sampled_from(["_1", "2", "_a.b", "-x", ""]))
    instances = [inst("Robot", "Robot_1")] + [
        inst(kind, f"{kind}{suffix}{n}") for n, kind in enumerate(chosen)
    ]
    scene = build_scene({"instances": instances, "assertions": []}, vocab)
    c = plan_constraint(scene, vocab)
    names = set(scene.order) - {scene.agent}
    for line in c.lines():
        (step,) = read_plan(line).steps
        assert step.canonical() == line and step.args[0] in names


def test_the_grammar_allows_abort_or_bounded_valid_lines(vocab: Vocabulary) -> None:
    c = plan_constraint(kitchen(vocab), vocab)
    text = c.gbnf()
    rules = dict(line.split(" ::= ", 1) for line in text.splitlines())
    assert rules["root"] == f'"{REFUSAL}" | plan'
    assert rules["plan"] == f'line ("\\n" line){{0,{MAX_LINES - 1}}}'
    # One rule per verb that takes anything, each listing exactly its objects.
    for verb, names in c.takes:
        rule = verb.lower().replace("_", "-")
        assert rules[f"{rule}-line"].startswith(f'"{verb} " {rule}-obj')
        assert re.findall(r'"([^"]*)"', rules[f"{rule}-obj"]) == list(names)
    assert "REASONING" not in text
    # Every rule a right-hand side uses is defined.
    bare = re.sub(r'"(?:\\.|[^"\\])*"', "", text)
    assert set(re.findall(r"[a-z-]+-(?:line|obj)\b", bare)) <= set(rules)


def test_the_reasoning_grammar_wraps_the_plan(vocab: Vocabulary) -> None:
    c = plan_constraint(kitchen(vocab), vocab)
    rules = dict(line.split(" ::= ", 1) for line in c.gbnf(reasoning=True).splitlines())
    assert rules["root"] == (
        f'"{REFUSAL}" | "REASONING:\\n" note{{1,3}} "PLAN:\\n" ("{REFUSAL}" | plan)'
    )
    # A note may not start with P, so it cannot be a second 'PLAN:'.
    assert rules["note"] == '[^P\\n] [^\\n]{0,119} "\\n"'
    assert {k: v for k, v in rules.items() if k not in ("root", "note")} == dict(
        line.split(" ::= ", 1) for line in c.gbnf().splitlines() if not line.startswith("root")
    )


def test_an_empty_scene_allows_only_a_refusal(vocab: Vocabulary) -> None:
    c = plan_constraint(build_scene({"instances": [inst("Robot", "Robot_1")]}, vocab), vocab)
    assert c == PlanConstraint(()) and c.lines() == ()
    assert c.gbnf() == c.gbnf(True) == f'root ::= "{REFUSAL}"\n'


def test_after_corrections_the_grammar_also_allows_choosing_one(vocab: Vocabulary) -> None:
    c = plan_constraint(kitchen(vocab), vocab).with_choices(2)
    rules = dict(line.split(" ::= ", 1) for line in c.gbnf().splitlines())
    assert rules["root"] == f'"{REFUSAL}" | plan | choice'
    assert rules["choice"] == '"USE " [1-2]'
    thinking = dict(line.split(" ::= ", 1) for line in c.gbnf(reasoning=True).splitlines())
    assert thinking["root"].endswith('"PLAN:\\n" ("TASK_ABORT" | plan | choice)')
    steps = c.json_schema()["properties"]["steps"]["items"]["enum"]
    assert steps[-3:] == ["USE 1", "USE 2", REFUSAL]
    # Narrowing keeps the choices; without any, no choice rule is written.
    assert c.narrowed(frozenset({"Apple_1"})).choices == 2
    assert "choice" not in plan_constraint(kitchen(vocab), vocab).gbnf()
    # With nothing in the scene to act on, a choice is still a reply.
    empty = PlanConstraint(()).with_choices(1)
    assert empty.gbnf() == f'root ::= "{REFUSAL}" | choice\nchoice ::= "USE " [1-1]\n'


@pytest.mark.parametrize(
    ("reply", "choice", "steps"),
    [
        ("USE 2", 2, 0),
        ('"use 1"', 1, 0),
        ("**USE 3**", 3, 0),
        ("REASONING:\nthe bowl is safe\nPLAN:\nUSE 1", 1, 0),
        # A plan of its own wins over a choice in the same reply.
        ("USE 1\nfind Apple_1", None, 1),
        # Only the exact answer: prose that starts with the word is prose.
        ("Use 2 apples", None, 0),
    ],
)
def test_the_reader_reads_a_choice(reply: str, choice: int | None, steps: int) -> None:
    got = read_after_plan_marker(reply)
    assert (got.choice, len(got.steps), got.refused) == (choice, steps, False)


def test_literals_escape_what_would_end_them() -> None:
    assert _literal("Mug_1") == '"Mug_1"'
    assert _literal('a"b\\c') == '"a\\"b\\\\c"'
    assert _literal("x\ny") == '"x\\ny"'
    assert _literal("Tasse\u00e9") == '"Tasse\\u00E9"'
    assert _literal("\U0001f600") == '"\\U0001F600"'


def test_the_json_schema_lists_the_valid_lines(vocab: Vocabulary) -> None:
    c = plan_constraint(theremin_room(vocab), vocab)
    schema = c.json_schema()
    steps = schema["properties"]["steps"]
    assert steps["items"]["enum"] == [*c.lines(), REFUSAL]
    assert steps["minItems"] == 1 and steps["maxItems"] == MAX_LINES
    assert schema["required"] == ["steps"] and schema["additionalProperties"] is False


class Constrained(ScriptedApprentice):
    """A scripted apprentice that says it decodes within the constraint."""

    @property
    def constrained(self) -> bool:
        return True


def test_the_loop_hands_the_scene_constraint_to_the_apprentice(tutor: LogicTutor) -> None:
    vocab = tutor.tbox.vocabulary
    data = load_scene_data(EXAMPLES / "burner-left-on" / "scene.json")
    scene = build_scene(data, vocab)
    # An unreadable reply and a plan: the repair is asked with the constraint too.
    scripted = Constrained(["find the moon", "find Pot_1"])
    result = refine(
        "Find the pot.", data, scripted, tutor.verifier, lambda d: build_scene(d, vocab), vocab
    )
    assert result.outcome == "APPROVED"
    # Narrowed to what the instruction names: the pot, and the counter it is on.
    focused = plan_constraint(scene, vocab).narrowed(frozenset({"Pot_1", "CounterTop_1"}))
    assert [r.constraint for r in scripted.requests] == [focused] * 2
    # Not part of what is logged: the messages are what the model was told.
    assert "constraint" not in json.dumps(scripted.requests[1].as_messages())
    # An apprentice that would not use it (a replay, a scripted one) costs
    # the loop nothing: no constraint is built.
    plain = ScriptedApprentice(["find Pot_1"])
    refine("Find the pot.", data, plain, tutor.verifier, lambda d: build_scene(d, vocab), vocab)
    assert plain.requests[0].constraint is None


def test_one_shot_methods_hand_it_over_too(tutor: LogicTutor) -> None:
    vocab = tutor.tbox.vocabulary
    data = load_scene_data(EXAMPLES / "burner-left-on" / "scene.json")
    scripted = Constrained(["find Pot_1"])
    run_method(
        get_method("impulsive"),
        "Heat the pot.",
        data,
        scripted,
        tutor.verifier,
        lambda d: build_scene(d, vocab),
        vocab,
    )
    (request,) = scripted.requests
    whole = plan_constraint(build_scene(data, vocab), vocab)
    assert request.constraint == whole.narrowed(frozenset({"Pot_1", "CounterTop_1"}))
