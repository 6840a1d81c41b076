"""The apprentice clients, driven end to end.

``OpenAIApprentice`` runs the real ``openai`` SDK against a real HTTP server
started here on 127.0.0.1, which answers POST /v1/chat/completions from a
script.  Nothing inside the client is replaced.
"""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

import pytest
from chat_support import FAST_RETRY, ChatServer, Reply, completion, error

from virf.errors import EnvironmentProblem, InputError
from virf.planner import (
    ClientSettings,
    OpenAIApprentice,
    Proposal,
    Purpose,
    ReplayApprentice,
    RunLog,
    ScriptedApprentice,
    export_replay,
    make_apprentice,
)
from virf.planner.chat import LOCAL_PLACEHOLDER_KEY

MESSAGES = [
    {"role": "system", "content": "You are a household robot planner."},
    {"role": "user", "content": "Heat the pot of water."},
]
PLAN = "find Pot\npick Pot\nput StoveBurner\nturn_on StoveKnob"


def apprentice(
    server: ChatServer, run_log: RunLog | None = None, **settings: Any
) -> OpenAIApprentice:
    opts: dict[str, Any] = {"max_retries": 2, "timeout_s": 5.0} | settings
    return OpenAIApprentice(
        ClientSettings(model="test-model", base_url=server.base_url, **opts),
        run_log=run_log,
        environ={"OPENAI_API_KEY": "sk-test-key-123"},
    )


def propose(app: Any, task_id: str = "t1", iteration: int = 1, method: str = "virf") -> Proposal:
    result: Proposal = app.propose(
        MESSAGES, task_id=task_id, iteration=iteration, method=method, purpose=Purpose.PLAN
    )
    return result


def one_line(exc: pytest.ExceptionInfo[Exception]) -> str:
    text = str(exc.value)
    assert "\n" not in text and text
    # The SDK's chained traceback is suppressed: the CLI shows this line only.
    assert exc.value.__suppress_context__ and exc.value.__cause__ is None
    return text


# ---------------------------------------------------------------------------
# OpenAIApprentice over HTTP


def test_normal_reply_sends_settings_and_reports_usage(server: ChatServer) -> None:
    server.queue(completion(PLAN, prompt_tokens=42, completion_tokens=9))
    with apprentice(server, seed=7, top_p=0.5) as app:
        result = propose(app)
    assert result == Proposal(
        text=PLAN,
        ok=True,
        reason="",
        prompt_tokens=42,
        completion_tokens=9,
        latency_ms=result.latency_ms,
        attempts=1,
    )
    assert result.latency_ms > 0
    (seen,) = server.seen
    assert seen.path == "/v1/chat/completions"
    assert seen.authorization == "Bearer sk-test-key-123"
    assert seen.body["model"] == "test-model"
    assert seen.body["messages"] == MESSAGES
    assert seen.body["temperature"] == 0.0
    assert seen.body["top_p"] == 0.5
    assert seen.body["max_tokens"] == 2048
    assert seen.body["seed"] == 7


def test_unset_options_are_left_out(server: ChatServer) -> None:
    server.queue(completion(PLAN))
    with apprentice(
        server, temperature=None, max_tokens=512, max_tokens_field="max_completion_tokens"
    ) as app:
        assert propose(app).ok
    body = server.seen[0].body
    assert "seed" not in body and "top_p" not in body and "temperature" not in body
    assert body["max_completion_tokens"] == 512 and "max_tokens" not in body


@pytest.mark.parametrize("status", [429, 500, 503])
def test_rate_limit_or_server_error_then_success(server: ChatServer, status: int) -> None:
    server.queue(error(status, "try again", FAST_RETRY), completion(PLAN))
    with apprentice(server) as app:
        result = propose(app)
    assert result.ok and result.text == PLAN
    assert result.attempts == 2
    assert len(server.seen) == 2


def test_timeout_then_success(server: ChatServer) -> None:
    slow = completion("too late")
    slow.delay_s = 1.0
    server.queue(slow, completion(PLAN))
    with apprentice(server, timeout_s=0.25) as app:
        result = propose(app)
    assert result.ok and result.text == PLAN and result.attempts == 2


