"""The ``virf`` command line, run as a real subprocess.

Each call starts a JVM (~3 s), so every command line runs at most once per
session (memoised) and the file keeps to eight distinct calls.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import EXAMPLES_DIR, ROOT

Run = Callable[..., subprocess.CompletedProcess[str]]


@pytest.fixture(scope="session")
def virf() -> Run:
    cache: dict[tuple[str, ...], subprocess.CompletedProcess[str]] = {}

    def run(*args: str | Path) -> subprocess.CompletedProcess[str]:
        key = tuple(str(a) for a in args)
        if key not in cache:
            cache[key] = subprocess.run(
                [sys.executable, "-m", "virf.cli.main", *key],
                cwd=ROOT,
                capture_output=True,
                text=True,
                timeout=300,
                check=False,
            )
        return cache[key]

    return run


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


@pytest.mark.parametrize(("case", "code"), [("pedagogical-refined", 0), ("walkthrough", 1)])
def test_verify_json(virf, example_report, case: str, code: int) -> None:
    result = virf("verify", "--json", *_example(case))
    assert result.returncode == code, result.stderr
    report = json.loads(result.stdout)  # exactly one JSON document, nothing else
    assert isinstance(report, dict)
    assert report == json.loads(example_report(case).to_json())


def test_verify_unknown_exit_code(virf) -> None:
    result = virf("verify", *_example("noise-omission"))
    assert result.returncode == 3, result.stderr
    assert "Verdict: UNKNOWN at step 1" in result.stdout
    assert "MissingObject" in result.stdout


@pytest.mark.parametrize("kind", ["unknown-verb", "malformed-scene", "unknown-class"])
def test_bad_input(virf, bad_inputs, kind: str) -> None:
    scene, plan = bad_inputs[kind]
    result = virf("verify", scene, plan)
    assert result.returncode == 2
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


def test_unknown_engine(virf) -> None:
    result = virf("verify", "--engine", "nosuch", *_example("walkthrough"))
    assert result.returncode == 2
    assert result.stderr.startswith("error:")
    assert "hermit" in result.stderr
    assert "Traceback" not in result.stderr


def test_kb_check_output(virf) -> None:
    result = virf("kb", "check")
    assert "TBox consistent: yes" in result.stdout
    assert "Traceback" not in result.stderr


def test_kb_check_exit_code(virf) -> None:
    result = virf("kb", "check")
    assert result.returncode == 0, result.stdout
