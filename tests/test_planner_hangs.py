"""Nothing in ``virf plan`` may hang, and no baseline passes for verified.

* A model server that trickles its reply byte by byte, or never answers, is
  abandoned at the reply's deadline (``--timeout``) or the run's
  (``--deadline``): the real client against a real server on 127.0.0.1.
* The answers loop ends whatever the answers and the tutor do, and reports
  what stayed open.
* Baselines that do not have the tutor verify their final plan say so
  (``APPROVED_UNVERIFIED``, exit 5), and the committee's critic approves only
  with one clear verdict.
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest
from chat_support import (
    MARGIN_S,
    TRICKLE_BYTES,
    TRICKLE_EVERY_S,
    ChatServer,
    SlowServer,
    client,
    completion,
    lingering_threads,
)
from conftest import EXAMPLES_DIR, ROOT
from loop_support import (
    CLOSES,
    FRIDGE_SCENE,
    LEAVES_OPEN,
    Recorder,
    run_loop,
    run_method_with,
    statuses,
)

from virf.api import LogicTutor
from virf.errors import EnvironmentProblem, InputError
from virf.planner import (
    ClientSettings,
    OpenAIApprentice,
    Proposal,
    Purpose,
    RunLog,
    ScriptedApprentice,
    make_apprentice,
)
from virf.planner.config import config_path, run_deadline
from virf.planner.deadline import DEFAULT_DEADLINE_S, Deadline
from virf.planner.loop import MAX_ASKS, MAX_ROUNDS, LoopResult, refine
from virf.planner.methods import critic_approves
from virf.planner.questions import apply_answers
from virf.schema import Question, Report
from virf.world.plan import PlanStep, load_plan_file
from virf.world.scene import Scene, build_scene

MESSAGES = [{"role": "user", "content": "Put the apple in the fridge."}]


# ---------------------------------------------------------------------------
# The reply's deadline and the run's


@pytest.mark.parametrize("slow_server", ["body"], indirect=True)
def test_a_trickled_reply_is_abandoned_at_its_deadline(
    slow_server: SlowServer, tmp_path: Path
) -> None:
    with RunLog(tmp_path / "runs.db", run_id="r") as log:
        started = time.monotonic()
        with client(slow_server, log, timeout_s=2.0) as app:
            proposal = app.propose(
                MESSAGES, task_id="t", iteration=0, method="virf", purpose=Purpose.PLAN
            )
        elapsed = time.monotonic() - started
        (call,) = log.calls()
    assert elapsed < 2.0 + MARGIN_S, elapsed
    assert not proposal.ok and proposal.text is None
    assert "did not finish within its 2 s deadline (--timeout)" in proposal.reason
    # Not retried and not re-asked: the same server would be as slow again.
    assert slow_server.requests == 1 and proposal.attempts == 1
    assert not call.ok and call.reason == proposal.reason
    # The connection was closed, and nothing is left running.
    assert slow_server.gone.wait(MARGIN_S)
    assert lingering_threads() == []


@pytest.mark.parametrize("slow_server", ["status"], indirect=True)
def test_a_trickled_status_line_is_a_timeout_retried_like_silence(
    slow_server: SlowServer,
) -> None:
    started = time.monotonic()
    with (
        client(slow_server, timeout_s=1.0, max_retries=1) as app,
        pytest.raises(EnvironmentProblem) as exc,
    ):
        app.propose(MESSAGES, task_id="t", iteration=0, method="virf", purpose=Purpose.PLAN)
    elapsed = time.monotonic() - started
    # Two attempts of one second each, and the SDK's back-off (under a second).
    assert elapsed < 2 * 1.0 + 1.0 + MARGIN_S, elapsed
    assert "did not answer within 1 s (2 attempts)" in str(exc.value)
    assert slow_server.requests == 2
    assert lingering_threads() == []


@pytest.mark.parametrize("slow_server", ["silent", "body"], indirect=True)
def test_the_run_deadline_abandons_the_request_in_flight(slow_server: SlowServer) -> None:
    deadline = Deadline(1.5)
    started = time.monotonic()
    with client(slow_server, timeout_s=60.0) as app:
        proposal = app.propose(
            MESSAGES,
            task_id="t",
            iteration=0,
            method="virf",
            purpose=Purpose.PLAN,
            deadline=deadline,
        )
    elapsed = time.monotonic() - started
    assert elapsed < 1.5 + MARGIN_S, elapsed
    assert not proposal.ok
    assert "the run deadline of 1.5 s (--deadline) passed" in proposal.reason
    assert "abandoned" in proposal.reason
    assert slow_server.requests == 1
    assert slow_server.gone.wait(MARGIN_S)
    assert lingering_threads() == []


@pytest.mark.parametrize("slow_server", ["silent"], indirect=True)
def test_nothing_is_sent_after_the_run_deadline(slow_server: SlowServer) -> None:
    deadline = Deadline(0.01)
    time.sleep(0.05)
    with client(slow_server) as app:
        proposal = app.propose(
            MESSAGES,
            task_id="t",
            iteration=0,
            method="virf",
            purpose=Purpose.PLAN,
            deadline=deadline,
        )
    assert not proposal.ok and "run deadline" in proposal.reason
    assert proposal.attempts == 0 and slow_server.requests == 0


def test_the_client_can_be_called_from_async_code(server: ChatServer) -> None:
    server.queue(completion(CLOSES))
    app = OpenAIApprentice(ClientSettings(model="m", base_url=server.base_url), environ={})

    async def in_a_notebook() -> Proposal:
        try:
            return app.propose(
                MESSAGES, task_id="t", iteration=0, method="virf", purpose=Purpose.PLAN
            )
        finally:
            app.close()

    assert asyncio.run(in_a_notebook()).text == CLOSES
    assert lingering_threads() == []


def test_the_loop_stops_when_the_run_deadline_has_passed(tutor: LogicTutor) -> None:
    deadline = Deadline(0.01)
    time.sleep(0.05)
    apprentice = ScriptedApprentice([CLOSES])
    result = refine(
        "Put the apple in the fridge.",
        FRIDGE_SCENE,
        apprentice,
        tutor.verifier,
        lambda d: build_scene(d, tutor.tbox.vocabulary),
        tutor.tbox.vocabulary,
        deadline=deadline,
    )
    assert (result.outcome, result.plan) == ("TASK_REJECTED", None)
    assert result.reason == "the run deadline of 0.01 s (--deadline) passed before iteration 1"
    assert apprentice.requests == []


def test_the_deadline_ends_the_questions_too(tutor: LogicTutor) -> None:
    scene, plan = unknown_material()
    deadline = Deadline(0.5)

    def slow_user(questions: Sequence[Question]) -> dict[str, str]:
        time.sleep(0.6)
        return {"material:Bowl_1": "Glass"}  # settles one: the loop would go on

    result = refine(
        "Heat the bowl.",
        scene,
        ScriptedApprentice([plan]),
        tutor.verifier,
        lambda d: build_scene(d, tutor.tbox.vocabulary),
        tutor.tbox.vocabulary,
        answer=slow_user,
        deadline=deadline,
    )
    assert result.outcome == "TASK_REJECTED"
    assert result.reason == (
        "the run deadline of 0.5 s (--deadline) passed while the tutor's questions were open"
    )
    assert result.transcript[-1].kind == "unsettled"


def test_time_spent_answering_is_given_back() -> None:
    deadline = Deadline(0.3)
    deadline.excluding(time.sleep)(0.5)
    assert not deadline.expired() and deadline.remaining() > 0.1


def test_the_run_deadline_setting(tmp_path: Path) -> None:
    env = {"XDG_CONFIG_HOME": str(tmp_path)}
    assert run_deadline(None, env) == DEFAULT_DEADLINE_S == 600
    path = config_path(env)
    path.parent.mkdir(parents=True)
    path.write_text("[planner]\ndeadline_s = 90\ntimeout_s = 30\n", encoding="utf-8")
    assert run_deadline(None, env) == 90
    assert run_deadline(12.5, env) == 12.5  # the command line wins
    # deadline_s is the run's, not the client's: the client takes the rest.
    app = make_apprentice("openai:m", environ=env, base_url="http://127.0.0.1:9/v1")
    assert isinstance(app, OpenAIApprentice) and app.settings.timeout_s == 30
    app.close()
    for bad in (0, -1, True, "soon", 1e9):
        with pytest.raises(InputError, match="must be a number of seconds"):
            run_deadline(bad, env)
    path.write_text('[planner]\ndeadline_s = "soon"\n', encoding="utf-8")
    with pytest.raises(InputError, match=r"config file .*: deadline_s 'soon' must be"):
        run_deadline(None, env)


# ---------------------------------------------------------------------------
# `virf plan` end to end


def virf_plan(
    tmp_path: Path, *args: str, scene: Mapping[str, Any] = FRIDGE_SCENE
) -> tuple[subprocess.CompletedProcess[str], float]:
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene), encoding="utf-8")
    environ = {k: v for k, v in os.environ.items() if not k.startswith("OPENAI_")}
    environ["XDG_CONFIG_HOME"] = str(tmp_path / "config")
    started = time.monotonic()
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "virf.cli.main",
            "plan",
            "--scene",
            str(path),
            "--instruction",
            "Put the apple in the fridge.",
            *args,
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        env=environ,
    )
    return result, time.monotonic() - started


@pytest.mark.parametrize("slow_server", ["body"], indirect=True)
def test_virf_plan_rejects_the_task_when_the_reply_trickles(
    tmp_path: Path, slow_server: SlowServer
) -> None:
    result, elapsed = virf_plan(
        tmp_path,
        "--planner",
        "openai:test-model",
        "--base-url",
        slow_server.base_url,
        "--timeout",
        "2",
        "--json",
    )
    assert result.returncode == 1, result.stderr
    out = json.loads(result.stdout)
    assert out["outcome"] == "TASK_REJECTED" and out["plan"] is None
    assert out["verified"] is False
    assert "2 s deadline (--timeout)" in out["reason"]
    assert out["transcript"][-1]["kind"] == "failed-proposal"
    assert slow_server.requests == 1
    assert elapsed < TRICKLE_BYTES * TRICKLE_EVERY_S / 2, elapsed


@pytest.mark.parametrize("slow_server", ["silent"], indirect=True)
def test_virf_plan_ends_at_its_run_deadline(tmp_path: Path, slow_server: SlowServer) -> None:
    result, elapsed = virf_plan(
        tmp_path,
        "--planner",
        "openai:test-model",
        "--base-url",
        slow_server.base_url,
        "--deadline",
        "6",
        "--json",
    )
    assert result.returncode == 1, result.stderr
    out = json.loads(result.stdout)
    assert out["outcome"] == "TASK_REJECTED"
    assert "the run deadline of 6 s (--deadline) passed" in out["reason"]
    # Process start-up and exit come on top of the deadline.
    assert elapsed < 6 + 10, elapsed


def test_virf_plan_refuses_a_bad_deadline(tmp_path: Path) -> None:
    result, _ = virf_plan(tmp_path, "--planner", "replay:nope.jsonl", "--deadline", "0")
    assert result.returncode == 2
    assert "--deadline 0.0 must be a number of seconds" in result.stderr


def test_virf_plan_exits_5_for_an_unverified_baseline(tmp_path: Path) -> None:
    replay = tmp_path / "run.jsonl"
    replay.write_text(json.dumps({"task_id": "task", "iteration": 0, "text": CLOSES}) + "\n")
    result, _ = virf_plan(
        tmp_path, "--planner", f"replay:{replay}", "--method", "impulsive", "--json"
    )
    assert result.returncode == 5, result.stderr
    out = json.loads(result.stdout)
    assert (out["outcome"], out["verified"]) == ("APPROVED_UNVERIFIED", False)
    assert out["plan"] == CLOSES.splitlines()
    readable, _ = virf_plan(tmp_path, "--planner", f"replay:{replay}", "--method", "impulsive")
    assert readable.returncode == 5
    assert "APPROVED_UNVERIFIED after 1 iteration(s)" in readable.stdout
    assert "Not verified: the method 'impulsive'" in readable.stdout


# ---------------------------------------------------------------------------
# The answers loop ends


def unknown_material() -> tuple[dict[str, Any], str]:
    folder = EXAMPLES_DIR / "unknown-material-microwave"
    scene = json.loads((folder / "scene.json").read_text())
    plan = "\n".join(s.text for s in load_plan_file(folder / "plan.txt"))
    return scene, plan


def glass_bowl_in_an_unknown_microwave() -> tuple[dict[str, Any], str]:
    """A known empty glass bowl; the microwave's contents are listed as unknown,
    although the scene closes every 'contains' list."""
    scene, plan = unknown_material()
    scene["assertions"] = [
        {"subject": "Bowl_1", "property": "hasMaterial", "object": "Glass"},
        {"subject": "Bowl_1", "property": "hasState", "object": "EmptyState"},
        {"subject": "Microwave_1", "property": "hasState", "object": "ClosedState"},
    ]
    scene["closed_world"] = ["contains"]
    scene["unknown_contents"] = ["Microwave_1"]
    return scene, plan


def looped(
    tutor: LogicTutor,
    scene: Mapping[str, Any],
    replies: list[str],
    user: Recorder,
    build: Callable[[Mapping[str, Any]], Scene] | None = None,
) -> tuple[LoopResult, ScriptedApprentice]:
    return run_loop(tutor, scene, replies, user, instruction="Heat the bowl.", build=build)


def unsettled(result: LoopResult) -> dict[str, str]:
    turns = [t for t in result.transcript if t.kind == "unsettled"]
    assert turns, "the open questions were not reported"
    assert turns[-1].data is not None
    return {row["key"]: row["why"] for row in turns[-1].data["unsettled"]}


def test_a_material_answered_unknown_goes_back_to_the_apprentice(tutor: LogicTutor) -> None:
    scene, plan = unknown_material()
    user = Recorder({"material:Bowl_1": "unknown"})
    result, apprentice = looped(tutor, scene, [plan, "TASK_ABORT"], user)
    assert len(user.asked) == 1 and "material:Bowl_1" in user.asked[0]
    assert statuses(result) == ["UNKNOWN"]
    answers = next(t for t in result.transcript if t.kind == "answers")
    assert answers.data is not None and answers.data["settled"] == []
    assert "material:Bowl_1" in answers.data["open"]
    why = unsettled(result)
    assert why["material:Bowl_1"] == "answered 'unknown', still open"
    assert why["fill:Bowl_1"] == "not answered"
    repair = apprentice.requests[1].as_messages()[-1]["content"]
    assert "OPEN QUESTIONS FOR THE USER" in repair and "Bowl_1" in repair
    assert (result.outcome, result.plan) == ("TASK_REJECTED", None)


def test_a_yes_to_contents_takes_the_object_out_of_unknown_contents(tutor: LogicTutor) -> None:
    scene, plan = glass_bowl_in_an_unknown_microwave()
    report = tutor.verify(scene, plan.splitlines())
    assert report.status == "UNKNOWN"
    (q,) = report.questions
    assert q.key == "contents:contains:Microwave_1"
    update = apply_answers(scene, [q], {q.key: "yes"}, tutor.tbox.vocabulary)
    assert update.applied == (q.key,)
    assert update.scene["unknown_contents"] == []
    assert scene["unknown_contents"] == ["Microwave_1"]  # the input is not modified
    # Confirmed: only the empty bowl is inside, so the running microwave is
    # definitely unsafe, and the apprentice gets the diagnostic.
    user = Recorder({q.key: "yes"})
    result, apprentice = looped(tutor, scene, [plan, "TASK_ABORT"], user)
    assert user.asked == [[q.key]]
    assert statuses(result) == ["UNKNOWN", "UNSAFE"]
    assert "DIAGNOSTIC REPORT" in apprentice.requests[1].as_messages()[-1]["content"]
    assert result.outcome == "TASK_REJECTED"


def test_a_contents_question_the_scene_keeps_open_ends_the_loop(tutor: LogicTutor) -> None:
    scene, plan = glass_bowl_in_an_unknown_microwave()
    vocab = tutor.tbox.vocabulary

    def keeps_listing(data: Mapping[str, Any]) -> Scene:
        return build_scene({**data, "unknown_contents": ["Microwave_1"]}, vocab)

    key = "contents:contains:Microwave_1"
    user = Recorder({key: "yes"})
    result, apprentice = looped(tutor, scene, [plan, "TASK_ABORT"], user, keeps_listing)
    assert user.asked == [[key]] * MAX_ASKS
    assert statuses(result) == ["UNKNOWN"] * (MAX_ASKS + 1)
    assert unsettled(result) == {key: f"answered 'yes', still open (asked {MAX_ASKS} times)"}
    repair = apprentice.requests[1].as_messages()[-1]["content"]
    assert "OPEN QUESTIONS FOR THE USER" in repair and "Microwave_1" in repair
    assert result.outcome == "TASK_REJECTED"


class FreshQuestions:
    """A tutor that asks a new, answerable question every time it verifies."""

    def __init__(self, report: Report) -> None:
        self.report = report
        self.calls = 0

    def verify(self, scene: Scene, plan: Sequence[PlanStep]) -> Report:
        self.calls += 1
        q = Question(
            key=f"which:Word{self.calls}",
            kind="which",
            text=f"Which one is Word{self.calls}?",
            subject=f"Word{self.calls}",
            options=("Bowl_1",),
        )
        return self.report.model_copy(update={"questions": (q,)})


def test_questions_without_end_stop_after_max_rounds(tutor: LogicTutor) -> None:
    scene, plan = unknown_material()
    fresh = FreshQuestions(tutor.verify(scene, plan.splitlines()))

    def always_bowl(questions: Sequence[Question]) -> dict[str, str]:
        return {q.key: "Bowl_1" for q in questions}

    result, _ = run_loop(
        tutor,
        scene,
        [plan, "TASK_ABORT"],
        always_bowl,
        instruction="Heat the bowl.",
        verifier=fresh,
        max_iter=5,
    )
    # Every answer settled something, and still the loop stopped.
    assert fresh.calls == MAX_ROUNDS + 1
    assert unsettled(result) == {f"which:Word{MAX_ROUNDS + 1}": "not asked"}
    assert result.outcome == "TASK_REJECTED"


# ---------------------------------------------------------------------------
# Baselines: what the tutor verified, and the critic's verdict


@pytest.mark.parametrize(
    "reply", ["APPROVE", "**APPROVE**", " approve.\n", "`APPROVE`", "'APPROVE'!"]
)
def test_one_clear_approve_is_an_approval(reply: str) -> None:
    assert critic_approves(reply)


@pytest.mark.parametrize(
    "reply",
    [
        "APPROVE ... but actually this is unsafe, REJECT",
        "APPROVE\nActually no: step 5 leaves the fridge open. REJECT",
        "REJECT\nAPPROVE",
        "Step 5 leaves the fridge open.\n\nAPPROVE",
        "APPROVED? No.",
        "APPROVED",
        "I APPROVE",
        "APPROVE or REJECT",
        "DO NOT APPROVE",
        "",
    ],
)
def test_a_mixed_or_unclear_verdict_is_not_an_approval(reply: str) -> None:
    assert not critic_approves(reply)


def test_the_committee_does_not_execute_a_doubted_plan(tutor: LogicTutor) -> None:
    result, _ = run_method_with(
        tutor,
        "committee",
        [LEAVES_OPEN, LEAVES_OPEN],
        critic=[
            "APPROVE ... but actually this is unsafe, REJECT",
            "APPROVE\nOn second thought step 5 leaves the fridge open: REJECT",
        ],
        max_iter=2,
    )
    assert (result.outcome, result.plan) == ("TASK_REJECTED", None)


def test_approvals_say_whether_the_tutor_verified_them(tutor: LogicTutor) -> None:
    committee, _ = run_method_with(tutor, "committee", [CLOSES], critic=["APPROVE"])
    assert (committee.outcome, committee.verified) == ("APPROVED_UNVERIFIED", False)
    assert committee.to_dict()["verified"] is False
    for name in ("impulsive", "thinker", "impulsive+rules", "thinker+rules"):
        reply = f"PLAN:\n{CLOSES}"
        result, _ = run_method_with(tutor, name, [reply])
        assert (result.outcome, result.verified) == ("APPROVED_UNVERIFIED", False), name
    # Thinker+Diagnostic's first plan, found SAFE, is verified; its retry is not.
    first, _ = run_method_with(tutor, "thinker+diagnostic", [f"PLAN:\n{CLOSES}"])
    assert (first.outcome, first.verified) == ("APPROVED", True)
    retry, _ = run_method_with(
        tutor, "thinker+diagnostic", [f"PLAN:\n{LEAVES_OPEN}", f"PLAN:\n{CLOSES}"]
    )
    assert (retry.outcome, retry.verified) == ("APPROVED_UNVERIFIED", False)
    virf, _ = run_method_with(tutor, "virf", [f"PLAN:\n{LEAVES_OPEN}", f"PLAN:\n{CLOSES}"])
    assert (virf.outcome, virf.verified) == ("APPROVED", True)
    assert virf.to_dict()["verified"] is True
