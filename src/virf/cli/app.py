"""The ``virf`` root command, its exit codes and the options the commands share.

Exit codes of ``virf verify``:
  0 SAFE, 1 UNSAFE, 2 bad input or usage, 3 UNKNOWN, 4 ERROR (verification
  could not be completed: fail closed).
Exit codes of ``virf plan``:
  0 a plan the tutor verified, 1 the task was rejected, 5 a baseline's plan
  the tutor did not verify.
Every command: 2 bad input or usage, 4 an environment problem (Java, memory,
a model that cannot be reached) or an internal error, each as one line on
stderr and, when ``--json`` was given, one JSON error object on stdout
(docs/reliability.md).  Ctrl-C, SIGTERM and SIGHUP end a command cleanly
(``finally`` blocks run: child processes stopped, temporary folders
removed) with 128 + the signal's number and one line saying so
(:func:`interrupted`).

Commands do not catch errors to report them: whatever a command raises ends
in :func:`_exit_for`, the one place that maps an error to its exit code.
The commands live in the sibling modules, named in :data:`COMMANDS`; a
command's module is imported when the command is run (``virf --help``
imports them all), so ``virf verify`` pays for neither FastAPI nor the
benchmark and knowledge-base commands.
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import json
import os
import re
import sys
import traceback
from collections.abc import Callable, Iterator, MutableMapping, Sequence
from contextvars import ContextVar
from pathlib import Path
from typing import Annotated, Any

import typer

from virf.cli.usage import HelpGroup, use_help_classes
from virf.errors import EnvironmentProblem, VirfError, printable
from virf.processes import Terminated, end_on_termination

EXIT = {"SAFE": 0, "UNSAFE": 1, "UNKNOWN": 3, "ERROR": 4}
EXIT_BAD_INPUT = 2
EXIT_CLOSED_PIPE = 141  # a closed stdout ends a command as SIGPIPE would (128 + 13)
# Whether this invocation asked for --json: its errors are then also a JSON
# object on stdout, so a caller parsing stdout never gets nothing.
_JSON_ERRORS: ContextVar[bool] = ContextVar("virf_json_errors", default=False)
# Whether this is the `virf` process (main()), which ends when its command
# does; a command run in-process (typer's test runner) is not.
_OWN_PROCESS: ContextVar[bool] = ContextVar("virf_own_process", default=False)


def _json_requested(args: Sequence[str]) -> bool:
    for arg in args:
        if arg == "--":  # what follows is file names
            return False
        if arg == "--json":
            return True
    return False


class _FailClosedGroup(HelpGroup):
    """The root command: whatever fails below it ends as a documented exit code
    with one line on stderr, never a traceback, and never as exit 1 (UNSAFE)."""

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        _JSON_ERRORS.set(_json_requested(args))
        return super().parse_args(ctx, args)

    def invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except Exception as exc:
            raise _exit_for(exc) from None


# The root's commands in the order `virf --help` lists them: the module and
# attribute of each command function or sub-app (a typer.Typer, a group).
COMMANDS: dict[str, tuple[str, str]] = {
    "verify": ("virf.cli.verify", "verify"),
    "demo": ("virf.cli.verify", "demo"),
    "plan": ("virf.cli.plan", "plan"),
    "perceive": ("virf.cli.perceive", "perceive"),
    "serve": ("virf.cli.serve", "serve"),
    "kb": ("virf.cli.kb", "kb_app"),
    "scene": ("virf.cli.scene", "scene_app"),
    "bench": ("virf.cli.bench", "bench_app"),
}


def _command(name: str) -> Any:
    """The click command of :data:`COMMANDS`' ``name``, made by typer as if it
    were registered on the root (a scratch root holding only it)."""
    module, attribute = COMMANDS[name]
    target = getattr(importlib.import_module(module), attribute)
    scratch = typer.Typer(add_completion=False)
    # With a callback typer makes a group even of one command, so the
    # command comes out under its name, as the root's own would.
    scratch.callback()(_no_options)
    if isinstance(target, typer.Typer):
        scratch.add_typer(target, name=name)
    else:
        scratch.command(name)(target)
    use_help_classes(scratch)
    return typer.main.get_command(scratch).commands[name]  # type: ignore[attr-defined]


def _no_options() -> None:
    return None


class _Commands(MutableMapping[str, Any]):
    """The root's commands by name: every name of :data:`COMMANDS` is listed,
    but a command is made (its module imported, its options built) only when
    it is looked up, so a run builds the one command it runs and help, or a
    misspelt command's suggestion, still sees them all."""

    def __init__(self, made: MutableMapping[str, Any]) -> None:
        self._made: dict[str, Any] = dict(made)

    def __getitem__(self, name: str) -> Any:
        if name not in self._made and name in COMMANDS:
            self._made[name] = _command(name)
        return self._made[name]

    def __setitem__(self, name: str, command: Any) -> None:
        self._made[name] = command

    def __delitem__(self, name: str) -> None:
        del self._made[name]

    def __iter__(self) -> Iterator[str]:
        yield from COMMANDS
        yield from (name for name in self._made if name not in COMMANDS)

    def __len__(self) -> int:
        return len(COMMANDS) + sum(name not in COMMANDS for name in self._made)

    def __contains__(self, name: object) -> bool:
        return name in COMMANDS or name in self._made


