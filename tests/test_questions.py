"""One question model: the report's typed questions are the ones the loop
asks, the CLI shows and the JSON carries, and each answer becomes scene data
that the scene reader rebuilds."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest
from conftest import EXAMPLES_DIR, ROOT, inst
from loop_support import Recorder, run_loop, statuses

from virf.api import LogicTutor
from virf.errors import InputError
from virf.planner import ScriptedApprentice
from virf.planner.loop import MAX_ASKS, LoopResult
from virf.planner.questions import SETTLEABLE, apply_answers, check_answer
from virf.schema import Question, Report
from virf.world.plan import PlanStep, load_plan_file
from virf.world.scene import Scene, build_scene

KETTLE_SCENE: dict[str, Any] = {
    "instances": [
        inst("CounterTop", "CounterTop_1"),
        inst("Fridge", "Fridge_1"),
        inst("Sink", "Sink_1"),
    ],
    "assertions": [],
}
KETTLE_PLAN = "find Kettle\npick Kettle\nfind Sink_1\nput Sink_1"
BOWLS: dict[str, Any] = {
    "instances": [inst("Bowl", "Bowl_1"), inst("Bowl", "Bowl_2"), inst("Microwave", "Microwave_1")],
    "assertions": [
        {"subject": "Bowl_1", "property": "hasMaterial", "object": "Glass"},
        {"subject": "Bowl_2", "property": "hasMaterial", "object": "Metal"},
    ],
}
BOWL_PLAN = (
    "pick Bowl\nfind Microwave_1\nopen Microwave_1\nput Microwave_1\n"
    "close Microwave_1\nturn_on Microwave_1"
)
CONTRADICTION = EXAMPLES_DIR / "noise-contradiction"


def loop(
    tutor: LogicTutor, replies: list[str], scene: Mapping[str, Any], answer: Recorder
) -> tuple[LoopResult, ScriptedApprentice, list[dict[str, Any]]]:
    """Run the loop; also return every scene it built, last one last."""
    built: list[dict[str, Any]] = []

    def build(data: Mapping[str, Any]) -> Scene:
        built.append(dict(data))
        return build_scene(data, tutor.tbox.vocabulary)

    result, apprentice = run_loop(tutor, scene, replies, answer, build=build)
    return result, apprentice, built


def test_a_missing_object_is_asked_and_placed(tutor: LogicTutor) -> None:
    user = Recorder({"where:Kettle": "on CounterTop_1"})
    result, apprentice, built = loop(tutor, [KETTLE_PLAN], KETTLE_SCENE, user)
    assert user.asked == [["where:Kettle"]]
    # The same plan, verified again in the same iteration, now that a kettle exists.
    assert statuses(result) == ["UNKNOWN", "SAFE"]
    assert (result.outcome, result.iterations) == ("APPROVED", 1)
    assert len(apprentice.requests) == 1
    assert {"class_name": "Kettle", "instance_name": "Kettle_1"} in built[-1]["instances"]
    assert {"subject": "Kettle_1", "property": "isOn", "object": "CounterTop_1"} in built[-1][
        "assertions"
    ]


@pytest.mark.parametrize(
    ("scenario", "rule"),
    [("paper", "UnsafeMicrowaveUsage"), ("kitchen", "MetalInRunningMicrowaveDanger")],
)
def test_an_ambiguous_object_is_asked_and_chosen(
    request: pytest.FixtureRequest, scenario: str, rule: str
) -> None:
    tutor = request.getfixturevalue({"paper": "paper_tutor", "kitchen": "tutor"}[scenario])
    user = Recorder({"which:Bowl": "bowl_2"})  # options match case-insensitively
    result, apprentice, built = loop(tutor, [BOWL_PLAN, "TASK_ABORT"], BOWLS, user)
    assert user.asked == [["which:Bowl"]]
    assert built[-1]["referents"] == {"Bowl": "Bowl_2"}
    # Bowl_2 is the metal one: the same plan is now definitely unsafe.
    assert statuses(result) == ["UNKNOWN", "UNSAFE"]
    diagnostic = apprentice.requests[1].as_messages()[-1]["content"]
    assert "Bowl_2" in diagnostic and rule in diagnostic


# The paper's noise test contradicts the microwave door's state (a material read
# two ways is no longer a contradiction: an object may be made of several).
@pytest.mark.parametrize(
    ("answer", "removed", "after"),
    [
        # The open reading is wrong: the door is closed, and the plate heats safely.
        ("2", {"subject": "Microwave_1", "property": "hasState", "object": "OpenState"}, "SAFE"),
        # The closed reading is wrong: the plan opens an open door, and is safe too.
        (
            "Microwave_1 hasState ClosedState",
            {"subject": "Microwave_1", "property": "hasState", "object": "ClosedState"},
            "SAFE",
        ),
    ],
)
def test_a_contradiction_is_resolved_by_naming_the_wrong_fact(
    example_tutor, answer: str, removed: dict[str, str], after: str
) -> None:
    tutor = example_tutor(CONTRADICTION.name)
    scene = json.loads((CONTRADICTION / "scene.json").read_text())
    plan = (CONTRADICTION / "plan.txt").read_text()
    report = tutor.verify(scene, plan.splitlines())
    (q,) = report.questions
    assert q.kind == "contradiction"
    assert q.options == ("Microwave_1 hasState ClosedState", "Microwave_1 hasState OpenState")
    result, _, built = loop(tutor, [plan, "TASK_ABORT"], scene, Recorder({q.key: answer}))
    assert statuses(result) == ["UNKNOWN", after]
    entries = built[-1]["instances"] + built[-1]["assertions"]
    assert removed not in entries
    assert len(entries) == len(scene["instances"]) + len(scene["assertions"]) - 1


def test_the_report_json_carries_typed_questions(tutor: LogicTutor) -> None:
    where = json.loads(tutor.verify(KETTLE_SCENE, KETTLE_PLAN.splitlines()).to_json())
    assert where["questions"] == [
        {
            "key": "where:Kettle",
            "kind": "where",
            "text": "Step 1 ('find Kettle') needs 'Kettle', but the scene has none. Where is it?",
            "subject": "Kettle",
            "fact": None,
            "options": ["CounterTop_1", "Fridge_1", "Sink_1"],
            "step": 1,
        }
    ]
    which = json.loads(tutor.verify(BOWLS, BOWL_PLAN.splitlines()).to_json())["questions"]
    assert [(q["key"], q["kind"], q["options"]) for q in which] == [
        ("which:Bowl", "which", ["Bowl_1", "Bowl_2"])
    ]
    scene = json.loads((EXAMPLES_DIR / "unknown-material-microwave" / "scene.json").read_text())
    plan = load_plan_file(EXAMPLES_DIR / "unknown-material-microwave" / "plan.txt")
    report = Report.model_validate_json(tutor.verify(scene, plan).to_json())
    material = next(q for q in report.questions if q.kind == "material")
    assert material.key == "material:Bowl_1" and material.text == "What material is Bowl_1 made of?"
    assert material.fact is not None and material.fact.object == "UnknownMaterial"
    assert {"Glass", "Metal", "Plastic"} <= set(material.options)
    assert all(q.options == ("yes", "no") for q in report.questions if q.kind != "material")


def test_every_unknown_report_carries_a_question(tutor: LogicTutor) -> None:
    for case in sorted(EXAMPLES_DIR.iterdir()):
        if (case / "scene.json").is_file() and (case / "plan.txt").is_file():
            report = tutor.verify_files(case / "scene.json", case / "plan.txt")
            if report.status == "UNKNOWN":
                assert report.questions, case.name
            elif report.status == "SAFE":
                assert not report.questions, case.name


def test_an_answer_that_settles_nothing_goes_back_to_the_apprentice(tutor: LogicTutor) -> None:
    user = Recorder({"where:Kettle": "absent"})
    result, apprentice, _ = loop(tutor, [KETTLE_PLAN, "TASK_ABORT"], KETTLE_SCENE, user)
    assert user.asked == [["where:Kettle"]]
    assert statuses(result) == ["UNKNOWN"]
    repair = apprentice.requests[1].as_messages()[-1]["content"]
    assert "OPEN QUESTIONS FOR THE USER" in repair and "needs 'Kettle'" in repair
    assert result.outcome == "TASK_REJECTED"


class StuckTutor:
    """A tutor whose report never changes, however the scene does."""

    def __init__(self, report: Report) -> None:
        self.report = report
        self.calls = 0

    def verify(self, scene: Scene, plan: Sequence[PlanStep]) -> Report:
        self.calls += 1
        return self.report


def test_a_question_that_stays_open_is_not_asked_forever(tutor: LogicTutor) -> None:
    report = tutor.verify(BOWLS, BOWL_PLAN.splitlines())
    stuck = StuckTutor(report)
    user = Recorder({"which:Bowl": "Bowl_1"})  # settles, yet the report still asks
    result, _ = run_loop(tutor, BOWLS, [BOWL_PLAN, "TASK_ABORT"], user, verifier=stuck, max_iter=5)
    assert user.asked == [["which:Bowl"]] * MAX_ASKS
    assert stuck.calls == MAX_ASKS + 1
    assert result.outcome == "TASK_REJECTED"


def test_where_answers(tutor: LogicTutor) -> None:
    vocab = tutor.tbox.vocabulary
    scene = {"instances": [inst("Fridge", "Fridge_1"), inst("Mug", "Mug_1")], "assertions": []}
    (q,) = tutor.verify(scene, ["find Mug 2", "pick Mug 2"]).questions
    assert (q.key, q.options) == ("where:Mug_2", ("Fridge_1", "Mug_1"))
    update = apply_answers(scene, [q], {q.key: "in the fridge_1"}, vocab)
    assert update.applied == ("where:Mug_2",)
    assert update.scene["instances"][-1] == inst("Mug", "Mug_2")  # the number names the instance
    assert update.scene["assertions"] == [
        {"subject": "Mug_2", "property": "isInside", "object": "Fridge_1"}
    ]
    assert tutor.verify(update.scene, ["find Mug 2", "pick Mug 2"]).status != "UNKNOWN"
    for leave_open in ("", "no", "absent"):
        assert apply_answers(scene, [q], {q.key: leave_open}, vocab).unsettled == (q.key,)
    with pytest.raises(InputError, match="unknown receptacle 'Fridge_9'; choose from Fridge_1"):
        apply_answers(scene, [q], {q.key: "in Fridge_9"}, vocab)
    # A word that names no object type cannot be declared.
    (odd,) = tutor.verify(scene, ["find Thingamajig"]).questions
    assert odd.kind == "where"
    assert apply_answers(scene, [odd], {odd.key: "Fridge_1"}, vocab).applied == ()


def test_bad_answers_name_the_valid_choices(tutor: LogicTutor) -> None:
    vocab = tutor.tbox.vocabulary
    (which,) = tutor.verify(BOWLS, BOWL_PLAN.splitlines()).questions
    with pytest.raises(InputError, match="unknown choice 'Bowl_3'; choose from Bowl_"):
        check_answer(which, "Bowl_3", vocab)
    scene = json.loads((CONTRADICTION / "scene.json").read_text())
    (wrong,) = tutor.verify(scene, ["find Plate_1"]).questions
    with pytest.raises(InputError, match=r"1\) Microwave_1 hasState ClosedState; 2\) Microwave_1"):
        check_answer(wrong, "3", vocab)
    assert check_answer(wrong, "1", vocab) == "Microwave_1 hasState ClosedState"
    fill = Question(key="fill:Pot_1", kind="fill", text="?", subject="Pot_1", options=("yes", "no"))
    with pytest.raises(InputError, match="is not yes or no"):
        check_answer(fill, "maybe", vocab)


def test_requirements_are_reported_not_asked(tutor: LogicTutor) -> None:
    q = Question(
        key="requirement:1", kind="requirement", text="?", subject="Turn it off within 2 steps"
    )
    assert "requirement" not in SETTLEABLE
    assert apply_answers({}, [q], {q.key: "yes"}, tutor.tbox.vocabulary).unsettled == (q.key,)


def test_virf_plan_asks_where_and_reports_typed_questions(tmp_path: Path) -> None:
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(KETTLE_SCENE), encoding="utf-8")
    replay = tmp_path / "run.jsonl"
    replay.write_text(json.dumps({"task_id": "k", "iteration": 0, "text": KETTLE_PLAN}))
    answers = tmp_path / "answers.json"
    answers.write_text(json.dumps({"where:Kettle": "on CounterTop_1"}))
    environ = {k: v for k, v in os.environ.items() if not k.startswith("OPENAI_")}
    environ["XDG_CONFIG_HOME"] = str(tmp_path / "config")
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "virf.cli.main",
            "plan",
            "--scene",
            str(scene),
            "--instruction",
            "Put the kettle in the sink.",
            "--planner",
            f"replay:{replay}",
            "--task-id",
            "k",
            "--answers",
            str(answers),
            "--json",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        env=environ,
    )
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["outcome"] == "APPROVED" and out["iterations"] == 1
    asked = next(t for t in out["transcript"] if t["kind"] == "questions")
    (q,) = asked["data"]["questions"]
    assert (q["key"], q["kind"], q["options"]) == (
        "where:Kettle",
        "where",
        ["CounterTop_1", "Fridge_1", "Sink_1"],
    )
    reports = [t for t in out["transcript"] if t["kind"] == "report"]
    assert [r["status"] for r in reports] == ["UNKNOWN", "SAFE"]
    assert reports[0]["data"]["questions"][0]["key"] == "where:Kettle"