def test_empty_reply_is_reasked_once(server: ChatServer) -> None:
    server.queue(completion("  \n", 10, 1), completion(PLAN, 10, 5))
    with apprentice(server) as app:
        result = propose(app)
    assert result.ok and result.text == PLAN
    assert (result.prompt_tokens, result.completion_tokens, result.attempts) == (20, 6, 2)
    assert [s.body["messages"] for s in server.seen] == [MESSAGES, MESSAGES]


def test_two_empty_replies_make_a_failed_proposal(server: ChatServer) -> None:
    server.queue(completion(""), completion(None))
    with apprentice(server) as app:
        result = propose(app)
    assert not result.ok and result.text is None
    assert result.reason == (
        "no usable reply after 2 asks: the reply was empty; the reply had no text content"
    )
    assert result.attempts == 2 and len(server.seen) == 2


@pytest.mark.parametrize(
    ("first", "second", "reason"),
    [
        (Reply(body="<html>bad gateway</html>"), Reply(body="{"), "the reply was not JSON"),
        (Reply(body={"id": "x"}), Reply(body={"choices": []}), "the reply had no choices"),
        (Reply(body=[1, 2]), Reply(body=[1]), "the reply was not a JSON object"),
    ],
)
def test_malformed_replies_are_failed_proposals(
    server: ChatServer, first: Reply, second: Reply, reason: str
) -> None:
    server.queue(first, second)
    with apprentice(server) as app:
        result = propose(app)
    assert not result.ok and result.text is None
    assert reason in result.reason


def test_malformed_then_good_reply(server: ChatServer) -> None:
    server.queue(Reply(body={"choices": [{"message": "oops"}]}), completion(PLAN))
    with apprentice(server) as app:
        result = propose(app)
    assert result.ok and result.text == PLAN and result.attempts == 2


def test_api_refusal_is_not_a_plan(server: ChatServer) -> None:
    refusal = completion(None)
    refusal.body["choices"][0]["message"]["refusal"] = "I can't help with that."
    server.queue(refusal, refusal)
    with apprentice(server) as app:
        result = propose(app)
    assert not result.ok
    assert "the model refused: I can't help with that." in result.reason


def test_context_overflow_fails_the_proposal_without_reasking(server: ChatServer) -> None:
    server.queue(error(400, "This model's maximum context length is 8192 tokens."))
    with apprentice(server) as app:
        result = propose(app)
    assert not result.ok and result.text is None
    assert result.reason.startswith("no usable reply after 1 ask: the prompt is too long")
    assert len(server.seen) == 1


def test_rejected_key_is_one_line(server: ChatServer) -> None:
    server.queue(error(401, "Incorrect API key provided: sk-test-key-123."))
    with apprentice(server) as app, pytest.raises(EnvironmentProblem) as exc:
        propose(app)
    line = one_line(exc)
    assert "rejected the API key (HTTP 401)" in line
    assert "set OPENAI_API_KEY to a valid key" in line
    assert "sk-test-key-123" not in line
    assert len(server.seen) == 1


def test_unknown_model_is_an_input_error(server: ChatServer) -> None:
    server.queue(error(404, "model 'test-model' not found"))
    with apprentice(server) as app, pytest.raises(InputError) as exc:
        propose(app)
    assert "no model 'test-model'" in one_line(exc)


def test_bad_request_names_the_options_to_drop(server: ChatServer) -> None:
    server.queue(error(400, "Unrecognized request argument supplied: seed"))
    with apprentice(server, seed=1) as app, pytest.raises(InputError) as exc:
        propose(app)
    assert "Unrecognized request argument supplied: seed" in one_line(exc)


def test_rate_limit_exhausted_is_logged_then_raised(server: ChatServer, tmp_path: Path) -> None:
    server.queue(error(429, "slow down", FAST_RETRY), error(429, "slow down", FAST_RETRY))
    with RunLog(tmp_path / "runs.db", run_id="r") as log:
        with (
            apprentice(server, log, max_retries=1) as app,
            pytest.raises(EnvironmentProblem) as exc,
        ):
            propose(app)
        assert "still rate-limiting (HTTP 429)" in one_line(exc)
        (call,) = log.calls()
    assert not call.ok and call.reply is None and call.attempts == 2
    assert call.reason == str(exc.value)