class _RootGroup(_FailClosedGroup):
    """The ``virf`` command: :class:`_FailClosedGroup` with its commands made
    on first use (:class:`_Commands`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.commands = _Commands(self.commands)


app = typer.Typer(
    cls=_RootGroup,
    name="virf",
    help="VIRF Logic Tutor: verify robot task plans against an OWL 2 DL safety ontology.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
# No command is registered on the root itself (they are in COMMANDS); a
# callback that does nothing makes typer build the root as a group all the same.
app.callback()(_no_options)

_SCENARIOS = (
    "a room (kitchen, living-room, bedroom, bathroom), household (every room), "
    "paper (the hand-written rules only), appliances, cleaning"
)
ScenarioOpt = Annotated[
    str | None,
    typer.Option(
        "--scenario",
        "-s",
        help=f"Scenario module to load: {_SCENARIOS}.",
        # Typer writes the default itself (help text in brackets would be
        # read as Rich markup and vanish).
        show_default="kitchen, or the workspace's with --kb",
    ),
]
# For commands without --kb.
PlainScenarioOpt = Annotated[
    str | None,
    typer.Option(
        "--scenario",
        "-s",
        help=f"Scenario module to load: {_SCENARIOS}.",
        show_default="kitchen",
    ),
]
RoomScenarioOpt = Annotated[
    str,
    typer.Option(
        "--scenario",
        "-s",
        help="Scenario for every task; 'auto' takes each task's room from its floor plan "
        "(with --kb: the workspace's scenario).",
    ),
]


class RoomTutors:
    """Tutors of benchmark tasks: one per scenario, made on first use; the
    scenario is the task's room's for ``auto`` (the workspace's with ``kb``)."""

    def __init__(self, scenario: str, kb: Path | None, explain: bool, engine: str = "fast") -> None:
        from virf.errors import unknown_term
        from virf.ontology.tbox import resolve_scenario, scenario_names

        if scenario != "auto" and scenario not in scenario_names():
            raise unknown_term("scenario", scenario, ["auto", *scenario_names()])
        named = None if scenario == "auto" else scenario
        # With a workspace, its scenario verifies every task (it layers on one).
        self.fixed = resolve_scenario(named, kb) if kb is not None else named
        self.kb, self.explain, self.engine = kb, explain, engine
        self._made: dict[str, Any] = {}

    def named(self, scenario: str) -> Any:
        """The tutor (a :class:`virf.api.LogicTutor`) of ``scenario``."""
        if scenario not in self._made:
            from virf.api import LogicTutor

            self._made[scenario] = LogicTutor(
                scenario=scenario, engine=self.engine, explain=self.explain, kb=self.kb
            )
        return self._made[scenario]

    def for_task(self, task: Any) -> Any:
        return self.named(self.fixed or task.room.name)


KbOpt = Annotated[
    Path | None,
    typer.Option(
        "--kb",
        help="Knowledge workspace (made by 'virf kb init') whose accepted axioms are added "
        "to the built-in TBox.",
    ),
]
WorkspaceOpt = Annotated[
    Path,
    typer.Option("--workspace", "-w", help="Knowledge workspace folder (made by 'virf kb init')."),
]
EngineOpt = Annotated[
    str,
    typer.Option(
        "--engine",
        "-e",
        help="Reasoning engine: fast (default; exact, falls back to the reference when its "
        "bounds do not meet), reference (= hermit, HermiT 1.4) or pellet (Openllet 2.6).",
    ),
]


# Model settings shared by `virf plan` and `virf bench agents`.
BaseUrlOpt = Annotated[
    str | None,
    typer.Option(help="Chat-completions base URL (default: $OPENAI_BASE_URL, else OpenAI)."),
]
ApiKeyEnvOpt = Annotated[
    str | None,
    typer.Option(help="Environment variable holding the API key (default OPENAI_API_KEY)."),
]
TemperatureOpt = Annotated[float | None, typer.Option(help="Sampling temperature.")]
TopPOpt = Annotated[float | None, typer.Option(help="Nucleus sampling (top-p).")]
MaxTokensOpt = Annotated[int | None, typer.Option(help="Longest reply, in tokens.")]
ModelTimeoutOpt = Annotated[float | None, typer.Option(help="Seconds to wait for one model reply.")]
SeedOpt = Annotated[int | None, typer.Option(help="Sampling seed, where the server supports it.")]
ConstrainOpt = Annotated[
    bool | None,
    typer.Option(
        "--constrain/--no-constrain",
        help="Hold the model's plans to the actions the scene allows on the objects the "
        "instruction names (local: planners, on by default, write a line at a time, each "
        "one that runs next; a JSON schema for openai: servers, off by default).",
    ),
]


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> typer.Exit:
    """One line on stderr and, under --json, one JSON error object on stdout:
    {"status": "BAD_INPUT" (exit 2) or "ERROR" (any other code), "error": line}."""
    # A message quoting a file name or an OWLAPI error may hold line breaks or
    # escape sequences; the line must stay one line and plain text.
    line = printable(re.sub(r"\s*[\r\n]+\s*", " ", message.strip()))
    typer.echo(f"error: {line}", err=True)
    if _JSON_ERRORS.get():
        status = "BAD_INPUT" if code == EXIT_BAD_INPUT else "ERROR"
        typer.echo(json.dumps({"status": status, "error": line}))
    return typer.Exit(code)


def _exit_for(exc: BaseException) -> BaseException:
    """The exception that ends the process for ``exc`` under the exit-code rules."""
    names = {c.__name__ for c in type(exc).__mro__}
    if isinstance(exc, typer.Exit | typer.Abort) or names & {"Exit", "Abort"}:
        return exc  # already an exit, or an interrupt that main() reports
    if "ClickException" in names:
        # click's usage errors (vendored inside newer typer versions, so
        # matched by name).  Their own exit code may be 1, which verify uses
        # for UNSAFE: every usage error is 2.
        ctx = getattr(exc, "ctx", None)
        hint = f" (see '{ctx.command_path} --help')" if "UsageError" in names and ctx else ""
        message = exc.format_message()  # type: ignore[attr-defined]
        if "NoArgsIsHelpError" in names:  # the help is already on stdout
            message = "give a command"
        return _fail(f"{message}{hint}")
    if isinstance(exc, VirfError):
        # Exit 4 for what the user's input cannot fix (Java, memory, an
        # unreachable model), else 2.
        code = EXIT["ERROR"] if isinstance(exc, EnvironmentProblem) else EXIT_BAD_INPUT
        return _fail(str(exc), code)
    detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    if isinstance(exc, BrokenPipeError):
        # Whoever read stdout stopped reading (`virf ... | head`): say nothing,
        # as a program ended by SIGPIPE does, and exit as one (128 + 13), a
        # status no verdict uses.  Later writes (and the flush at exit) would
        # fail again, so stdout goes nowhere from here on.
        with contextlib.suppress(OSError, ValueError):  # a stdout without a descriptor
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return typer.Exit(EXIT_CLOSED_PIPE)
    if isinstance(exc, MemoryError) or "OutOfMemoryError" in names:
        return _fail(f"out of memory ({detail})", EXIT["ERROR"])
    # A bug.  Exit 4 (ERROR), never 1: a crash must not read as UNSAFE, nor
    # as any verdict.
    debug = os.environ.get("VIRF_DEBUG", "") not in ("", "0")
    if debug:
        traceback.print_exception(exc, file=sys.stderr)
    where = "" if debug else " (VIRF_DEBUG=1 shows the traceback)"
    return _fail(f"internal error: {detail}; please report{where}", EXIT["ERROR"])


def interrupted(exc: BaseException | None = None, what: str = "") -> typer.Exit:
    """The end of a command stopped by Ctrl-C (``exc`` a KeyboardInterrupt or
    None) or by SIGTERM or SIGHUP (a :class:`Terminated`): one line on
    stderr, ``what`` saying what was kept, and under ``--json`` one object
    ``{"status": "INTERRUPTED", "error": ...}`` on stdout; exit 128 + the
    signal's number (130, 143, 129)."""
    if isinstance(exc, Terminated):
        line, code = f"interrupted by {exc.name}", exc.exit_code
    else:
        line, code = "interrupted (Ctrl-C)", 130
    if what:
        line += f": {what}"
    # A terminal that hung up takes no more output; the exit code still tells.
    with contextlib.suppress(OSError, ValueError):
        typer.echo(line, err=True)
        if _JSON_ERRORS.get():
            typer.echo(json.dumps({"status": "INTERRUPTED", "error": line}))
    return typer.Exit(code)


def main() -> None:
    """Run the root command, then end the process with its exit code."""
    end_on_termination()
    _OWN_PROCESS.set(True)
    try:
        sys.exit(_run())
    finally:
        # The process ends next.  Interpreter shutdown runs the cyclic
        # collector over everything still alive (modules, pydantic's
        # validators, the knowledge base), which cost a cold `virf verify`
        # about 45 ms, a sixth of its time; frozen objects are not walked.
        # Objects are still freed and atexit handlers and weakref finalizers
        # (temporary folders, the JVM) still run.
        gc.freeze()


def loaded() -> None:
    """Say that the command has loaded what it keeps until the process ends
    (modules, the knowledge base).  In the ``virf`` process the cyclic
    collector stops walking those objects (``gc.freeze``): a cold ``virf
    verify`` spent ~20 ms re-walking them in its collections.  A command run
    in-process (tests) leaves the collector as it is."""
    if _OWN_PROCESS.get():
        gc.freeze()


def _run() -> int:
    """The root command's exit code, under the exit-code rules."""
    try:
        code = app(standalone_mode=False)
    except (KeyboardInterrupt, Terminated) as exc:
        return interrupted(exc).exit_code
    except Exception as exc:
        # Errors before a command runs (the root's own options, no command at
        # all) and anything the root group let through take the same road.
        ending = _exit_for(exc)
        if isinstance(ending, typer.Exit):
            return ending.exit_code
        if "Abort" in {c.__name__ for c in type(ending).__mro__}:
            return interrupted().exit_code
        exit_code = getattr(ending, "exit_code", EXIT["ERROR"])
        return exit_code if isinstance(exit_code, int) else EXIT["ERROR"]
    return code if isinstance(code, int) else 0


def write_output(path: Path, text: str) -> None:
    """A report file a command was asked to write, whole or not at all."""
    from virf.files import write_atomically

    try:
        write_atomically(path, text)
    except OSError as exc:
        raise _fail(f"cannot write {printable(str(path))}: {exc.strerror}") from None


def check_writable(path: Path, option: str) -> None:
    """Fail before the work, not after it, when an output cannot be written."""
    if path.is_dir():
        raise VirfError(f"{option} {path} is a directory; give a file path")
    if not path.parent.is_dir():
        raise VirfError(f"{option} {path}: folder {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK):
        raise VirfError(f"{option} {path}: folder {path.parent} is not writable")


def progress_bar(console: Any) -> Any:
    """The progress bar of long runs, on stderr, only when it is a terminal."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=console,
        transient=True,
        disable=not console.is_terminal,
    )


def progress_ticks(progress: Any) -> Callable[[str, int], Callable[[], None]]:
    """What a benchmark that reports progress is given: told a label and a
    total, it adds a bar to ``progress`` and returns the bar's tick."""

    def bar(label: str, total: int) -> Callable[[], None]:
        task = progress.add_task(label, total=total)
        return lambda: progress.advance(task)

    return bar


def default_reviewer() -> str:
    """Who is deciding when nobody said: the login name."""
    import getpass

    try:
        return os.environ.get("USER") or getpass.getuser()
    except (KeyError, OSError):  # no login name (a container without a passwd entry)
        return "reviewer"
