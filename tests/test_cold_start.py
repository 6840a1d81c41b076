"""What a cold ``virf verify`` imports: only what the verdict needs.

A fresh process pays for every module it imports, so the commands, the
service, the Java bridge and the rest are imported where they are used
(issue 29, cold start).  These tests check which modules a real
process has loaded, not how long it took: an import made eager again fails
here, whatever the machine's speed.  The time itself is a benchmark
(``virf bench latency --cold-runs``).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from conftest import EXAMPLES_DIR, ROOT
from typer.testing import CliRunner

from virf.cli.app import COMMANDS
from virf.cli.main import app

# Loaded by none of the fast engine's verifications: each was once imported on
# the way to a verdict (FastAPI by `virf serve`'s module, the Java bridge by
# the artifact loader, the other commands by the CLI's start-up).
NOT_FOR_A_VERDICT = (
    "fastapi",
    "starlette",
    "uvicorn",
    "httpx",
    "openai",
    "rich",
    "jpype",
    "nltk",  # WordNet: read only for a scene's words the knowledge base lacks
    "sqlite3",
    "argparse",
    "concurrent.futures",
    "virf.web",
    "virf.service",
    "virf.planner",
    "virf.bench",
    "virf.authoring",
    "virf.perception",
    "virf.cli.bench",
    "virf.cli.kb",
    "virf.cli.plan",
    "virf.cli.perceive",
    "virf.cli.scene",
    "virf.cli.serve",
    "virf.ontology.owlapi",
    "virf.ontology.jvm",
    "virf.render.feedback",
)

# Runs the console entry point in this interpreter, then reports the exit code
# and the loaded modules on stderr's last line.
_PROBE = """
import json, sys
from virf.cli.main import main
sys.argv = ["virf", *sys.argv[1:]]
try:
    main()
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "modules": sorted(sys.modules)}), file=sys.stderr)
"""


def _loaded_by(*args: str) -> tuple[int, set[str]]:
    done = subprocess.run(
        [sys.executable, "-c", _PROBE, *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    probe = json.loads(done.stderr.strip().splitlines()[-1])
    return probe["code"], set(probe["modules"])


def _heavy(modules: set[str]) -> list[str]:
    return [
        name
        for name in NOT_FOR_A_VERDICT
        if name in modules or any(m.startswith(name + ".") for m in modules)
    ]


@pytest.mark.parametrize("as_json", [False, True])
def test_a_fast_verify_imports_only_what_its_verdict_needs(as_json: bool) -> None:
    walk = EXAMPLES_DIR / "walkthrough"
    extra = ["--json"] if as_json else []
    code, modules = _loaded_by("verify", *extra, str(walk / "scene.json"), str(walk / "plan.txt"))
    assert code == 1  # UNSAFE: the verdict was reached
    assert "virf.reasoning.fast" in modules  # so the probe sees a real verification
    assert _heavy(modules) == []


def test_every_command_is_listed_and_made_on_demand() -> None:
    """The root lists every command without importing it, and each one,
    named, is made from its module: a wrong module or attribute in
    COMMANDS fails here rather than when a user runs the command."""
    runner = CliRunner()
    for name in COMMANDS:
        result = runner.invoke(app, [name, "--help"])
        assert result.exit_code == 0, (name, result.stdout, result.stderr)
        assert f"Usage: virf {name} " in result.stdout


def test_a_misspelt_command_is_still_matched_against_all_commands() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "virf.cli.main", "verfy"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2
    assert "Did you mean 'verify'?" in done.stderr
