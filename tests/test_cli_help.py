"""Every command's ``--help`` reads as a user expects: flags without a type
(``--json``, not ``--json <bool>``), arguments named on the usage line as
``SCENE PLAN`` (not ``{scene} {plan}``), help text that Rich markup does
not eat (``[default: ...]`` inside a help string vanished), and the default
of ``--scenario`` shown.  The commands are found by walking the root app,
so a command added later is checked too."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest
import typer
from rich.text import Text
from typer.testing import CliRunner

from virf.cli.app import COMMANDS
from virf.cli.main import app


def _walk(command: Any, path: tuple[str, ...]) -> Iterator[tuple[tuple[str, ...], Any]]:
    yield path, command
    for name in getattr(command, "commands", {}):
        yield from _walk(command.commands[name], (*path, name))


ROOT = typer.main.get_command(app)
EVERY_COMMAND = list(_walk(ROOT, ()))


def test_the_walk_finds_every_command() -> None:
    paths = {" ".join(path) for path, _ in EVERY_COMMAND}
    assert set(COMMANDS) <= paths
    assert {"kb check", "kb corpus add", "bench safeagentbench", "scene show"} <= paths


@pytest.fixture(scope="module")
def helps() -> dict[str, str]:
    runner = CliRunner()
    shown: dict[str, str] = {}
    for path, _ in EVERY_COMMAND:
        result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "200"})
        assert result.exit_code == 0, (path, result.stdout, result.stderr)
        shown[" ".join(("virf", *path))] = result.stdout
    return shown


def test_no_flag_shows_a_type(helps: dict[str, str]) -> None:
    for name, text in helps.items():
        assert "<bool>" not in text, (name, text)


def test_arguments_are_named_plainly_on_the_usage_line(helps: dict[str, str]) -> None:
    for name, text in helps.items():
        usage = next(line for line in text.splitlines() if "Usage:" in line)
        assert not re.search(r"[{}]", usage), (name, usage)
    assert re.search(r"Usage: virf verify \[OPTIONS\] SCENE PLAN\s*$", helps["virf verify"], re.M)
    assert re.search(r"Usage: virf demo \[OPTIONS\] \[FOLDER\]\s*$", helps["virf demo"], re.M)
    assert re.search(
        r"Usage: virf kb corpus add \[OPTIONS\] FILES\.\.\.\s*$", helps["virf kb corpus add"], re.M
    )


def test_help_text_survives_rich_markup() -> None:
    """Typer reads help as Rich markup: a bracketed phrase that looks like a
    tag (``[default: kitchen]``) disappears from what the user sees."""
    for path, command in EVERY_COMMAND:
        texts = [command.help or ""] + [getattr(p, "help", None) or "" for p in command.params]
        for text in texts:
            assert Text.from_markup(text).plain == text, (path, text)


@pytest.mark.parametrize(
    ("command", "default"),
    [
        ("virf verify", "kitchen, or the workspace's with --kb"),
        ("virf scene show", "kitchen"),
        ("virf kb rules", "kitchen, or the workspace's with --kb"),
        ("virf bench safeagentbench", "auto"),
    ],
)
def test_scenario_shows_its_default(helps: dict[str, str], command: str, default: str) -> None:
    row = helps[command][helps[command].index("--scenario") :]
    row = row[: row.index("│ --", 1)] if "│ --" in row[1:] else row
    assert "[default:" in row and default in re.sub(r"[\s│]+", " ", row), (command, row)
