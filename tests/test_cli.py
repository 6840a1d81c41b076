"""The ``virf`` command line: verdicts, exit codes and bad input.

The commands run in-process (the ``cli`` fixture); one test starts the
installed console script to check the entry point's exit codes end to end.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import EXAMPLES_DIR, ROOT, load_expected


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory) -> dict[str, tuple[Path, Path]]:
    d = tmp_path_factory.mktemp("cli")
    walk = EXAMPLES_DIR / "walkthrough"
    (d / "verb.txt").write_text("find Pot_1\nteleport Pot_1\n", encoding="utf-8")
    (d / "broken.json").write_text('{"instances": [\n', encoding="utf-8")
    (d / "class.json").write_text(
        json.dumps({"instances": [{"class_name": "Mircowave", "instance_name": "M_1"}]}),
        encoding="utf-8",
    )
    return {
        "unknown-verb": (walk / "scene.json", d / "verb.txt"),
        "malformed-scene": (d / "broken.json", walk / "plan.txt"),
        "unknown-class": (d / "class.json", walk / "plan.txt"),
    }


def _example(name: str) -> tuple[Path, Path]:
    return EXAMPLES_DIR / name / "scene.json", EXAMPLES_DIR / name / "plan.txt"


def _scenario(name: str) -> list[str]:
    """``--scenario S`` when the example reproduces a scenario other than the
    default (the paper's examples name ``"scenario": "paper"``)."""
    scenario = load_expected(EXAMPLES_DIR / name).get("scenario")
    return [] if scenario is None else ["--scenario", scenario]


@pytest.mark.parametrize(("case", "code"), [("pedagogical-refined", 0), ("walkthrough", 1)])
def test_verify_json(cli, example_report, case: str, code: int) -> None:
    result = cli("verify", "--json", *_scenario(case), *_example(case))
    assert result.exit_code == code, result.stderr
    report = json.loads(result.stdout)  # exactly one JSON document, nothing else
    assert isinstance(report, dict)
    assert report == json.loads(example_report(case).to_json())


def test_verify_unknown_exit_code(cli) -> None:
    result = cli("verify", *_example("noise-omission"))
    assert result.exit_code == 3, result.stderr
    assert "Verdict: UNKNOWN at step 1" in result.stdout
    assert "MissingObject" in result.stdout


def test_verify_text_and_feedback(cli, example_report) -> None:
    from virf.render.feedback import feedback_prompt
    from virf.render.text import render_report

    scene, plan = _example("walkthrough")
    report = example_report("walkthrough")
    result = cli("verify", "--feedback", *_scenario("walkthrough"), scene, plan)
    assert result.exit_code == 1, result.stderr
    expected = render_report(report, title=f"{scene} + {plan}") + "\n" + feedback_prompt(report)
    assert result.stdout == expected


@pytest.mark.parametrize("kind", ["unknown-verb", "malformed-scene", "unknown-class"])
def test_bad_input(cli, bad_inputs, kind: str) -> None:
    scene, plan = bad_inputs[kind]
    result = cli("verify", scene, plan)
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error:")
    assert "Traceback" not in result.stderr + result.stdout
    expected = {
        "unknown-verb": "'teleport'",
        "malformed-scene": "not valid JSON",
        "unknown-class": "Microwave",
    }[kind]
    assert expected in lines[0]


def test_unknown_engine(cli) -> None:
    result = cli("verify", "--engine", "nosuch", *_example("walkthrough"))
    assert result.exit_code == 2
    assert result.stderr.startswith("error:")
    assert "hermit" in result.stderr
    assert "Traceback" not in result.stderr


def test_kb_check(cli) -> None:
    result = cli("kb", "check")
    assert result.exit_code == 0, result.stdout
    assert "TBox consistent: yes" in result.stdout
    assert "Compiled artifact: what the modules compile to" in result.stdout
    assert "Traceback" not in result.stderr


def test_help_lists_the_commands_in_order(cli) -> None:
    result = cli("--help")
    assert result.exit_code == 0
    names = ["verify", "demo", "plan", "kb", "scene", "bench"]
    where = [result.stdout.find(f"│ {name} ") for name in names]
    assert -1 not in where and where == sorted(where), result.stdout


def test_the_installed_script_exits_with_the_verdict() -> None:
    """The console entry point (pyproject [project.scripts]) as a real process."""
    script = Path(sys.executable).with_name("virf")
    if not script.is_file():
        pytest.skip(f"no installed virf script beside {sys.executable}")
    for case, code in (("pedagogical-refined", 0), ("walkthrough", 1)):
        result = subprocess.run(
            [str(script), "verify", "--json", *_scenario(case), *map(str, _example(case))],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        assert result.returncode == code, result.stderr
        assert json.loads(result.stdout)["status"] == ("SAFE" if code == 0 else "UNSAFE")
