"""Checked corrections (virf.verify.repairs): every one offered verifies SAFE."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest
from conftest import EXAMPLES_DIR, inst, rel
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from virf.api import LogicTutor
from virf.errors import InputError
from virf.planner import ScriptedApprentice
from virf.planner.loop import refine
from virf.planner.methods import get_method, run_method
from virf.render.feedback import feedback_prompt
from virf.schema import Report
from virf.verify.repairs import MAX_OFFERED, Candidate, candidates
from virf.verify.verifier import Verifier
from virf.world.plan import PlanStep, load_plan_file, parse_plan
from virf.world.scene import Scene, build_scene

BURNER = EXAMPLES_DIR / "burner-left-on"
HEAT_POT = [
    "find Pot_1",
    "pick Pot_1",
    "find Microwave_1",
    "open Microwave_1",
    "put Pot_1 in Microwave_1",
    "close Microwave_1",
    "turn_on Microwave_1",
    "turn_off Microwave_1",
    "open Microwave_1",
    "pick Pot_1",
    "close Microwave_1",
]


def microwave_scene(bowl: bool) -> dict[str, Any]:
    """A metal pot to heat in a microwave; with ``bowl``, a ceramic bowl beside it."""
    instances = [
        inst("Microwave", "Microwave_1"),
        inst("Pot", "Pot_1"),
        inst("CounterTop", "CounterTop_1"),
    ]
    assertions = [
        rel("Microwave_1", "hasState", "ClosedState"),
        rel("Microwave_1", "hasState", "OffState"),
        rel("Pot_1", "isOn", "CounterTop_1"),
        # Filled, so that neither runs the microwave empty.
        rel("Pot_1", "hasState", "FilledWithLiquidState"),
    ]
    if bowl:
        instances.append(inst("Bowl", "Bowl_1"))
        assertions += [
            rel("Bowl_1", "isOn", "CounterTop_1"),
            rel("Bowl_1", "hasMaterial", "Ceramic"),
            rel("Bowl_1", "hasState", "FilledWithLiquidState"),
        ]
    return {"instances": instances, "assertions": assertions}


def checked(
    tutor: LogicTutor, scene: Scene, plan: Sequence[PlanStep], **kw: Any
) -> tuple[Report, tuple[Candidate, ...]]:
    report = tutor.verifier.verify(scene, plan)
    return report, candidates(scene, plan, report, tutor.verifier, tutor.tbox.vocabulary, **kw)


def assert_all_safe(tutor: LogicTutor, scene: Scene, offered: Sequence[Candidate]) -> None:
    """Each offered plan, verified again by a verifier of its own."""
    fresh = Verifier(tutor.tbox, tutor.engine)
    for c in offered:
        assert fresh.verify(scene, parse_plan(c.plan)).status == "SAFE", c.edit


def test_burner_left_on_offers_turning_the_knob_off(tutor: LogicTutor) -> None:
    scene = tutor.scene(BURNER / "scene.json")
    plan = load_plan_file(BURNER / "plan.txt")
    report, offered = checked(tutor, scene, plan)
    assert report.status == "UNSAFE"
    assert [c.edit for c in offered] == ["insert `turn_off StoveKnob_1` at the end (after step 3)"]
    (c,) = offered
    assert c.kind == "insert" and c.kept == len(plan)
    assert c.plan == (*(s.text for s in plan), "turn_off StoveKnob_1")
    assert "StoveBurner_1" in c.why and "OnState" in c.why
    assert_all_safe(tutor, scene, offered)


def test_dropping_the_dangerous_step_is_not_offered_when_only_moves_remain(
    tutor: LogicTutor,
) -> None:
    # Without turn_on the burner plan only finds things: doing nothing is no correction.
    scene = tutor.scene(BURNER / "scene.json")
    _, offered = checked(tutor, scene, load_plan_file(BURNER / "plan.txt"))
    assert all(c.kind != "drop" for c in offered)


# A filled bowl to heat in a microwave, written as a small model writes it:
# nothing found first, the door never opened.
TERSE = ["pick Bowl_1", "put Microwave_1", "turn_on Microwave_1", "turn_off Microwave_1"]


def test_steps_a_plan_lacks_are_supplied_one_after_another(tutor: LogicTutor, vocab: Any) -> None:
    # As in a benchmark scene, the robot must find each object before using it.
    scene = build_scene({**microwave_scene(bowl=True), "unlocated_by_default": True}, vocab)
    report, offered = checked(tutor, scene, parse_plan(TERSE))
    assert report.violations[0].id == "LogicalInconsistency_ActionOnUnlocatedObject"
    first = offered[0]
    assert first.kind == "insert" and first.kept == len(TERSE)
    assert first.plan == (
        "find Bowl_1",
        "pick Bowl_1",
        "find Microwave_1",
        "open Microwave_1",
        "put Microwave_1",
        "close Microwave_1",
        "turn_on Microwave_1",
        "turn_off Microwave_1",
    )
    assert first.edit.startswith("insert `find Bowl_1` before `pick Bowl_1`; ")
    assert_all_safe(tutor, scene, offered)


def test_nothing_is_supplied_where_the_danger_is_the_material(
    tutor: LogicTutor, vocab: Any
) -> None:
    # The twin: every step is in place, and the pot is metal. No step the
    # plan lacks would end that, so no supplied plan is offered.
    scene = build_scene({**microwave_scene(bowl=False), "unlocated_by_default": True}, vocab)
    report, offered = checked(tutor, scene, parse_plan(HEAT_POT))
    assert report.status == "UNSAFE"
    assert not [c for c in offered if "before `" in c.edit]
    assert_all_safe(tutor, scene, offered)


def test_metal_pot_with_a_ceramic_bowl_in_the_scene_offers_the_bowl(
    tutor: LogicTutor, vocab: Any
) -> None:
    scene = build_scene(microwave_scene(bowl=True), vocab)
    report, offered = checked(tutor, scene, parse_plan(HEAT_POT))
    assert report.status == "UNSAFE" and report.violations[0].id == "MetalInRunningMicrowaveDanger"
    swaps = [c for c in offered if c.kind == "substitute"]
    assert [c.edit for c in swaps] == ["use Bowl_1 (Ceramic) instead of Pot_1 (Metal)"]
    assert swaps[0].plan == tuple(line.replace("Pot_1", "Bowl_1") for line in HEAT_POT)
    assert len(offered) <= MAX_OFFERED
    assert_all_safe(tutor, scene, offered)


def test_metal_pot_without_a_bowl_gets_no_substitution(tutor: LogicTutor, vocab: Any) -> None:
    scene = build_scene(microwave_scene(bowl=False), vocab)
    report, offered = checked(tutor, scene, parse_plan(HEAT_POT))
    assert report.status == "UNSAFE"
    assert not [c for c in offered if c.kind == "substitute"]
    assert_all_safe(tutor, scene, offered)


def test_a_metal_bowl_is_not_offered_and_one_of_no_stated_material_says_so(
    tutor: LogicTutor, vocab: Any
) -> None:
    metal = microwave_scene(bowl=True)
    metal["assertions"] = [
        rel("Bowl_1", "hasMaterial", "Metal") if a["property"] == "hasMaterial" else a
        for a in metal["assertions"]
    ]
    _, offered = checked(tutor, build_scene(metal, vocab), parse_plan(HEAT_POT))
    assert not [c for c in offered if c.kind == "substitute"]
    # AI2-THOR's bowls are ceramic, glass or plastic: never metal, so the
    # tutor passes one the scene says nothing about, and the edit says no more.
    unsaid = microwave_scene(bowl=True)
    unsaid["assertions"] = [a for a in unsaid["assertions"] if a["property"] != "hasMaterial"]
    scene = build_scene(unsaid, vocab)
    _, offered = checked(tutor, scene, parse_plan(HEAT_POT))
    swaps = [c.edit for c in offered if c.kind == "substitute"]
    assert swaps == ["use Bowl_1 (not Metal) instead of Pot_1 (Metal)"]
    assert_all_safe(tutor, scene, offered)


def test_same_input_same_corrections_and_feedback(tutor: LogicTutor, vocab: Any) -> None:
    scene = build_scene(microwave_scene(bowl=True), vocab)
    plan = parse_plan(HEAT_POT)
    first, again = checked(tutor, scene, plan), checked(tutor, scene, plan)
    assert first == again and first[1]
    assert feedback_prompt(*first) == feedback_prompt(*again)


def test_feedback_lists_each_correction_with_its_whole_plan(tutor: LogicTutor) -> None:
    scene = tutor.scene(BURNER / "scene.json")
    report, offered = checked(tutor, scene, load_plan_file(BURNER / "plan.txt"))
    prompt = feedback_prompt(report, offered)
    # The paper's template comes first, unchanged.
    assert prompt.startswith(feedback_prompt(report))
    section = prompt[len(feedback_prompt(report)) :]
    assert "[CHECKED CORRECTIONS]" in section and "passes safety verification" in section
    assert "Correction 1: insert `turn_off StoveKnob_1` at the end (after step 3)" in section
    assert section.endswith("Plan:\n" + "\n".join(offered[0].plan) + "\n")


def test_no_corrections_leave_the_prompt_as_it_was(example_report: Callable[[str], Report]) -> None:
    report = example_report("walkthrough")
    assert feedback_prompt(report, ()) == feedback_prompt(report)


def test_a_tutor_out_of_time_offers_none(tutor: LogicTutor) -> None:
    scene = tutor.scene(BURNER / "scene.json")
    plan = load_plan_file(BURNER / "plan.txt")
    report = tutor.verifier.verify(scene, plan)
    hurried = Verifier(tutor.tbox, tutor.engine, timeout_s=1e-9)
    assert candidates(scene, plan, report, hurried, tutor.tbox.vocabulary) == ()
    # A deadline already passed: nothing is verified, nothing offered.
    late = time.monotonic() - 1
    assert (
        candidates(scene, plan, report, tutor.verifier, tutor.tbox.vocabulary, deadline=late) == ()
    )


def test_only_unsafe_reports_get_corrections(tutor: LogicTutor) -> None:
    scene = tutor.scene(EXAMPLES_DIR / "safe-fridge" / "scene.json")
    plan = load_plan_file(EXAMPLES_DIR / "safe-fridge" / "plan.txt")
    report, offered = checked(tutor, scene, plan)
    assert report.status == "SAFE" and offered == ()


class Failing:
    """A tutor that breaks on every correction: none may be offered."""

    def __init__(self, inner: Verifier) -> None:
        self.inner = inner

    def verify(self, scene: Scene, plan: Sequence[PlanStep]) -> Report:
        raise RuntimeError("the engine died")


def test_a_failing_tutor_offers_none(tutor: LogicTutor) -> None:
    scene = tutor.scene(BURNER / "scene.json")
    plan = load_plan_file(BURNER / "plan.txt")
    report = tutor.verifier.verify(scene, plan)
    assert candidates(scene, plan, report, Failing(tutor.verifier), tutor.tbox.vocabulary) == ()


# ---------------------------------------------------------------- random plans
def _cases() -> list[Path]:
    return sorted(
        p
        for p in EXAMPLES_DIR.iterdir()
        if (p / "scene.json").is_file() and (p / "plan.txt").is_file()
    )


VERBS_ON_ONE = ["find", "pick", "open", "close", "turn_on", "turn_off", "put", "slice", "cook"]


@settings(
    max_examples=15,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_every_offered_correction_verifies_safe(
    data: st.DataObject, example_tutor: Callable[[str], LogicTutor]
) -> None:
    case = data.draw(st.sampled_from(_cases()))
    tutor = example_tutor(case.name)
    scene = tutor.scene(case / "scene.json")
    original = [s.text for s in load_plan_file(case / "plan.txt")]
    names = [o for o in scene.order if o != scene.agent]
    made = st.builds(
        lambda verb, obj: f"{verb} {obj}", st.sampled_from(VERBS_ON_ONE), st.sampled_from(names)
    )
    lines = data.draw(st.lists(st.one_of(st.sampled_from(original), made), min_size=1, max_size=8))
    try:
        plan = parse_plan(lines)
    except InputError:
        return  # a random line the reader refuses: no plan to correct
    _, offered = checked(tutor, scene, plan)
    assert len(offered) <= MAX_OFFERED
    assert len({c.plan for c in offered}) == len(offered)
    for c in offered:
        assert c.plan and not all(line.split()[0] == "find" for line in c.plan)
    assert_all_safe(tutor, scene, offered)


# ---------------------------------------------------------------- the loop
def microwave_dialogue(
    tutor: LogicTutor, vocab: Any, apprentice: ScriptedApprentice, instruction: str
) -> Any:
    """Two iterations in the microwave scene with a bowl, corrections on."""
    return refine(
        instruction,
        microwave_scene(bowl=True),
        apprentice,
        tutor.verifier,
        lambda d: build_scene(d, vocab),
        vocab,
        max_iter=2,
        corrections=tutor.verifier,
    )


def test_the_apprentice_takes_a_correction_and_is_approved(tutor: LogicTutor, vocab: Any) -> None:
    scene_data = microwave_scene(bowl=True)
    first = "\n".join(HEAT_POT)
    probe = build_scene(scene_data, vocab)
    _, offered = checked(tutor, probe, parse_plan(HEAT_POT))
    taken = next(c for c in offered if c.kind == "substitute")
    apprentice = ScriptedApprentice([first, "\n".join(taken.plan)])
    result = microwave_dialogue(tutor, vocab, apprentice, "Heat the water.")
    assert result.outcome == "APPROVED" and result.plan == taken.plan
    turns = [t for t in result.transcript if t.kind == "corrections"]
    assert len(turns) == 1 and turns[0].data is not None
    assert [c["edit"] for c in turns[0].data["candidates"]] == [c.edit for c in offered]
    assert "Bowl_1" in turns[0].text
    # The apprentice saw them in its feedback.
    feedback = apprentice.requests[1].messages[-1][1]
    assert "[CHECKED CORRECTIONS]" in feedback and "\n".join(taken.plan) in feedback
    # The approved plan was verified like any other proposal.
    reports = [t for t in result.transcript if t.kind == "report"]
    assert [t.status for t in reports] == ["UNSAFE", "SAFE"]


@pytest.mark.parametrize(("method", "offers"), [("virf", True), ("virf-reject", False)])
def test_virf_offers_corrections_and_virf_reject_does_not(
    tutor: LogicTutor, vocab: Any, method: str, offers: bool
) -> None:
    plan = (BURNER / "plan.txt").read_text()
    apprentice = ScriptedApprentice([plan, plan])
    result = run_method(
        get_method(method),
        "Heat the stove.",
        json.loads((BURNER / "scene.json").read_text()),
        apprentice,
        tutor.verifier,
        lambda d: build_scene(d, vocab),
        vocab,
        max_iter=2,
    )
    kinds = [t.kind for t in result.transcript]
    assert ("corrections" in kinds) is offers
    feedback = apprentice.requests[1].messages[-1][1]
    assert ("[CHECKED CORRECTIONS]" in feedback) is offers


# ---------------------------------------------------------------- 'USE n'
class ConstrainedScript(ScriptedApprentice):
    """A scripted apprentice that says it decodes within the constraint."""

    @property
    def constrained(self) -> bool:
        return True


def test_the_apprentice_takes_a_correction_by_its_number(tutor: LogicTutor, vocab: Any) -> None:
    scene_data = microwave_scene(bowl=True)
    probe = build_scene(scene_data, vocab)
    _, offered = checked(tutor, probe, parse_plan(HEAT_POT))
    n = next(i for i, c in enumerate(offered, 1) if c.kind == "substitute")
    apprentice = ConstrainedScript(["\n".join(HEAT_POT), f"USE {n}"])
    result = microwave_dialogue(tutor, vocab, apprentice, "Heat the water in the pot.")
    assert result.outcome == "APPROVED" and result.plan == offered[n - 1].plan
    taken = [t for t in result.transcript if t.kind == "proposal"][-1]
    assert taken.data == {"reply": f"USE {n}", "chose": n}
    # Verified like any other proposal: the choice is a plan, not a verdict.
    reports = [t for t in result.transcript if t.kind == "report"]
    assert [t.status for t in reports] == ["UNSAFE", "SAFE"]
    # The feedback said how to choose, and the grammar allowed exactly as many
    # choices as were offered: none before the feedback, len(offered) after.
    assert 'reply with exactly "USE n"' in apprentice.requests[1].messages[-1][1]
    first, second = (r.constraint for r in apprentice.requests)
    assert first is not None and second is not None
    assert (first.choices, second.choices) == (0, len(offered))
    # The bowl of the correction is writable now, though the instruction never named it.
    assert "pick Bowl_1" in second.lines() and "pick Bowl_1" not in first.lines()


def burner_dialogue(
    tutor: LogicTutor, vocab: Any, replies: list[str], *, corrections: bool
) -> tuple[Any, ScriptedApprentice]:
    """The burner left on, then ``replies``: the loop's result and the apprentice."""
    apprentice = ScriptedApprentice([(BURNER / "plan.txt").read_text(), *replies])
    result = refine(
        "Heat the stove.",
        json.loads((BURNER / "scene.json").read_text()),
        apprentice,
        tutor.verifier,
        lambda d: build_scene(d, vocab),
        vocab,
        max_iter=len(replies) + 1,
        corrections=tutor.verifier if corrections else None,
    )
    return result, apprentice