def test_connection_refused_is_one_line() -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    settings = ClientSettings(model="m", base_url=f"http://127.0.0.1:{port}/v1", max_retries=0)
    with OpenAIApprentice(settings, environ={}) as app, pytest.raises(EnvironmentProblem) as exc:
        propose(app)
    line = one_line(exc)
    assert line.startswith(f"cannot reach http://127.0.0.1:{port}/v1:")
    assert "OPENAI_BASE_URL" in line


# ---------------------------------------------------------------------------
# Settings and keys


def test_missing_key_says_what_to_set() -> None:
    remote = ClientSettings(model="gpt-4o-mini")
    with pytest.raises(EnvironmentProblem) as exc:
        remote.resolve({})
    assert str(exc.value) == (
        "no API key: set OPENAI_API_KEY, or pass --api-key-env NAME "
        "(or api_key under [planner] in ~/.config/virf/config.toml)"
    )
    gemini = ClientSettings(
        model="gemini-2.0-flash",
        base_url="https://generativelanguage.googleapis.com/v1beta/openai/",
        api_key_env="GEMINI_API_KEY",
    )
    with pytest.raises(EnvironmentProblem, match=r"^no API key: set GEMINI_API_KEY \(or api_key"):
        gemini.resolve({"OPENAI_API_KEY": "not this one"})
    endpoint = gemini.resolve({"GEMINI_API_KEY": "g-key"})
    assert endpoint.base_url == "https://generativelanguage.googleapis.com/v1beta/openai"
    assert endpoint.api_key == "g-key" and "g-key" not in repr(endpoint)


def test_base_url_comes_from_the_environment() -> None:
    settings = ClientSettings(model="m")
    env = {"OPENAI_BASE_URL": "http://localhost:11434/v1/"}
    assert settings.resolve(env).base_url == "http://localhost:11434/v1"
    assert settings.resolve({"OPENAI_API_KEY": "k"}).base_url == "https://api.openai.com/v1"
    with pytest.raises(InputError, match=r"^OPENAI_BASE_URL 'localhost:8000' is not an http"):
        settings.resolve({"OPENAI_BASE_URL": "localhost:8000"})


def test_local_server_needs_no_key(server: ChatServer) -> None:
    server.queue(completion(PLAN))
    settings = ClientSettings(model="llama3", base_url=server.base_url)
    with OpenAIApprentice(settings, environ={}) as app:
        assert propose(app).ok
    assert server.seen[0].authorization == f"Bearer {LOCAL_PLACEHOLDER_KEY}"


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"temperature": 3}, "temperature 3 is out of range; choose 0 to 2"),
        ({"top_p": 0}, "top_p 0 is out of range"),
        ({"max_tokens": 0}, "max_tokens 0 must be an integer >= 1"),
        ({"timeout_s": 0}, "timeout 0 must be a number of seconds"),
        ({"max_retries": -1}, "max_retries -1 must be an integer >= 0"),
        ({"seed": -5}, "seed -5 must be an integer >= 0"),
        ({"api_key_env": "MY KEY"}, "is not a valid environment variable name"),
        ({"base_url": "ftp://x"}, "base URL 'ftp://x' is not an http(s) URL"),
        ({"model": " "}, "no model name: use openai:MODEL"),
    ],
)
def test_bad_settings_are_one_line_input_errors(settings: dict[str, Any], message: str) -> None:
    with pytest.raises(InputError) as exc:
        ClientSettings(**({"model": "m"} | settings))
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_api_key_is_not_in_repr() -> None:
    assert "secret" not in repr(ClientSettings(model="m", api_key="secret-key"))


def test_bad_messages_are_rejected_before_sending() -> None:
    app = ScriptedApprentice([PLAN])
    with pytest.raises(InputError, match=r"^message 1 has role 'tool'; choose one of"):
        app.propose(
            [{"role": "tool", "content": "x"}],
            task_id="t",
            iteration=0,
            method="m",
            purpose=Purpose.PLAN,
        )
    with pytest.raises(InputError, match=r"^no messages to send for task t iteration 0$"):
        app.propose([], task_id="t", iteration=0, method="m", purpose=Purpose.PLAN)
    assert app.remaining == 1


