"""Algorithm 1 with scripted apprentices and the real Logic Tutor."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from conftest import EXAMPLES_DIR
from loop_support import CLOSES, FRIDGE_SCENE, LEAVES_OPEN

from virf.api import LogicTutor
from virf.errors import InputError
from virf.planner import Purpose, ScriptedApprentice
from virf.planner.loop import LoopResult, refine
from virf.planner.prompting import read_plan
from virf.planner.questions import answers_file, apply_answers
from virf.world.plan import load_plan_file
from virf.world.scene import build_scene

BURNER = json.loads((EXAMPLES_DIR / "burner-left-on-open-world" / "scene.json").read_text())
BURNER_PLAN = "find StoveBurner_1\nfind StoveKnob_1\nturn_on StoveKnob_1"


def run(
    tutor: LogicTutor, replies: list[str], scene: dict[str, Any] = FRIDGE_SCENE, **kw: Any
) -> tuple[LoopResult, ScriptedApprentice]:
    apprentice = ScriptedApprentice(replies)
    result = refine(
        "Put the apple in the fridge.",
        scene,
        apprentice,
        tutor.verifier,
        lambda d: build_scene(d, tutor.tbox.vocabulary),
        tutor.tbox.vocabulary,
        **kw,
    )
    return result, apprentice


def test_unsafe_plan_is_repaired_after_the_diagnostic(
    fridge_tutor: tuple[LogicTutor, str],
) -> None:
    tutor, fridge_rule = fridge_tutor
    result, apprentice = run(tutor, [LEAVES_OPEN, CLOSES])
    assert result.outcome == "APPROVED"
    assert result.plan == tuple(CLOSES.splitlines())
    assert result.iterations == 2
    second = apprentice.requests[1].as_messages()
    assert "DIAGNOSTIC REPORT" in second[-1]["content"]
    assert fridge_rule in second[-1]["content"]
    kinds = [(t.speaker, t.kind, t.status) for t in result.transcript]
    assert kinds == [
        ("user", "instruction", None),
        ("apprentice", "proposal", None),
        ("tutor", "report", "UNSAFE"),
        ("apprentice", "proposal", None),
        ("tutor", "report", "SAFE"),
    ]


def test_each_proposal_says_whether_it_plans_or_repairs(tutor: LogicTutor) -> None:
    # The first request asks for a plan; each later one answers feedback (an
    # unreadable reply, then a tutor's report), so the apprentice is told so.
    result, apprentice = run(tutor, ["levitate Apple_1", LEAVES_OPEN, CLOSES])
    assert result.outcome == "APPROVED" and result.iterations == 3
    assert [r.purpose for r in apprentice.requests] == [
        Purpose.PLAN,
        Purpose.REPAIR,
        Purpose.REPAIR,
    ]


def test_refusal_rejects_the_task(tutor: LogicTutor) -> None:
    result, _ = run(tutor, ["TASK_ABORT"])
    assert (result.outcome, result.plan, result.iterations) == ("TASK_REJECTED", None, 1)


def test_unreadable_lines_are_sent_back(tutor: LogicTutor) -> None:
    result, apprentice = run(tutor, ["Plan:\n1. find Apple_1\n2. levitate Apple_1", CLOSES])
    assert result.outcome == "APPROVED" and result.iterations == 2
    assert "levitate Apple_1" in apprentice.requests[1].as_messages()[-1]["content"]


def test_a_failed_proposal_is_never_a_plan(tutor: LogicTutor) -> None:
    result, _ = run(tutor, [""])
    assert result.outcome == "TASK_REJECTED" and result.plan is None
    assert result.transcript[-1].kind == "failed-proposal"


def test_iterations_run_out(tutor: LogicTutor) -> None:
    result, _ = run(tutor, [LEAVES_OPEN] * 3, max_iter=3)
    assert result.outcome == "TASK_REJECTED" and result.iterations == 3


def test_unknown_asks_the_user_and_reverifies_the_same_plan(tutor: LogicTutor) -> None:
    asked: list[list[str]] = []

    def user(questions: Any) -> dict[str, str]:
        asked.append([q.key for q in questions])
        return {q.key: "yes" for q in questions}

    result, apprentice = run(tutor, [BURNER_PLAN, "TASK_ABORT"], BURNER, answer=user)
    assert asked == [["contents:supports:StoveBurner_1"]]
    statuses = [t.status for t in result.transcript if t.kind == "report"]
    # Confirmed empty: the same plan is now definitely unsafe, and the
    # apprentice gets the diagnostic (and refuses here).
    assert statuses == ["UNKNOWN", "UNSAFE"]
    assert len(apprentice.requests) == 2
    assert result.outcome == "TASK_REJECTED"


def test_unanswered_questions_go_back_to_the_apprentice(tutor: LogicTutor) -> None:
    result, apprentice = run(tutor, [BURNER_PLAN, "TASK_ABORT"], BURNER)
    assert [t.status for t in result.transcript if t.kind == "report"] == ["UNKNOWN"]
    assert "nothing is on StoveBurner_1" in apprentice.requests[1].as_messages()[-1]["content"]


def test_answers_file_and_scene_update(tmp_path: Path, tutor: LogicTutor) -> None:
    report = tutor.verify(BURNER, BURNER_PLAN.splitlines())
    questions = report.questions
    path = tmp_path / "answers.json"
    path.write_text(json.dumps({"contents:supports:StoveBurner_1": "yes", "other": "no"}))
    answers = answers_file(path)(questions)
    update = apply_answers(BURNER, questions, answers, tutor.tbox.vocabulary)
    assert update.applied == ("contents:supports:StoveBurner_1",)
    assert update.scene["closed_world"] == ["supports:StoveBurner_1"]
    assert "closed_world" not in BURNER  # the input is not modified
    again = tutor.verify(update.scene, BURNER_PLAN.splitlines())
    assert again.status == "UNSAFE"


def test_material_answers_are_checked(tutor: LogicTutor) -> None:
    scene = json.loads((EXAMPLES_DIR / "unknown-material-microwave" / "scene.json").read_text())
    plan = load_plan_file(EXAMPLES_DIR / "unknown-material-microwave" / "plan.txt")
    questions = tutor.verify(scene, plan).questions
    material = [q for q in questions if q.kind == "material"]
    assert material
    with pytest.raises(InputError, match="unknown material 'Kryptonite'"):
        apply_answers(scene, material, {material[0].key: "Kryptonite"}, tutor.tbox.vocabulary)
    update = apply_answers(scene, material, {material[0].key: "glass"}, tutor.tbox.vocabulary)
    assert update.applied == (material[0].key,)
    after = tutor.verify(update.scene, plan).questions
    assert material[0].key not in {q.key for q in after}


@pytest.mark.parametrize(
    ("reply", "steps", "unreadable", "refused"),
    [
        ("find Apple_1\npick Apple_1", ["find Apple_1", "pick Apple_1"], [], False),
        (
            "Here you go:\n```\n1. find Apple_1\n2) pick Apple_1\n```\nDone.",
            ["find Apple_1", "pick Apple_1"],
            [],
            False,
        ),
        (
            "- **find Apple_1**\n- `turn on StoveKnob_1`",
            ["find Apple_1", "turn_on StoveKnob_1"],
            [],
            False,
        ),
        ("1. find Apple_1\n2. teleport Apple_1", ["find Apple_1"], ["teleport Apple_1"], False),
        ("I cannot do this safely.\nTASK_ABORT", [], [], True),
        ("pick Apple_1 Apple_2", [], ["pick Apple_1 Apple_2"], False),
        ("Put simply, here is the plan:\nfind Apple_1", ["find Apple_1"], [], False),
        ('["find Apple_1", "pick Apple_1"]', ["find Apple_1", "pick Apple_1"], [], False),
        ("find Apple_1\nTASK_ABORT", ["find Apple_1"], [], True),
    ],
)
def test_reading_plans_out_of_replies(
    reply: str, steps: list[str], unreadable: list[str], refused: bool
) -> None:
    read = read_plan(reply)
    assert [s.canonical() for s in read.steps] == steps
    assert [u.split(":")[0] for u in read.unreadable] == unreadable
    assert read.refused == refused


def test_answers_in_the_last_iteration_still_count(paper_tutor: LogicTutor, tmp_path: Path) -> None:
    # The paper's example (its expected.json names scenario paper): a glass
    # bowl of liquid heated in a closed microwave is safe by the paper's rules.
    # The household rules find the same plan unsafe however it is answered (a
    # liquid left heating with no stop, or a microwave running empty).
    tutor = paper_tutor
    scene = json.loads((EXAMPLES_DIR / "unknown-material-microwave" / "scene.json").read_text())
    plan = "\n".join(
        s.text for s in load_plan_file(EXAMPLES_DIR / "unknown-material-microwave" / "plan.txt")
    )
    answers = {
        "material:Bowl_1": "Glass",
        "fill:Bowl_1": "yes",
        "contents:contains:Microwave_1": "yes",
    }
    result, _ = run(tutor, [plan], scene, answer=lambda qs: answers, max_iter=1)
    assert result.outcome == "APPROVED" and result.iterations == 1
    assert [t.status for t in result.transcript if t.kind == "report"][-1] == "SAFE"


def test_the_planner_never_imports_the_reasoner() -> None:
    import subprocess
    import sys

    code = (
        "import sys, virf.planner, virf.planner.loop, virf.planner.methods; "
        "print(any(m.startswith('virf.reasoning') for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_demo_dialogue_replays(tutor: LogicTutor) -> None:
    from virf.planner import ReplayApprentice

    folder = EXAMPLES_DIR / "dialogue"
    result = refine(
        (folder / "instruction.txt").read_text().strip(),
        json.loads((folder / "scene.json").read_text()),
        ReplayApprentice(folder / "replay.jsonl"),
        tutor.verifier,
        lambda d: build_scene(d, tutor.tbox.vocabulary),
        tutor.tbox.vocabulary,
        task_id="demo-fridge",
    )
    assert result.outcome == "APPROVED" and result.iterations == 2
