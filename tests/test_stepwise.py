"""Plan lines offered one at a time: those that run next, change something,
do not go round a loop, and (with a tutor) make nothing unsafe at their step.

Pure tests: no model is loaded.  The scenes pair worlds that differ only in
the fact that matters (a fridge open or closed; an apple held or not).
"""

from __future__ import annotations

import pytest
from conftest import inst, rel
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from virf.api import LogicTutor
from virf.ontology.tbox import Vocabulary
from virf.planner.constraint import plan_constraint
from virf.planner.focus import Focus
from virf.planner.loop import line_judge
from virf.planner.prompting import read_plan
from virf.planner.stepwise import Sandbox, Stepper
from virf.schema import Fact
from virf.world.language import LIQUIDS
from virf.world.plan import parse_line
from virf.world.scene import Scene, build_scene
from virf.world.simulator import PreconditionFailure, ResolvedStep, Simulator


def pantry(vocab: Vocabulary, fridge: str) -> Scene:
    """A pear on a shelf, a fridge in the given state, and a lamp; the robot
    must find each before acting on it, as in a benchmark scene."""
    return build_scene(
        {
            "unlocated_by_default": True,
            "instances": [
                inst("Robot", "Robot_1"),
                inst("Pear", "Pear_1"),
                inst("Shelf", "Shelf_1"),
                inst("Fridge", "Fridge_1"),
                inst("DeskLamp", "DeskLamp_1"),
            ],
            "assertions": [
                rel("Pear_1", "isOn", "Shelf_1"),
                rel("Fridge_1", "hasState", fridge),
            ],
        },
        vocab,
    )


def stepper(scene: Scene, vocab: Vocabulary, tutor: LogicTutor | None = None) -> Stepper:
    judge = None if tutor is None else line_judge(tutor, scene)
    constraint = plan_constraint(scene, vocab)
    return Stepper(constraint, Sandbox(scene, vocab, judge))


def offered(s: Stepper) -> set[str]:
    return set(s.next_lines().lines())


def test_a_line_is_offered_only_once_it_can_run(vocab: Vocabulary) -> None:
    s = stepper(pantry(vocab, "ClosedState"), vocab)
    first = offered(s)
    # Nothing in the hand: nothing to put or drop.
    assert "find Pear_1" in first
    assert not {line for line in first if line.split()[0] in ("put", "drop", "throw")}
    s.take("find Pear_1")
    s.take("pick Pear_1")
    held = offered(s)
    assert "drop Pear_1" in held
    assert "pick Pear_1" not in held  # already in the hand
    # Back on its shelf, the pear would be where it started.
    assert "put Shelf_1" not in held


def test_a_closed_fridge_takes_nothing_and_an_open_one_does(vocab: Vocabulary) -> None:
    def after_picking(fridge: str) -> set[str]:
        s = stepper(pantry(vocab, fridge), vocab)
        for line in ("find Pear_1", "pick Pear_1", "find Fridge_1"):
            s.take(line)
        return offered(s)

    closed, opened = after_picking("ClosedState"), after_picking("OpenState")
    assert "put Fridge_1" not in closed and "open Fridge_1" in closed
    assert "put Fridge_1" in opened and "open Fridge_1" not in opened


def test_a_line_that_changes_nothing_or_goes_back_is_not_offered(vocab: Vocabulary) -> None:
    s = stepper(pantry(vocab, "ClosedState"), vocab)
    s.take("find Pear_1")
    assert "find Pear_1" not in offered(s)  # the robot is there already
    for line in ("pick Pear_1", "find Fridge_1", "open Fridge_1", "close Fridge_1"):
        assert line in offered(s)
        s.take(line)
    # Closing the fridge undid opening it, which a plan may do once (a fridge
    # left open is a hazard) ...
    assert "open Fridge_1" not in offered(s)
    # ... but not go round.
    s = stepper(pantry(vocab, "OpenState"), vocab)
    lines = ("find Pear_1", "pick Pear_1", "find Fridge_1", "put Fridge_1", "pick Pear_1")
    for line in (*lines, "put Fridge_1"):
        assert line in offered(s), line
        s.take(line)
    # The second 'put' undid the 'pick' before it: the pear may not come out again.
    assert "pick Pear_1" not in offered(s)
    # Going to another object changes where the robot is.
    assert "find Shelf_1" in offered(s) and "find Fridge_1" not in offered(s)


def test_refused_lines_are_left_out_and_others_stay(vocab: Vocabulary) -> None:
    s = stepper(pantry(vocab, "ClosedState"), vocab)
    left = set(s.next_lines(frozenset({"find Pear_1"})).lines())
    assert "find Pear_1" not in left and "find Shelf_1" in left


def test_taking_a_line_that_does_not_run_is_a_fault(vocab: Vocabulary) -> None:
    s = stepper(pantry(vocab, "ClosedState"), vocab)
    with pytest.raises(RuntimeError, match="does not run"):
        s.take("put Shelf_1")