def test_a_request_names_its_purpose() -> None:
    app = ScriptedApprentice(["a", "b"])
    app.propose(MESSAGES, task_id="t", iteration=0, method="m", purpose=Purpose.CRITIQUE)
    # A purpose's value names it as well as the member does.
    app.propose(MESSAGES, task_id="t", iteration=1, method="m", purpose="repair")
    assert [r.purpose for r in app.requests] == [Purpose.CRITIQUE, Purpose.REPAIR]
    with pytest.raises(InputError) as exc:
        app.propose(MESSAGES, task_id="t", iteration=2, method="m", purpose="review")
    assert one_line(exc) == (
        "purpose 'review' is unknown; choose from plan, repair, critique, draft, perceive"
    )
    assert app.remaining == 0


# ---------------------------------------------------------------------------
# Offline apprentices and the factory


def write_jsonl(path: Path, entries: list[dict[str, Any]]) -> Path:
    path.write_text("".join(json.dumps(e) + "\n" for e in entries), encoding="utf-8")
    return path


def test_replay_serves_recorded_proposals(tmp_path: Path) -> None:
    path = write_jsonl(
        tmp_path / "rec.jsonl",
        [
            {"task_id": "t1", "iteration": 1, "text": "find Pot"},
            {"task_id": "t1", "iteration": 1, "method": "thinker", "text": "find Mug"},
            {"task_id": "t1", "iteration": 2, "text": None, "reason": "recorded failure"},
            {
                "task_id": "t2",
                "iteration": 1,
                "text": "pick Knife",
                "prompt_tokens": 5,
                "completion_tokens": 3,
                "latency_ms": 12.5,
                "attempts": 2,
            },
        ],
    )
    app = ReplayApprentice(path)
    assert propose(app, "t1", 1, "virf").text == "find Pot"
    assert propose(app, "t1", 1, "thinker").text == "find Mug"
    assert propose(app, "t1", 2) == Proposal.failed("recorded failure")
    assert propose(app, "t2", 1) == Proposal(
        text="pick Knife",
        ok=True,
        prompt_tokens=5,
        completion_tokens=3,
        latency_ms=12.5,
        attempts=2,
    )
    # Replaying is exact: asking again gives the same proposal.
    assert propose(app, "t2", 1) == propose(app, "t2", 1)
    with pytest.raises(InputError) as exc:
        propose(app, "t3", 4, "virf")
    assert (
        str(exc.value) == f"replay file {path} has no proposal for task t3 iteration 4 method virf"
    )


def test_replay_without_methods_names_task_and_iteration(tmp_path: Path) -> None:
    path = write_jsonl(tmp_path / "r.jsonl", [{"task_id": "a", "iteration": 0, "text": "drop"}])
    with pytest.raises(InputError) as exc:
        propose(ReplayApprentice(path), "a", 1)
    assert str(exc.value) == f"replay file {path} has no proposal for task a iteration 1"


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        (['{"task_id": "a", "iteration": 1, "text": "x"}', "{oops"], "line 2 is not JSON"),
        (['{"task_id": "a", "iteration": 1, "txt": "x"}'], "unknown field 'txt'"),
        (['{"task_id": "a", "iteration": -1, "text": "x"}'], "needs an integer 'iteration'"),
        (['{"iteration": 1, "text": "x"}'], "needs a string 'task_id'"),
        (['{"task_id": "a", "iteration": 1, "text": " ", "ok": true}'], "says ok but"),
        (
            ['{"task_id": "a", "iteration": 1, "text": "x"}'] * 2,
            "line 2 repeats task a iteration 1",
        ),
        ([""], "holds no proposals"),
    ],
)
def test_bad_replay_files(tmp_path: Path, lines: list[str], message: str) -> None:
    path = tmp_path / "bad.jsonl"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as exc:
        ReplayApprentice(path)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_missing_replay_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"^replay file not found: "):
        make_apprentice(f"replay:{tmp_path / 'nope.jsonl'}")


def test_scripted_apprentice_queue() -> None:
    app = ScriptedApprentice([PLAN, "", Proposal.failed("planner crashed")])
    assert propose(app, iteration=1).text == PLAN
    empty = propose(app, iteration=2)
    assert not empty.ok and empty.reason == "the reply was empty"
    assert propose(app, iteration=3).reason == "planner crashed"
    assert [r.iteration for r in app.requests] == [1, 2, 3]
    assert app.requests[0].as_messages() == MESSAGES
    with pytest.raises(InputError) as exc:
        propose(app, iteration=4)
    assert str(exc.value) == "no more scripted replies: all 3 were used before task t1 iteration 4"


