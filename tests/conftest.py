"""Shared fixtures: one JVM, one knowledge base, one Logic Tutor per test session.

Loading the TBox and starting HermiT costs seconds, so ``tutor`` is session
scoped and every test reuses it.  Tests that need a broken or slow engine build
their own ``Verifier`` around ``tutor.tbox`` instead of touching the shared one.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner, Result

from virf.api import LogicTutor
from virf.ontology.tbox import Vocabulary
from virf.schema import Report

# Fixtures that several test modules use live in support modules, loaded here
# as plugins so that no test module imports another.
pytest_plugins = ("chat_support", "loop_support", "postgres_support")

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES_DIR = ROOT / "examples"


def example_cases() -> list[Path]:
    """Every example folder: one ``scene.json`` + ``plan.txt`` (+ ``expected.json``)."""
    return sorted(
        p
        for p in EXAMPLES_DIR.iterdir()
        if p.is_dir() and (p / "scene.json").is_file() and (p / "plan.txt").is_file()
    )


def load_expected(case: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((case / "expected.json").read_text(encoding="utf-8"))
    return data


def case_params(keep: Callable[[Path], bool] | None = None) -> list[Any]:
    """Example folders as pytest params with readable ids, optionally filtered."""
    return [pytest.param(c, id=c.name) for c in example_cases() if keep is None or keep(c)]


def interruptible() -> None:
    """A ``preexec_fn`` for a child a test sends SIGINT: it takes Ctrl-C as
    from a terminal even when the suite itself runs in the background (a
    shell's background job ignores SIGINT, and its children inherit that)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


# Small builders for inline scenes.
def inst(cls: str, name: str) -> dict[str, str]:
    return {"class_name": cls, "instance_name": name}


def rel(subject: str, prop: str, obj: str, kind: str = "object_property") -> dict[str, str]:
    return {"subject": subject, "property": prop, "object": obj, "type": kind}


@pytest.fixture(scope="session")
def tutor() -> LogicTutor:
    """The default tutor (fast engine)."""
    return LogicTutor()


@pytest.fixture(scope="session")
def reference_tutor() -> LogicTutor:
    """The same knowledge base with the reference engine (HermiT)."""
    return LogicTutor(engine="reference")


@pytest.fixture(scope="session")
def cli(tutor: LogicTutor) -> Callable[..., Result]:
    """Run ``virf ARGS`` in-process with typer's CliRunner: ``cli("verify", scene, plan)``.

    The commands reuse the session's knowledge base, so a call costs
    milliseconds instead of a JVM start.  ``env`` sets (or, with None,
    removes) environment variables for the call.  A real process is for what
    only one shows: the installed script, signals, a closed pipe."""
    from virf.cli.main import app

    runner = CliRunner()

    def invoke(
        *args: str | Path, input: str | None = None, env: Mapping[str, str | None] | None = None
    ) -> Result:
        return runner.invoke(app, [str(a) for a in args], input=input, env=env)

    return invoke


@pytest.fixture(scope="session")
def vocab(tutor: LogicTutor) -> Vocabulary:
    return tutor.tbox.vocabulary


@pytest.fixture(scope="session")
def examples_dir() -> Path:
    return EXAMPLES_DIR


@pytest.fixture(scope="session")
def paper_tutor() -> LogicTutor:
    """The paper's hand-written rules (scenario ``paper``, fast engine)."""
    return LogicTutor(scenario="paper")


@pytest.fixture(scope="session")
def paper_reference_tutor() -> LogicTutor:
    """The paper's rules with the reference engine (HermiT)."""
    return LogicTutor(scenario="paper", engine="reference")


@pytest.fixture(scope="session")
def example_tutor(tutor: LogicTutor, paper_tutor: LogicTutor) -> Callable[[str], LogicTutor]:
    """The tutor an example folder is verified with: the scenario its
    expected.json names (the paper's examples reproduce the paper's rules),
    else the default."""

    def get(name: str) -> LogicTutor:
        scenario = load_expected(EXAMPLES_DIR / name).get("scenario")
        if scenario is None:
            return tutor
        assert scenario == "paper", f"{name}: add a session tutor for scenario {scenario}"
        return paper_tutor

    return get


@pytest.fixture(scope="session")
def example_report(example_tutor: Callable[[str], LogicTutor]) -> Callable[[str], Report]:
    """The report for an example folder by name, verified once per session."""
    cache: dict[str, Report] = {}

    def get(name: str) -> Report:
        if name not in cache:
            case = EXAMPLES_DIR / name
            cache[name] = example_tutor(name).verify_files(case / "scene.json", case / "plan.txt")
        return cache[name]

    return get


_exit_status: list[int] = []


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    _exit_status.append(int(exitstatus))


def pytest_unconfigure(config: pytest.Config) -> None:
    """Leave without the interpreter's teardown once pytest has reported.

    The session's JVM (JPype) can crash while it shuts down with reasoner and
    worker threads still parked (seen once as a segfault after every test had
    passed); the verdict of the run is already printed, so the process ends
    with pytest's own exit status instead of risking that teardown."""
    if _exit_status and os.environ.get("VIRF_PYTEST_TEARDOWN") != "1":
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status[-1])
