"""``virf plan``: the whole loop from the command line, offline (replay) and
through the real HTTP client against a scripted server on 127.0.0.1.

The command runs in-process (the ``cli`` fixture); the planner's own hangs
and signals are tested on real processes in test_planner_hangs.py."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from chat_support import FAST_RETRY, ChatServer, completion, error
from loop_support import CLOSES, FRIDGE_SCENE, LEAVES_OPEN
from typer.testing import Result

from virf.errors import InputError

PlanRun = Callable[..., Result]


@pytest.fixture
def virf_plan(cli: Callable[..., Result], tmp_path: Path) -> PlanRun:
    """``virf plan`` on the fridge scene, without the caller's model settings."""
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(FRIDGE_SCENE), encoding="utf-8")
    # No OPENAI_* variables, and no user config unless a test writes one.
    isolated: dict[str, str | None] = {k: None for k in os.environ if k.startswith("OPENAI_")}
    isolated["XDG_CONFIG_HOME"] = str(tmp_path / "config")

    def run(*args: str) -> Result:
        return cli(
            "plan",
            "--scene",
            scene,
            "--instruction",
            "Put the apple in the fridge.",
            *args,
            env=isolated,
        )

    return run


@pytest.fixture
def paper_kb(tmp_path: Path) -> Path:
    """A workspace on the paper's rules with nothing accepted: ``--kb`` makes
    ``virf plan`` check the paper's scenario (the command has no --scenario)."""
    from virf.authoring.workspace import Workspace

    root = tmp_path / "paper-kb"
    Workspace.init(root, scenario="paper", starter=False).close()
    return root


def test_replayed_run(tmp_path: Path, virf_plan: PlanRun) -> None:
    replay = tmp_path / "run.jsonl"
    replay.write_text(
        "\n".join(
            json.dumps({"task_id": "t1", "iteration": i, "text": text})
            for i, text in enumerate([LEAVES_OPEN, CLOSES])
        ),
        encoding="utf-8",
    )
    log = tmp_path / "log.sqlite"
    result = virf_plan(
        "--planner", f"replay:{replay}", "--task-id", "t1", "--json", "--log", str(log)
    )
    assert result.exit_code == 0, result.stderr
    out: dict[str, Any] = json.loads(result.stdout)
    assert out["outcome"] == "APPROVED"
    assert out["iterations"] == 2
    assert out["plan"] == CLOSES.splitlines()
    assert [t["status"] for t in out["transcript"] if t["kind"] == "report"] == ["UNSAFE", "SAFE"]
    assert log.is_file()
    readable = virf_plan("--planner", f"replay:{replay}", "--task-id", "t1")
    assert readable.exit_code == 0
    assert "APPROVED after 2 iteration(s)" in readable.stdout


@pytest.mark.parametrize(("method", "iterations"), [("virf-manual", 2), ("virf-rag", 1)])
def test_an_ablation_checks_only_its_own_rules(
    tmp_path: Path, virf_plan: PlanRun, paper_kb: Path, method: str, iterations: int
) -> None:
    # The paper's ablations split the paper's rules (scenario paper).
    # FridgeLeftOpenDanger is a manual rule: VIRF-RAG's tutor does not know it
    # and approves the plan that leaves the fridge open.
    replay = tmp_path / "run.jsonl"
    replay.write_text(
        "\n".join(
            json.dumps({"task_id": "t1", "iteration": i, "text": text})
            for i, text in enumerate([LEAVES_OPEN, CLOSES])
        ),
        encoding="utf-8",
    )
    result = virf_plan(
        "--planner",
        f"replay:{replay}",
        "--task-id",
        "t1",
        "--json",
        "-m",
        method,
        "--kb",
        str(paper_kb),
    )
    assert result.exit_code == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["outcome"] == "APPROVED" and out["iterations"] == iterations
    assert out["plan"] == (CLOSES if iterations == 2 else LEAVES_OPEN).splitlines()