def test_make_apprentice_forms(server: ChatServer, tmp_path: Path) -> None:
    server.queue(completion(PLAN))
    app = make_apprentice(
        "openai:test-model",
        base_url=server.base_url,
        temperature=None,
        seed=None,
        environ={},
    )
    assert isinstance(app, OpenAIApprentice) and app.label == "openai:test-model"
    with app:
        assert propose(app).text == PLAN
    replay = write_jsonl(tmp_path / "r.jsonl", [{"task_id": "t1", "iteration": 1, "text": "x"}])
    # Client options a command line passes along do not disturb offline planners.
    assert isinstance(make_apprentice(f"replay:{replay}", temperature=0.7), ReplayApprentice)
    scripted = make_apprentice("scripted", replies=["a"])
    assert isinstance(scripted, ScriptedApprentice) and propose(scripted).text == "a"


@pytest.mark.parametrize(
    ("spec", "settings", "message"),
    [
        (
            "gpt-4o",
            {},
            "unknown planner 'gpt-4o'; choose openai:MODEL, local:NAME (or local:PATH.gguf), replay:FILE or scripted",
        ),
        ("openai:", {}, "no model name: use openai:MODEL"),
        ("replay:", {}, "no replay file: use replay:FILE"),
        ("scripted:x", {}, "unknown planner 'scripted:x'"),
        ("openai:m", {"temprature": 0.2}, "unknown planner setting 'temprature'; choose from"),
    ],
)
def test_make_apprentice_errors(spec: str, settings: dict[str, Any], message: str) -> None:
    with pytest.raises(InputError) as exc:
        make_apprentice(spec, environ={"OPENAI_API_KEY": "k"}, **settings)
    assert str(exc.value).startswith(message)


# ---------------------------------------------------------------------------
# Run logging through the HTTP client, and re-scoring a recorded run


def test_calls_are_logged_and_replay_exactly(server: ChatServer, tmp_path: Path) -> None:
    server.queue(
        completion("", 10, 0),
        completion(PLAN, 10, 8),
        completion("find Knife", 30, 4),
        completion(None),
        completion(" "),
    )
    with RunLog(tmp_path / "runs.db", run_id="run-1") as log:
        with apprentice(server, log) as app:
            live = [
                propose(app, "t1", 1),
                propose(app, "t1", 2),
                propose(app, "t2", 1, "thinker"),
            ]
        calls = log.calls(run_id="run-1")
        assert [(c.task_id, c.iteration, c.ask, c.ok) for c in calls] == [
            ("t1", 1, 1, False),
            ("t1", 1, 2, True),
            ("t1", 2, 1, True),
            ("t2", 1, 1, False),
            ("t2", 1, 2, False),
        ]
        first = calls[0]
        assert first.messages == MESSAGES and first.method == "virf"
        assert first.apprentice == "openai:test-model" and first.model == "test-model"
        assert first.reason == "the reply was empty" and first.prompt_tokens == 10
        assert json.loads(first.reply or "")["choices"][0]["message"]["content"] == ""
        assert calls[1].reply == PLAN and calls[1].completion_tokens == 8
        assert all(c.latency_ms > 0 and c.attempts == 1 for c in calls)

        replay_path = tmp_path / "replay.jsonl"
        assert export_replay(log, "run-1", replay_path) == 3
    with RunLog(tmp_path / "rescore.db", run_id="rescore") as log2:
        replay = ReplayApprentice(replay_path, run_log=log2)
        replayed = [
            propose(replay, "t1", 1),
            propose(replay, "t1", 2),
            propose(replay, "t2", 1, "thinker"),
        ]
        assert [c.reply for c in log2.calls()] == [PLAN, "find Knife", None]
    for got, want in zip(replayed, live, strict=True):
        assert (got.text, got.ok, got.reason) == (want.text, want.ok, want.reason)
        assert (got.prompt_tokens, got.completion_tokens, got.attempts) == (
            want.prompt_tokens,
            want.completion_tokens,
            want.attempts,
        )
    assert live[2].prompt_tokens == 22  # both failed asks are paid for
