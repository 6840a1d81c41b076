"""Every failure of every ``virf`` command: a documented exit code, one line on
stderr, one JSON error object on stdout under ``--json``, never a traceback.

Most cases run in-process (the ``cli`` fixture, sharing the session's
knowledge base); the few that need a real process (the JVM under a memory
limit, a closed stdout, errors before any command runs) start one each.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from conftest import EXAMPLES_DIR, ROOT
from typer.testing import Result

from virf.errors import EnvironmentProblem

Cli = Callable[..., Result]
WALK_SCENE = str(EXAMPLES_DIR / "walkthrough" / "scene.json")
WALK_PLAN = str(EXAMPLES_DIR / "walkthrough" / "plan.txt")


def assert_one_error_line(result: Any, code: int, *, as_json: bool = False) -> str:
    """The shape of every failure; returns the message."""
    assert result.exit_code == code, (result.exit_code, result.stdout, result.stderr)
    assert "Traceback" not in result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ")
    message: str = lines[0][len("error: ") :]
    if as_json:
        shown = json.loads(result.stdout)  # exactly one JSON document
        status = "BAD_INPUT" if code == 2 else "ERROR"
        assert shown == {"status": status, "error": message}
    else:
        assert result.stdout == ""
    return message


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-1", "0", "1e999", "86401"])
@pytest.mark.parametrize("as_json", [False, True])
def test_verify_refuses_a_timeout_that_is_no_deadline(cli: Cli, value: str, as_json: bool) -> None:
    args = ["verify", WALK_SCENE, WALK_PLAN, "--timeout", value]
    result = cli(*args, *(["--json"] if as_json else []))
    assert "--timeout" in assert_one_error_line(result, 2, as_json=as_json)


@pytest.mark.parametrize("workers", ["0", "65", "100000"])
def test_verify_refuses_absurd_worker_counts(cli: Cli, workers: str) -> None:
    # 100000 engines would be forked before the deadline is ever checked.
    assert_one_error_line(cli("verify", WALK_SCENE, WALK_PLAN, "--workers", workers), 2)


def test_an_internal_error_is_exit_4_never_1(cli: Cli, monkeypatch: pytest.MonkeyPatch) -> None:
    import virf.render.text

    def broken(*_: Any, **__: Any) -> str:
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(virf.render.text, "render_report", broken)
    monkeypatch.delenv("VIRF_DEBUG", raising=False)
    message = assert_one_error_line(cli("verify", WALK_SCENE, WALK_PLAN), 4)
    assert message.startswith("internal error: ZeroDivisionError: a bug; please report")
    assert "VIRF_DEBUG=1" in message

    monkeypatch.setenv("VIRF_DEBUG", "1")
    result = cli("verify", WALK_SCENE, WALK_PLAN)
    assert result.exit_code == 4
    assert "Traceback" in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("error: internal error:")


def test_an_internal_error_under_json_is_one_error_object(
    cli: Cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    import virf.api

    def broken(self: Any, *_: Any, **__: Any) -> None:
        raise KeyError("missing")

    monkeypatch.setattr(virf.api.LogicTutor, "__init__", broken)
    monkeypatch.delenv("VIRF_DEBUG", raising=False)
    assert_one_error_line(cli("verify", "--json", WALK_SCENE, WALK_PLAN), 4, as_json=True)


def test_an_environment_problem_is_exit_4(cli: Cli, monkeypatch: pytest.MonkeyPatch) -> None:
    import virf.api

    def no_java(self: Any, *_: Any, **__: Any) -> None:
        raise EnvironmentProblem("the Java VM could not start: test")

    monkeypatch.setattr(virf.api.LogicTutor, "__init__", no_java)
    for args in (["verify", WALK_SCENE, WALK_PLAN], ["demo", str(EXAMPLES_DIR)]):
        assert "Java VM" in assert_one_error_line(cli(*args), 4)
    result = cli("verify", WALK_SCENE, WALK_PLAN, "--json")
    assert_one_error_line(result, 4, as_json=True)


def test_kb_commands_report_environment_problems_as_4(
    cli: Cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    import virf.ontology.check
    import virf.ontology.tbox

    def no_java(*_: Any, **__: Any) -> None:
        raise EnvironmentProblem("java not found")

    monkeypatch.setattr(virf.ontology.check, "check_tbox", no_java)
    monkeypatch.setattr(virf.ontology.tbox, "load_tbox", no_java)
    assert_one_error_line(cli("kb", "check", "--json"), 4, as_json=True)
    assert_one_error_line(cli("kb", "rules"), 4)
    assert_one_error_line(cli("scene", "show", WALK_SCENE), 4)


@pytest.fixture(scope="module")
def junk(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("junk")
    files = {
        "dup.json": '{"instances": [], "instances": []}',
        "nan.json": '{"instances": [], "x": NaN}',
        "list.json": "[1, 2]",
        "empty-arg.txt": "put_in(, Microwave_1)\n",
        "control.txt": "find Pot_1\x1b[2J\n",
        "long.txt": "find " + "P" * 2000 + "\n",
        "many.txt": "find Pot_1\n" * 1001,
        "plan-dup.txt": '[{"a": 1, "a": 2}]',
        "tasks.jsonl": '{"instruction": "x"}\n{broken\n',
    }
    for name, text in files.items():
        (d / name).write_text(text, encoding="utf-8")
    (d / "binary.txt").write_bytes(b"\xff\xfe\x00")
    (d / "examples" / "a").mkdir(parents=True)
    for name in ("scene.json", "plan.txt"):
        (d / "examples" / "a" / name).write_text(
            (EXAMPLES_DIR / "walkthrough" / name).read_text(encoding="utf-8"), encoding="utf-8"
        )
    (d / "examples" / "a" / "expected.json").write_text('{"status": NaN}', encoding="utf-8")
    return {name: d / name for name in [*files, "binary.txt", "examples"]}


@pytest.mark.parametrize(
    ("scene", "plan", "expected"),
    [
        ("dup.json", None, "duplicate key 'instances'"),
        ("nan.json", None, "NaN"),
        ("list.json", None, "JSON object"),
        (None, "empty-arg.txt", "argument 1 is empty"),
        (None, "control.txt", "U+001B"),
        (None, "long.txt", "the limit is 1000"),
        (None, "many.txt", "more than 1000 actions"),
        (None, "plan-dup.txt", "duplicate key 'a'"),
        (None, "binary.txt", "not UTF-8"),
    ],
)
@pytest.mark.parametrize("as_json", [False, True])
def test_verify_refuses_hostile_files(
    cli: Cli,
    junk: dict[str, Path],
    scene: str | None,
    plan: str | None,
    expected: str,
    as_json: bool,
) -> None:
    args = [
        "verify",
        str(junk[scene]) if scene else WALK_SCENE,
        str(junk[plan]) if plan else WALK_PLAN,
    ]
    result = cli(*args, *(["--json"] if as_json else []))
    message = assert_one_error_line(result, 2, as_json=as_json)
    assert expected in message
    assert "\x1b" not in result.stderr  # the escape is shown escaped, not sent to the terminal


@pytest.mark.parametrize(
    ("args", "as_json"),
    [
        (["demo", "/nonexistent"], False),
        (["kb", "check", "--scenario", "bogus", "--json"], True),
        (["kb", "rules", "--scenario", "bogus"], False),
        (["scene", "show", "/nonexistent.json", "--json"], True),
        (["scene", "show", "/dev/zero"], False),
        (["scene", "safeagentbench", "/nonexistent.jsonl", "1"], False),
        (["bench", "safeagentbench", "/nonexistent.jsonl", "--json"], True),
        (["bench", "latency", "/nonexistent.jsonl", "--json"], True),
        (["bench", "latency", WALK_SCENE, "--sizes", "10,100000"], False),
        (["bench", "latency", WALK_SCENE, "--lengths", "10,5000"], False),
        (["bench", "agents", "--method", "nosuch", "--planner", "replay:x", "--tasks", "y"], False),
        (["verify", WALK_SCENE, WALK_PLAN, "--engine", "nosuch", "--json"], True),
        (["verify", WALK_SCENE, "--json"], True),  # a usage error: PLAN is missing
        (["verify", WALK_SCENE, WALK_PLAN, "--bogus"], False),
        (["nosuch"], False),
    ],
)
def test_every_command_fails_with_one_line(cli: Cli, args: list[str], as_json: bool) -> None:
    assert_one_error_line(cli(*args), 2, as_json=as_json)


def test_a_file_named_json_after_double_dash_is_not_the_option(cli: Cli, tmp_path: Path) -> None:
    result = cli("verify", "--", str(tmp_path / "--json"), WALK_PLAN)
    assert_one_error_line(result, 2, as_json=False)


def test_demo_reports_a_broken_expected_file_as_a_mismatch(cli: Cli, junk: dict[str, Path]) -> None:
    result = cli("demo", str(junk["examples"]))
    assert result.exit_code == 1  # demo: an example did not give its expected verdict
    assert "Traceback" not in result.stdout + result.stderr
    assert "NaN" in result.stdout


def test_user_text_is_never_read_as_terminal_markup(cli: Cli, tmp_path: Path) -> None:
    # rich reads '[/red]' as a closing tag: a scene name or a plan word like it
    # once crashed 'scene show' and 'demo' with a MarkupError.
    scene = tmp_path / "scene.json"
    scene.write_text(
        json.dumps(
            {"instances": [{"class_name": "Pot", "instance_name": "Pot_1"}], "name": "[/red]"}
        ),
        encoding="utf-8",
    )
    result = cli("scene", "show", str(scene))
    assert result.exit_code == 0, result.stderr
    assert "Scene [/red]" in result.stdout
    case = tmp_path / "examples" / "a"
    case.mkdir(parents=True)
    (case / "scene.json").write_text(scene.read_text(encoding="utf-8"), encoding="utf-8")
    (case / "plan.txt").write_text("find [/red]\n", encoding="utf-8")
    result = cli("demo", str(tmp_path / "examples"))
    assert result.exit_code == 0, result.stderr
    assert "find [/red]" in result.stdout


# ---------------------------------------------------------------- real processes
def virf(*args: str, limit_kb: int | None = None, **kw: Any) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "virf.cli.main", *args]
    if limit_kb is not None:
        command = ["bash", "-c", f'ulimit -v {limit_kb}; exec "$@"', "virf", *command]
    return subprocess.run(
        command, cwd=ROOT, capture_output=True, text=True, timeout=300, check=False, **kw
    )


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ulimit -v and fork")
@pytest.mark.parametrize("as_json", [False, True])
def test_a_jvm_that_cannot_start_is_an_environment_problem(as_json: bool) -> None:
    # HotSpot cannot reserve its class space in 600 MB and ends the process
    # itself (status 1, the UNSAFE code), printing to stdout.  The reference
    # engine: the fast one verifies this plan without starting Java at all.
    extra = ["--json"] if as_json else []
    args = ["verify", "--engine", "reference", WALK_SCENE, WALK_PLAN, *extra]
    result = virf(*args, limit_kb=600_000)
    assert result.returncode == 4, (result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Java VM could not start" in lines[0], result.stderr
    if as_json:
        assert json.loads(result.stdout)["status"] == "ERROR"
    else:
        assert result.stdout == ""


@pytest.mark.parametrize(
    ("args", "code"), [((), 2), (("--bogus",), 2), (("kb",), 2), (("verify", "--help"), 0)]
)
def test_errors_before_any_command_runs(args: tuple[str, ...], code: int) -> None:
    result = virf(*args)
    assert result.returncode == code, result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    if code:
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_a_closed_stdout_is_not_a_verdict() -> None:
    # `virf verify ... | head -0`: exit 1 would read as UNSAFE.  Quietly, with
    # the status of a program SIGPIPE ended (what `| head` users expect).
    proc = subprocess.Popen(
        [sys.executable, "-m", "virf.cli.main", "verify", WALK_SCENE, WALK_PLAN],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()
    stderr = proc.stderr.read()
    assert proc.wait(timeout=300) == 141, stderr
    assert stderr == ""


@pytest.mark.parametrize(("engine", "guess"), [("fats", "did you mean fast? "), ("bogus", "")])
def test_an_unknown_engine_lists_every_engine(cli: Cli, engine: str, guess: str) -> None:
    result = cli("verify", WALK_SCENE, WALK_PLAN, "--engine", engine)
    assert result.exit_code == 2
    every = "choose from fast, hermit, openllet, pellet, reference"
    assert result.stderr.strip() == f"error: unknown engine '{engine}'; {guess}{every}"