@pytest.mark.parametrize(
    ("scenario", "fridge_rule"),
    [("kitchen", "ColdStorageLeftOpenDanger"), ("paper", "FridgeLeftOpenDanger")],
)
def test_http_run_with_a_rate_limit_and_a_repair(
    virf_plan: PlanRun,
    server: ChatServer,
    paper_kb: Path,
    scenario: str,
    fridge_rule: str,
) -> None:
    server.queue(
        completion(f"Here is my plan:\n```\n{LEAVES_OPEN}\n```"),
        error(429, "slow down", FAST_RETRY),
        completion(CLOSES),
    )
    kb = ["--kb", str(paper_kb)] if scenario == "paper" else []
    result = virf_plan(
        "--planner", "openai:test-model", "--base-url", server.base_url, "--json", *kb
    )
    assert result.exit_code == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["outcome"] == "APPROVED" and out["iterations"] == 2
    assert len(server.seen) == 3  # the 429 was retried by the client
    repair_prompt = server.seen[2].body["messages"][-1]["content"]
    assert "DIAGNOSTIC REPORT" in repair_prompt and fridge_rule in repair_prompt


def test_http_refusal_and_malformed_reply(virf_plan: PlanRun, server: ChatServer) -> None:
    server.queue(completion(""), completion("TASK_ABORT"))
    result = virf_plan("--planner", "openai:test-model", "--base-url", server.base_url, "--json")
    assert result.exit_code == 1, result.stderr
    out = json.loads(result.stdout)
    assert out["outcome"] == "TASK_REJECTED" and out["plan"] is None
    assert out["transcript"][-1]["kind"] == "refusal"


def test_missing_key_says_what_to_set(virf_plan: PlanRun) -> None:
    result = virf_plan(
        "--planner", "openai:gpt-4o-mini", "--base-url", "https://api.example.com/v1"
    )
    assert result.exit_code == 4
    assert result.stderr.startswith("error: no API key: set OPENAI_API_KEY")
    assert "Traceback" not in result.stderr


def test_unknown_planner(virf_plan: PlanRun) -> None:
    result = virf_plan("--planner", "gpt4")
    assert result.exit_code == 2
    assert (
        "choose openai:MODEL, local:NAME (or local:PATH.gguf), replay:FILE or scripted"
        in result.stderr
    )
    assert result.stderr.count("\n") == 1


def test_user_config_supplies_the_key(tmp_path: Path) -> None:
    from virf.planner import make_apprentice
    from virf.planner.clients import OpenAIApprentice
    from virf.planner.config import config_path, planner_settings

    env = {"XDG_CONFIG_HOME": str(tmp_path / "cfg")}
    assert planner_settings(env) == {}
    path = config_path(env)
    path.parent.mkdir(parents=True)
    path.write_text('[planner]\napi_key = "sk-from-file"\ntemperature = 0.2\n', encoding="utf-8")
    app = make_apprentice("openai:gpt-4o-mini", environ=env, base_url="https://api.example.com/v1")
    assert isinstance(app, OpenAIApprentice)
    assert app.settings.resolve(env).api_key == "sk-from-file"
    assert app.settings.temperature == 0.2
    # The environment wins over the file, the command line over both.
    env2 = env | {"OPENAI_API_KEY": "sk-from-env"}
    app2 = make_apprentice(
        "openai:m", environ=env2, base_url="https://x.example/v1", temperature=0.7
    )
    assert isinstance(app2, OpenAIApprentice)
    assert app2.settings.resolve(env2).api_key == "sk-from-env"
    assert app2.settings.temperature == 0.7
    path.write_text('[planner]\napi_ky = "typo"\n', encoding="utf-8")
    with pytest.raises(InputError, match="unknown \\[planner\\] key 'api_ky'"):
        planner_settings(env)


def test_terminal_answers_that_cannot_be_used_are_asked_again(
    monkeypatch: pytest.MonkeyPatch, tutor: Any
) -> None:
    from virf.cli.plan import _terminal_policy
    from virf.schema import Question, Triple

    replies = iter(["Kryptonite", "glass", ""])
    monkeypatch.setattr("typer.prompt", lambda *a, **k: next(replies))
    marker = Triple(subject="Bowl_1", predicate="hasMaterial", object="UnknownMaterial")
    material = Question(
        key="material:Bowl_1", kind="material", text="What material?", subject="Bowl_1", fact=marker
    )
    fill = Question(key="fill:Bowl_1", kind="fill", text="Liquid?", subject="Bowl_1", fact=marker)
    ask = _terminal_policy(tutor.tbox.vocabulary)
    assert ask([material, fill]) == {"material:Bowl_1": "glass"}  # Enter leaves one open


def test_usage_errors_are_one_line(cli: Callable[..., Result]) -> None:
    for args in (["plan", "--scene", "x"], ["nosuch"], ["bench", "agents", "--limit", "0"]):
        result = cli(*args)
        assert result.exit_code == 2, args
        assert result.stderr.startswith("error: ") and result.stderr.count("\n") == 1, result.stderr