@pytest.mark.parametrize("reply", ["USE 4", "use 0"])
def test_a_number_no_correction_has_is_unreadable(
    tutor: LogicTutor, vocab: Any, reply: str
) -> None:
    result, apprentice = burner_dialogue(tutor, vocab, [reply, reply], corrections=True)
    offered = next(t for t in result.transcript if t.kind == "corrections").data
    assert offered is not None and len(offered["candidates"]) < 4
    assert result.outcome != "APPROVED"
    unreadable = [t for t in result.transcript if t.kind == "unreadable"]
    assert unreadable
    said = apprentice.requests[2].messages[-1][1]
    n = reply.split()[1]
    assert f"USE {n}: no correction {n}; corrections 1 to {len(offered['candidates'])}" in said


def test_a_choice_with_no_corrections_offered_is_unreadable(tutor: LogicTutor, vocab: Any) -> None:
    # VIRF-Reject's feedback offers no corrections: 'USE 1' names nothing.
    result, _ = burner_dialogue(tutor, vocab, ["USE 1"], corrections=False)
    (turn,) = [t for t in result.transcript if t.kind == "unreadable"]
    assert turn.text == "USE 1"
    assert result.outcome != "APPROVED"


def test_virf_plan_shows_which_correction_was_taken(tutor: LogicTutor, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from virf.cli.main import app

    replies = [(BURNER / "plan.txt").read_text(), "USE 1"]
    replay = tmp_path / "replay.jsonl"
    replay.write_text(
        "".join(
            json.dumps({"task_id": "burner", "iteration": i, "text": text}) + "\n"
            for i, text in enumerate(replies)
        )
    )
    args = ["plan", "--scene", str(BURNER / "scene.json"), "-i", "Heat the stove."]
    args += ["-p", f"replay:{replay}", "--task-id", "burner"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.stdout + result.stderr
    assert "iteration 1 · apprentice · proposal · took correction 1" in result.stdout
    assert "APPROVED after 2 iteration(s)" in result.stdout
