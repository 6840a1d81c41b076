"""One plan limit everywhere: a plan the model writes is held to the limits
of a plan file, so ``virf plan`` never approves what ``virf verify`` refuses."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import Result
from loop_support import FRIDGE_SCENE, run_method_with

from virf.api import LogicTutor
from virf.errors import InputError
from virf.planner import ScriptedApprentice
from virf.planner.loop import LoopResult, refine
from virf.planner.prompting import read_after_plan_marker, read_plan
from virf.world.plan import MAX_PLAN_STEPS, parse_plan
from virf.world.scene import build_scene

# Safe on its own and safe repeated: the fridge ends closed every time.
ROUND = ["find Fridge_1", "open Fridge_1", "close Fridge_1"]
# The length of the plan issue 28 reported: 502 rounds, 1,506 actions.
LONG = ROUND * 502
# Exactly at the limit (999 actions and one more), and one over it.
AT_LIMIT = (ROUND * (MAX_PLAN_STEPS // 3 + 1))[:MAX_PLAN_STEPS]
OVER_LIMIT = (ROUND * (MAX_PLAN_STEPS // 3 + 1))[: MAX_PLAN_STEPS + 1]


def limit_message() -> str:
    """What ``virf verify`` says of a plan over the limit."""
    with pytest.raises(InputError) as refused:
        parse_plan(OVER_LIMIT)
    return str(refused.value)


def test_the_reader_refuses_a_reply_over_the_limit_with_the_files_message() -> None:
    message = limit_message()
    assert message == f"plan has more than {MAX_PLAN_STEPS} actions (the limit)"
    for reply in ("\n".join(OVER_LIMIT), json.dumps(LONG), "PLAN:\n" + "\n".join(LONG)):
        got = read_after_plan_marker(reply)
        assert (got.steps, got.unreadable, got.refused) == ((), (), False)
        assert got.problem == message
    # At the limit, the reply is a plan, as a file of the same lines is.
    assert len(read_plan("\n".join(AT_LIMIT)).steps) == MAX_PLAN_STEPS == len(parse_plan(AT_LIMIT))


def test_the_loop_never_approves_a_plan_over_the_limit(tutor: LogicTutor) -> None:
    vocab = tutor.tbox.vocabulary

    def loop(replies: list[str], max_iter: int) -> tuple[LoopResult, ScriptedApprentice]:
        apprentice = ScriptedApprentice(replies)
        result = refine(
            "Open and close the fridge until told to stop.",
            FRIDGE_SCENE,
            apprentice,
            tutor.verifier,
            lambda d: build_scene(d, vocab),
            vocab,
            max_iter=max_iter,
        )
        return result, apprentice

    result, _ = loop(["\n".join(LONG)], 1)
    assert (result.outcome, result.plan) == ("TASK_REJECTED", None)
    (turn,) = [t for t in result.transcript if t.speaker == "apprentice"]
    assert (turn.kind, turn.text) == ("unreadable", limit_message())
    assert turn.data is not None and turn.data["reply"] == "\n".join(LONG)
    assert not any(t.kind == "report" for t in result.transcript)
    # The apprentice is told why, in the limit's words, and may try again.
    result, apprentice = loop(["\n".join(LONG), "\n".join(ROUND)], 2)
    assert (result.outcome, result.plan) == ("APPROVED", tuple(ROUND))
    assert limit_message() in apprentice.requests[1].as_messages()[-1]["content"]


@pytest.mark.parametrize("method", ["impulsive", "thinker", "committee", "thinker+diagnostic"])
def test_no_method_passes_on_a_plan_over_the_limit(tutor: LogicTutor, method: str) -> None:
    reply = "PLAN:\n" + "\n".join(LONG)
    result, _ = run_method_with(tutor, method, [reply, reply], critic=["APPROVE"])
    assert (result.outcome, result.plan) == ("TASK_REJECTED", None)
    assert limit_message() in result.reason


def test_virf_plan_rejects_what_virf_verify_refuses(
    cli: Callable[..., Result], tmp_path: Path
) -> None:
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(FRIDGE_SCENE), encoding="utf-8")
    plan = tmp_path / "plan.txt"
    plan.write_text("\n".join(LONG) + "\n", encoding="utf-8")
    refused = cli("verify", scene, plan, "--json")
    assert refused.exit_code == 2
    assert json.loads(refused.stdout)["error"] == limit_message()

    replay = tmp_path / "replay.jsonl"
    replay.write_text(
        json.dumps({"task_id": "long", "iteration": 0, "text": "PLAN:\n" + "\n".join(LONG)}) + "\n",
        encoding="utf-8",
    )
    for method in ("virf", "impulsive"):
        planned = cli(
            "plan",
            "--scene",
            scene,
            "--instruction",
            "Open and close the fridge.",
            "--planner",
            f"replay:{replay}",
            "--task-id",
            "long",
            "--method",
            method,
            "--max-iter",
            "1",
            "--json",
        )
        assert planned.exit_code == 1, planned.output
        out = json.loads(planned.stdout)
        assert out["outcome"] == "TASK_REJECTED" and out["plan"] is None
        assert limit_message() in json.dumps(out["transcript"]) + out["reason"]