def test_the_tutor_turns_away_a_line_on_an_object_not_yet_found(
    vocab: Vocabulary, tutor: LogicTutor
) -> None:
    s = stepper(pantry(vocab, "ClosedState"), vocab, tutor)
    # The simulator lets the hand reach a pear the robot never went to; the
    # tutor does not (an action on an object not located).
    assert "pick Pear_1" in offered(s)
    assert not s.accepts("pick Pear_1")
    assert s.accepts("find Pear_1")
    s.take("find Pear_1")
    assert s.accepts("pick Pear_1")


def test_without_a_tutor_every_line_is_accepted(vocab: Vocabulary) -> None:
    s = stepper(pantry(vocab, "ClosedState"), vocab)
    assert s.accepts("pick Pear_1")


def test_a_hazard_only_the_end_shows_does_not_turn_a_line_away(
    vocab: Vocabulary, tutor: LogicTutor
) -> None:
    scene = pantry(vocab, "ClosedState")
    lines = ("find Fridge_1", "open Fridge_1")
    # The plan as a whole leaves the fridge open: unsafe at its end ...
    full = tutor.verify(scene, read_plan("\n".join(lines)).steps)
    assert full.status == "UNSAFE"
    assert {v.phase for v in full.violations} == {"final"}
    # ... but opening it is not unsafe at its own step: a later line may close it.
    s = stepper(scene, vocab, tutor)
    s.take("find Fridge_1")
    assert s.accepts("open Fridge_1")


def test_the_focus_carries_the_scene_and_the_judge(vocab: Vocabulary, tutor: LogicTutor) -> None:
    scene = pantry(vocab, "ClosedState")
    judge = line_judge(tutor, scene)
    c = Focus.of("Put the pear in the fridge.", scene, vocab, judge).constraint()
    assert c.sandbox is not None and c.sandbox.judge is judge
    assert {n for _, names in c.takes for n in names} == {"Pear_1", "Fridge_1", "Shelf_1"}
    # Narrowing and the choice of corrections keep it.
    assert c.with_choices(2).sandbox is c.sandbox


def test_the_next_line_grammar_ends_or_adds_one_line(vocab: Vocabulary) -> None:
    s = stepper(pantry(vocab, "ClosedState"), vocab)
    s.take("find Pear_1")
    text = s.next_lines().next_gbnf()
    assert text.startswith('root ::= ("\\n" line)?\n')
    assert '"pick "' in text
    one = s.next_lines().gbnf(lines=1)
    assert "plan ::= line\n" in one


def test_virf_plan_lists_the_lines_turned_away(capsys: pytest.CaptureFixture[str]) -> None:
    from virf.cli.plan import _print_dialogue
    from virf.planner.loop import LoopResult, Turn

    proposal = Turn(
        0,
        "apprentice",
        "proposal",
        "find Pear_1\npick Pear_1",
        data={"reply": "find Pear_1\npick Pear_1", "turned_away": ["pick Pear_1", "drop Pear_1"]},
    )
    _print_dialogue(LoopResult("TASK_REJECTED", None, 1, "gave up", (proposal,)))
    out = capsys.readouterr().out
    assert "(turned away as it was written: pick Pear_1; drop Pear_1)" in out


def _world(s: Stepper) -> frozenset[Fact]:
    return frozenset(f for f in s._state.facts if f.predicate != "isLocated")


def _naive_offered(
    s: Stepper, worlds: list[frozenset[Fact]], back: frozenset[Fact] | None, vocab: Vocabulary
) -> set[str]:
    """The rule of :class:`Stepper` read off whole fact sets: a line is
    offered when it runs, changes the world, and does not bring it back to
    a world the plan has made (except to undo the line before, once)."""
    sim = Simulator(vocab)
    out = set()
    for line in s._constraint.lines():
        verb, *rest = line.split()
        # A vessel's fills are offered together, decided by the first liquid.
        first = f"{verb} {rest[0]} {LIQUIDS[0]}" if verb == "fillLiquid" else line
        resolved = sim.resolve(s._state, parse_line(first, 1, 1, None))
        if not isinstance(resolved, ResolvedStep):
            continue
        after = sim.apply(s._state, resolved)
        if isinstance(after, PreconditionFailure):
            continue
        world = frozenset(f for f in after.facts if f.predicate != "isLocated")
        if world != worlds[-1] and (world == back or world not in worlds):
            out.add(line)
    return out


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data(), fridge=st.sampled_from(["OpenState", "ClosedState"]))
def test_the_offered_lines_follow_the_rule_read_off_whole_fact_sets(
    vocab: Vocabulary, data: st.DataObject, fridge: str
) -> None:
    s = stepper(pantry(vocab, fridge), vocab)
    worlds, back = [_world(s)], None
    for _ in range(8):
        offered_now = s.next_lines().lines()
        assert set(offered_now) == _naive_offered(s, worlds, back, vocab), s.lines
        if not offered_now:
            break
        s.take(data.draw(st.sampled_from(sorted(offered_now))))
        now = _world(s)
        back = None if now == back else worlds[-1]
        worlds.append(now)
