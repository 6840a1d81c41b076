"""Constrained plans from a served model: structured output through
``response_format``, against the scripted chat server on 127.0.0.1 (the real
``openai`` SDK, nothing inside the client replaced), and the fallback to
plain text when the server refuses the option."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import pytest
from chat_support import ChatServer, completion, error

from virf.errors import EnvironmentProblem
from virf.planner import (
    ClientSettings,
    OpenAIApprentice,
    Proposal,
    Purpose,
    ReplayApprentice,
    RunLog,
    export_replay,
    make_apprentice,
)
from virf.planner.clients import plan_text
from virf.planner.constraint import PlanConstraint
from virf.planner.prompting import REFUSAL

MESSAGES = [
    {"role": "system", "content": "You plan actions for a household robot."},
    {"role": "user", "content": "Heat the pot."},
]
CONSTRAINT = PlanConstraint(
    (("find", ("Pot_1", "StoveKnob_1")), ("pick", ("Pot_1",)), ("turn_on", ("StoveKnob_1",)))
)
STEPS = ["find Pot_1", "pick Pot_1"]


def served(server: ChatServer, run_log: RunLog | None = None, **settings: Any) -> OpenAIApprentice:
    opts: dict[str, Any] = {"max_retries": 0, "timeout_s": 5.0} | settings
    return OpenAIApprentice(
        ClientSettings(model="test-model", base_url=server.base_url, **opts),
        run_log=run_log,
        environ={"OPENAI_API_KEY": "sk-test-key-123"},
    )


def ask(
    app: Any, iteration: int = 0, purpose: Purpose = Purpose.PLAN, task_id: str = "t1"
) -> Proposal:
    result: Proposal = app.propose(
        MESSAGES,
        task_id=task_id,
        iteration=iteration,
        method="virf",
        purpose=purpose,
        constraint=CONSTRAINT,
    )
    return result


def test_a_constrained_request_sends_the_valid_lines_as_a_schema(
    server: ChatServer, tmp_path: Path
) -> None:
    server.queue(completion(json.dumps({"steps": STEPS})))
    with RunLog(tmp_path / "log.db", run_id="run-1") as log:
        with served(server, log, constrain=True) as app:
            assert app.constrained
            got = ask(app)
        # The reply is plan text, for the reader and for the log alike.
        assert got.ok and got.text == "find Pot_1\npick Pot_1"
        (call,) = log.calls()
        assert call.reply == got.text and call.reason == ""
        assert export_replay(log, "run-1", tmp_path / "replay.jsonl") == 1
    replayed = ask(ReplayApprentice(tmp_path / "replay.jsonl"))
    assert replayed.text == got.text
    (seen,) = server.seen
    fmt = seen.body["response_format"]
    assert fmt["type"] == "json_schema"
    assert fmt["json_schema"]["name"] == "plan" and fmt["json_schema"]["strict"] is True
    assert fmt["json_schema"]["schema"] == CONSTRAINT.json_schema()
    enum = fmt["json_schema"]["schema"]["properties"]["steps"]["items"]["enum"]
    assert enum == [*CONSTRAINT.lines(), REFUSAL]
    # The sampling settings still go along.
    assert seen.body["temperature"] == 0.0


def test_served_models_are_not_constrained_unless_asked(server: ChatServer) -> None:
    server.queue(completion("find Pot_1"), completion("APPROVE"), completion("find Pot_1"))
    with served(server) as app:
        assert not app.constrained
        ask(app)
    with served(server, constrain=True) as app:
        # A critique is no plan: it is never held to the plan's lines.
        ask(app, purpose=Purpose.CRITIQUE)
        # A request without a constraint (no scene) is asked as before.
        app.propose(MESSAGES, task_id="t", iteration=0, method="virf", purpose=Purpose.PLAN)
    assert all("response_format" not in s.body for s in server.seen)


def test_a_server_that_refuses_structured_output_gets_plain_text_for_the_rest_of_the_run(
    server: ChatServer, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    server.queue(
        error(400, "Unknown parameter: 'response_format'."),
        completion("find Pot_1\nturn_on StoveKnob_1"),
        completion("find Pot_1"),
    )
    with RunLog(tmp_path / "log.db", run_id="run-1") as log:
        with served(server, log, constrain=True) as app, caplog.at_level(logging.WARNING):
            first = ask(app)
            second = ask(app, iteration=1, purpose=Purpose.REPAIR)
        assert first.ok and first.text == "find Pot_1\nturn_on StoveKnob_1"
        assert first.attempts == 2  # the refused request and the plain one
        assert second.ok and second.text == "find Pot_1" and second.attempts == 1
        # Said once, on the warning channel and in the call that fell back.
        (warned,) = [r.getMessage() for r in caplog.records]
        assert "refused structured output (HTTP 400" in warned and "plain text" in warned
        assert app.plain_text_reason == warned
        calls = log.calls()
        assert [(c.iteration, c.ask, c.ok) for c in calls] == [(0, 1, True), (1, 1, True)]
        assert calls[0].reason == warned and calls[1].reason == ""
        # Still one proposal per ask: the run exports as a replay.
        assert export_replay(log, "run-1", tmp_path / "replay.jsonl") == 2
    sent = [("response_format" in s.body) for s in server.seen]
    assert sent == [True, False, False]


def test_a_too_long_prompt_is_not_mistaken_for_a_refused_option(server: ChatServer) -> None:
    server.queue(error(400, "This model's maximum context length is 8192 tokens."))
    with served(server, constrain=True) as app:
        got = ask(app)
        assert not got.ok and "too long" in got.reason
        assert app.plain_text_reason is None
    assert len(server.seen) == 1


def test_structured_replies_become_plan_text() -> None:
    assert plan_text('{"steps": ["find Pot_1", "pick Pot_1"]}') == "find Pot_1\npick Pot_1"
    assert plan_text(json.dumps({"steps": [REFUSAL]})) == REFUSAL
    # Anything else is left for the reader to judge, word for word.
    for other in ("find Pot_1", '{"steps": []}', '{"steps": [1]}', "[1, 2]", '{"plan": "x"}'):
        assert plan_text(other) == other


def test_the_setting_reaches_both_kinds_of_model_planner() -> None:
    with make_apprentice(
        "openai:test-model", base_url="http://127.0.0.1:9/v1", constrain=True
    ) as app:
        assert app.constrained
    # Recordings answer as they were recorded: the setting changes nothing.
    assert not make_apprentice("scripted", constrain=True).constrained


def test_a_server_error_that_names_the_option_falls_back_too(server: ChatServer) -> None:
    # llama.cpp's server validates response_format and answers HTTP 500.
    server.queue(
        error(
            500,
            "1 validation error: ('body', 'response_format', 'type') Input should be "
            "'text' or 'json_object'",
        ),
        completion("find Pot_1"),
    )
    with served(server, constrain=True) as app:
        got = ask(app)
    assert got.ok and got.text == "find Pot_1"
    assert app.plain_text_reason and "HTTP 500" in app.plain_text_reason
    assert [("response_format" in s.body) for s in server.seen] == [True, False]


def test_other_server_errors_still_stop_the_run(server: ChatServer) -> None:
    server.queue(error(500, "out of memory", {"x-should-retry": "false"}))
    with served(server, constrain=True) as app, pytest.raises(EnvironmentProblem):
        ask(app)
    assert app.plain_text_reason is None
