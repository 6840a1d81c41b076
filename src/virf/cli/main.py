"""The ``virf`` command: thin wrappers over :mod:`virf.api`.

Exit codes of ``virf verify``:
  0 SAFE, 1 UNSAFE, 2 bad input or usage, 3 UNKNOWN, 4 ERROR (verification
  could not be completed: fail closed).
Exit codes of ``virf plan``:
  0 a plan the tutor verified, 1 the task was rejected, 5 a baseline's plan
  the tutor did not verify.
Every command: 2 bad input or usage, 4 an environment problem (Java, memory,
a model that cannot be reached) or an internal error, each as one line on
stderr and, when ``--json`` was given, one JSON error object on stdout
(docs/reliability.md).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import sys
import traceback
from collections.abc import Sequence
from contextvars import ContextVar
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from virf.errors import EnvironmentProblem, VirfError, printable

EXIT = {"SAFE": 0, "UNSAFE": 1, "UNKNOWN": 3, "ERROR": 4}
EXIT_BAD_INPUT = 2
# Whether this invocation asked for --json: its errors are then also a JSON
# object on stdout, so a caller parsing stdout never gets nothing.
_JSON_ERRORS: ContextVar[bool] = ContextVar("virf_json_errors", default=False)


def _json_requested(args: Sequence[str]) -> bool:
    for arg in args:
        if arg == "--":  # what follows is file names
            return False
        if arg == "--json":
            return True
    return False


class _FailClosedGroup(TyperGroup):
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


app = typer.Typer(
    cls=_FailClosedGroup,
    name="virf",
    help="VIRF Logic Tutor: verify robot task plans against an OWL 2 DL safety ontology.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
kb_app = typer.Typer(help="Inspect the safety knowledge base (TBox).", no_args_is_help=True)
app.add_typer(kb_app, name="kb")
scene_app = typer.Typer(
    help="Show how a scene is understood; build scenes for benchmark tasks.", no_args_is_help=True
)
app.add_typer(scene_app, name="scene")
bench_app = typer.Typer(help="Evaluate the Logic Tutor on benchmarks.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")

ScenarioOpt = Annotated[
    str,
    typer.Option(
        "--scenario", "-s", help="Scenario module to load (kitchen, appliances, cleaning)."
    ),
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


def _fail_for(exc: VirfError) -> typer.Exit:
    """Exit 4 for what the user's input cannot fix (Java, memory), else 2."""
    return _fail(str(exc), EXIT["ERROR"] if isinstance(exc, EnvironmentProblem) else EXIT_BAD_INPUT)


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
        return _fail_for(exc)
    detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    if isinstance(exc, BrokenPipeError):
        # Whoever read stdout stopped reading; later writes (and the flush at
        # exit) would fail again, so stdout goes nowhere from here on.
        with contextlib.suppress(OSError, ValueError):  # a stdout without a descriptor
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return _fail("stdout was closed before all output was written", EXIT["ERROR"])
    if isinstance(exc, MemoryError) or "OutOfMemoryError" in names:
        return _fail(f"out of memory ({detail})", EXIT["ERROR"])
    # A bug.  Exit 4 (ERROR), never 1: a crash must not read as UNSAFE, nor
    # as any verdict.
    debug = os.environ.get("VIRF_DEBUG", "") not in ("", "0")
    if debug:
        traceback.print_exception(exc, file=sys.stderr)
    where = "" if debug else " (VIRF_DEBUG=1 shows the traceback)"
    return _fail(f"internal error: {detail}; please report{where}", EXIT["ERROR"])


@app.command()
def verify(
    scene: Annotated[Path, typer.Argument(help="Scene ABox JSON file.")],
    plan: Annotated[
        Path, typer.Argument(help="Plan: one action per line, or a JSON list of actions.")
    ],
    as_json: Annotated[
        bool, typer.Option("--json", help="Print exactly one JSON report on stdout.")
    ] = False,
    feedback: Annotated[
        bool,
        typer.Option("--feedback", help="Also print the paper's feedback prompt for the planner."),
    ] = False,
    scenario: ScenarioOpt = "kitchen",
    engine: EngineOpt = "fast",
    timeout: Annotated[
        float,
        typer.Option(
            help="Give up (status ERROR) after this many seconds (above 0, at most 86400)."
        ),
    ] = 120.0,
    workers: Annotated[
        int,
        typer.Option(
            min=1,
            max=64,
            help="Classify the plan's snapshots on this many engines in parallel "
            "(pays off with the reference engine; the report is the same).",
        ),
    ] = 1,
) -> None:
    """Verify PLAN in SCENE.  Exit 0 SAFE, 1 UNSAFE, 3 UNKNOWN, 4 ERROR, 2 bad input."""
    from virf.api import LogicTutor, check_timeout
    from virf.render.feedback import feedback_prompt, render_report
    from virf.world.plan import load_plan_file
    from virf.world.scene import load_scene_file

    try:
        check_timeout(timeout, "--timeout")
        steps = load_plan_file(plan)
        tutor = LogicTutor(scenario=scenario, engine=engine, timeout_s=timeout, workers=workers)
        sc = load_scene_file(scene, tutor.tbox.vocabulary)
    except VirfError as exc:
        raise _fail_for(exc) from None
    report = tutor.verifier.verify(sc, steps)
    if as_json:
        typer.echo(report.to_json())
    else:
        typer.echo(render_report(report, title=f"{scene} + {plan}"), nl=False)
        if feedback and report.status != "SAFE":
            typer.echo("\n" + feedback_prompt(report), nl=False)
    raise typer.Exit(EXIT[report.status])


@app.command()
def demo(
    folder: Annotated[
        Path, typer.Argument(help="Folder of examples: one sub-folder per scene.json + plan.txt.")
    ] = Path("examples"),
    engine: EngineOpt = "fast",
) -> None:
    """Verify every example and print the reports; checks each against its expected.json."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from virf.api import LogicTutor
    from virf.errors import read_json_file
    from virf.render.feedback import render_report

    cases = sorted(p.parent for p in folder.glob("*/plan.txt")) if folder.is_dir() else []
    if not cases:
        raise _fail(f"no examples in {folder} (expected <name>/scene.json and <name>/plan.txt)")
    try:
        tutor = LogicTutor(engine=engine)
    except VirfError as exc:
        raise _fail_for(exc) from None
    console = Console(highlight=False, width=150)
    table = Table(title="VIRF demo", show_lines=False)
    for col in ("example", "expected", "verdict", "step", "violated concept", "match"):
        table.add_column(col)
    mismatches = 0
    for case in cases:
        expected: dict[str, Any] = {}
        try:
            if (case / "expected.json").exists():
                expected = read_json_file(case / "expected.json", "expected verdict")
                if not isinstance(expected, dict):
                    raise VirfError(f"{case / 'expected.json'} must be a JSON object")
            report = tutor.verify_files(case / "scene.json", case / "plan.txt")
        except VirfError as exc:
            console.print(f"{case.name}: {exc}", style="red", markup=False)
            mismatches += 1
            continue
        # Reports quote the user's files: '[/red]' in a plan is text, not markup.
        console.print(render_report(report, title=case.name), markup=False)
        ok = (not expected) or (
            expected.get("status") == report.status
            and expected.get("dangerous_step", report.dangerous_step) == report.dangerous_step
            and expected.get(
                "violated_concept", report.violated_concept and report.violated_concept.id
            )
            == (report.violated_concept and report.violated_concept.id)
        )
        mismatches += 0 if ok else 1
        table.add_row(
            escape(case.name),
            escape(str(expected.get("status", "-"))),
            report.status,
            "-" if report.dangerous_step is None else str(report.dangerous_step),
            report.violated_concept.id if report.violated_concept else "-",
            "yes" if ok else "[red]NO[/red]",
        )
    console.print(table)
    if mismatches:
        raise _fail(f"{mismatches} example(s) did not give their expected verdict", 1)


@app.command()
def plan(
    scene: Annotated[Path, typer.Option("--scene", help="Scene ABox JSON file.")],
    instruction: Annotated[str, typer.Option("--instruction", "-i", help="What the user asks.")],
    planner: Annotated[
        str,
        typer.Option(
            "--planner",
            "-p",
            help="openai:MODEL (any OpenAI-compatible server) or replay:FILE (a recorded run).",
        ),
    ],
    base_url: BaseUrlOpt = None,
    api_key_env: ApiKeyEnvOpt = None,
    temperature: TemperatureOpt = None,
    seed: SeedOpt = None,
    top_p: TopPOpt = None,
    max_tokens: MaxTokensOpt = None,
    timeout: Annotated[
        float | None,
        typer.Option(
            help="Seconds one model reply may take, start to end (default 120). A reply "
            "still arriving then is abandoned and the proposal fails; a server that has "
            "not begun to answer is retried."
        ),
    ] = None,
    deadline: Annotated[
        float | None,
        typer.Option(
            help="Seconds the whole run may take (default 600, or deadline_s in the config "
            "file). When they pass, the request in flight is abandoned and the task is "
            "rejected. Time spent answering questions at the terminal does not count."
        ),
    ] = None,
    max_iter: Annotated[int, typer.Option(min=1, help="Refinement iterations (N_max).")] = 5,
    method: Annotated[
        str,
        typer.Option(
            "--method",
            "-m",
            help="virf (default), virf-reject, virf-rag, virf-manual, thinker+diagnostic, "
            "committee, impulsive, thinker, impulsive+rules or thinker+rules.",
        ),
    ] = "virf",
    answers: Annotated[
        Path | None,
        typer.Option(
            help="JSON answers to the tutor's questions ({key: answer}); without it the "
            "questions are asked on the terminal, or left unanswered when stdin is not one."
        ),
    ] = None,
    task_id: Annotated[
        str, typer.Option(help="Task id (keys replay files and the run log).")
    ] = "task",
    log: Annotated[Path | None, typer.Option(help="SQLite run log of every model call.")] = None,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json", help="Print one JSON object: outcome, plan, iterations, transcript."
        ),
    ] = False,
    engine: EngineOpt = "fast",
) -> None:
    """Let the apprentice plan and the tutor verify until a plan is approved (Algorithm 1).

    Exit 0 when the tutor verified the approved plan, 1 when the task is
    rejected (also when --deadline passes), 2 on bad input, 4 when the model
    cannot be reached, 5 when a baseline method (impulsive, thinker, committee,
    the +rules methods, thinker+diagnostic's retry) approved a plan the tutor
    did not verify.
    """
    from virf.api import LogicTutor
    from virf.planner import RunLog, make_apprentice
    from virf.planner.config import run_deadline
    from virf.planner.deadline import Deadline
    from virf.planner.methods import get_method, knowledge_filter, run_method
    from virf.planner.questions import answers_file, deny
    from virf.verify.verifier import Verifier
    from virf.world.scene import build_scene, load_scene_data

    run_log: Any = None
    try:
        # Started first: the deadline bounds the whole run, loading included.
        clock = Deadline(run_deadline(deadline))
        data = load_scene_data(scene)
        tutor = LogicTutor(engine=engine)
        vocab = tutor.tbox.vocabulary
        build_scene(data, vocab)  # bad scenes fail here, before any model call
        policy = (
            answers_file(answers)
            if answers is not None
            else (
                clock.excluding(_terminal_policy(vocab))
                if sys.stdin.isatty() and not as_json
                else deny
            )
        )
        run_log = RunLog(log) if log is not None else None
        apprentice = make_apprentice(
            planner,
            run_log=run_log,
            base_url=base_url,
            api_key_env=api_key_env,
            temperature=temperature,
            seed=seed,
            top_p=top_p,
            max_tokens=max_tokens,
            timeout_s=timeout,
        )
        if not instruction.strip():
            raise VirfError("--instruction is empty; say what the robot should do")
        chosen = get_method(method)
        verifier = tutor.verifier
        if chosen.knowledge != "all":
            verifier = Verifier(
                tutor.tbox,
                tutor.engine,
                uscs={u.name for u in vocab.uscs.values() if knowledge_filter(u, chosen.knowledge)},
            )
        with apprentice:
            result = run_method(
                chosen,
                instruction,
                data,
                apprentice,
                verifier,
                lambda d: build_scene(d, vocab, name=scene.stem),
                vocab,
                max_iter=max_iter,
                answer=policy,
                task_id=task_id,
                deadline=clock,
            )
    except EnvironmentProblem as exc:
        raise _fail(str(exc), EXIT["ERROR"]) from None
    except VirfError as exc:
        raise _fail(str(exc)) from None
    finally:
        if run_log is not None:
            run_log.close()
    if as_json:
        typer.echo(result.to_json())
    else:
        _print_dialogue(result)
        if result.outcome == "APPROVED_UNVERIFIED":
            typer.echo(
                f"Not verified: the method '{chosen.name}' did not have the Logic Tutor "
                "check this plan (exit 5)."
            )
    codes = {"APPROVED": 0, "TASK_REJECTED": 1, "APPROVED_UNVERIFIED": 5}
    raise typer.Exit(codes[result.outcome])


def _terminal_policy(vocab: Any) -> Any:
    """Ask each question on the terminal; an answer that cannot be used is asked again."""
    from virf.planner.questions import check_answer

    def ask(questions: Any) -> dict[str, str]:
        typer.echo(
            "The tutor needs facts it does not know (press Enter to leave one open):", err=True
        )
        out: dict[str, str] = {}
        for q in questions:
            prompt = f"  {q.text}"
            if q.kind == "contradiction":  # answered by number
                prompt += "".join(f"\n    {n}) {o}" for n, o in enumerate(q.options, start=1))
            elif q.options and len(q.options) <= 6:
                prompt += f" [{'/'.join(q.options)}]"
            while True:
                reply = typer.prompt(prompt, default="", show_default=False, err=True)
                if not reply.strip():
                    break
                try:
                    check_answer(q, reply.strip(), vocab)
                except VirfError as exc:
                    typer.echo(f"  {exc}", err=True)
                    continue
                out[q.key] = reply.strip()
                break
        return out

    return ask


def _print_dialogue(result: Any) -> None:
    from rich.console import Console
    from rich.rule import Rule

    from virf.render.feedback import render_report
    from virf.schema import Report

    console = Console(highlight=False, width=110)
    for t in result.transcript:
        label = f"iteration {t.iteration} · {t.speaker} · {t.kind}"
        if t.status:
            label += f" · {t.status}"
        console.print(Rule(label, align="left"))
        if t.kind == "report" and t.data:
            console.print(render_report(Report.model_validate(t.data)).rstrip(), markup=False)
        else:
            console.print(t.text, markup=False)
    console.print(Rule())
    console.print(
        f"{result.outcome} after {result.iterations} iteration(s): {result.reason}", markup=False
    )
    if result.plan:
        console.print("\n".join(result.plan), markup=False)


@kb_app.command("check")
def kb_check(
    scenario: ScenarioOpt = "kitchen",
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the figures as one JSON object.")
    ] = False,
) -> None:
    """Check the TBox: consistency, satisfiability of every USC, and counts per module and category."""
    from rich.console import Console
    from rich.table import Table

    from virf.ontology.check import check_tbox

    try:
        result = check_tbox(scenario)
    except VirfError as exc:
        raise _fail_for(exc) from None
    if as_json:
        typer.echo(json.dumps(result, indent=2, sort_keys=True))
    else:
        console = Console(highlight=False, width=150)
        console.print(f"Scenario: {scenario}  (reasoner: {result['reasoner']})")
        console.print(f"TBox consistent: {'yes' if result['consistent'] else 'NO'}")
        unsat = result["unsatisfiable_uscs"]
        console.print(
            f"Unsafe State Concepts satisfiable: {result['uscs'] - len(unsat)}/{result['uscs']}"
            + (f"  UNSATISFIABLE: {', '.join(unsat)}" if unsat else "")
        )
        bad = result["unsatisfiable_classes"]
        console.print(
            f"Named classes satisfiable: {result['classes'] - len(bad)}/{result['classes']}"
            + (f"  UNSATISFIABLE: {', '.join(bad)}" if bad else "")
        )
        table = Table(title="Modules")
        for col in (
            "module",
            "imports",
            "classes",
            "obj props",
            "data props",
            "individuals",
            "logical axioms",
            "USCs",
        ):
            table.add_column(col, justify="right" if col not in ("module", "imports") else "left")
        for m in result["modules"]:
            table.add_row(
                m["name"],
                ", ".join(m["imports"]),
                str(m["classes"]),
                str(m["object_properties"]),
                str(m["data_properties"]),
                str(m["individuals"]),
                str(m["logical_axioms"]),
                str(m["uscs"]),
            )
        console.print(table)
        cats = Table(title="Unsafe State Concepts per category and kind")
        kinds = sorted({k for row in result["usc_by_category"].values() for k in row})
        cats.add_column("category")
        for k in kinds:
            cats.add_column(k, justify="right")
        cats.add_column("total", justify="right")
        for cat, row in sorted(result["usc_by_category"].items()):
            cats.add_row(cat, *[str(row.get(k, 0)) for k in kinds], str(sum(row.values())))
        console.print(cats)
        console.print(f"Precondition definitions (simulator): {result['preconditions']}")
        console.print(f"Annotated background axioms: {result['background_axioms']}")
        fe = result["fast_engine"]
        if fe["exact_fragment"]:
            console.print(
                f"Fast engine: inside its fragment ({fe['query_classes']} query classes, "
                f"{fe['sink_classes']} sink classes, {fe['kb_axioms']} knowledge-base axioms, "
                f"{fe['compiled_axioms']} compiled to rules, {fe['model_checked_axioms']} "
                "checked on candidate models)"
            )
        else:
            console.print(
                "Fast engine: OUTSIDE its fragment, every question goes to the reference "
                f"engine: {'; '.join(fe['problems'][:3])}"
            )
    if not result["consistent"] or result["unsatisfiable_uscs"] or result["unsatisfiable_classes"]:
        raise typer.Exit(1)


@kb_app.command("rules")
def kb_rules(
    scenario: ScenarioOpt = "kitchen",
    as_json: Annotated[bool, typer.Option("--json", help="Print the rules as JSON.")] = False,
) -> None:
    """List the Unsafe State Concepts with their definitions and annotations."""
    from dataclasses import asdict

    from virf.ontology.tbox import load_tbox

    try:
        vocab = load_tbox(scenario).vocabulary
    except VirfError as exc:
        raise _fail_for(exc) from None
    rules = sorted(vocab.uscs.values(), key=lambda u: (u.module, u.id))
    if as_json:
        typer.echo(json.dumps([asdict(u) for u in rules], indent=2))
        return
    for u in rules:
        typer.echo(f"{u.id}  [{u.kind}; {u.category}; {u.danger_level}; checked: {u.check_at}]")
        typer.echo(f"    {u.definition}")
        typer.echo(f"    {u.description}")
        typer.echo(f"    source: {u.source}")


@scene_app.command("safeagentbench")
def scene_safeagentbench(
    file: Annotated[Path, typer.Argument(help="A SafeAgentBench JSONL file.")],
    line: Annotated[int, typer.Argument(help="1-based line of the task in FILE.")],
) -> None:
    """Print the scene ABox (the paper's JSON) VIRF builds for one task."""
    from virf.bench.safeagentbench import build_scene, task_at
    from virf.ontology.tbox import load_tbox

    try:
        vocab = load_tbox().vocabulary
        task = task_at(file, line)
        typer.echo(json.dumps(build_scene(task, vocab), indent=2))
    except VirfError as exc:
        raise _fail_for(exc) from None


@scene_app.command("show")
def scene_show(
    scene: Annotated[Path, typer.Argument(help="Scene ABox JSON file.")],
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the canonical world as one JSON object.")
    ] = False,
    scenario: ScenarioOpt = "kitchen",
) -> None:
    """Show how VIRF understood SCENE: the one canonical world it verifies against.

    Every object with its types, states, materials and relations; what came from
    the scene, from a catalogue default or from an open-world assumption; and how
    the scene wrote what was rewritten (a state individual, an inverse relation,
    a material class)."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from virf.ontology.tbox import load_tbox
    from virf.world.scene import describe_scene, load_scene_file

    try:
        world = describe_scene(load_scene_file(scene, load_tbox(scenario).vocabulary))
    except EnvironmentProblem as exc:
        raise _fail(str(exc), EXIT["ERROR"]) from None
    except VirfError as exc:
        raise _fail(str(exc)) from None
    if as_json:
        typer.echo(json.dumps(world, indent=2, sort_keys=True))
        return

    def cell(entries: list[dict[str, str]], relation: bool = False) -> str:
        out = []
        for e in entries:
            text = f"{e['relation']} {e['value']}" if relation else e["value"]
            if e["from"] != "scene":
                text += f" ({e['from']})"
            out.append(text)
        return "\n".join(out)

    console = Console(highlight=False, width=150)
    table = Table(title=f"Scene {escape(world['name'])}: the canonical world")
    for col in ("object", "types", "states", "materials", "relations"):
        table.add_column(col)
    rewritten: list[str] = []
    for name, obj in world["objects"].items():
        label = name + (" (agent)" if name == world["agent"] else "")
        table.add_row(
            label,
            ", ".join(obj["types"]),
            cell(obj["states"]),
            cell(obj["materials"] + obj["properties"]),
            cell(obj["relations"], relation=True),
        )
        for e in obj["states"] + obj["materials"] + obj["properties"] + obj["relations"]:
            if "written" in e:
                rewritten.append(f"{e['written']}  ->  {e['canonical']}")
    console.print(table)
    lines = [
        "closed world: " + (", ".join(world["closed_world"]) or "none (contents are open)"),
        f"objects start located: {'no' if world['unlocated_by_default'] else 'yes'}",
    ]
    if world["unknown_contents"]:
        lines.append("contents unknown: " + ", ".join(world["unknown_contents"]))
    if world["referents"]:
        lines.append(
            "referents: " + ", ".join(f"{k} -> {v}" for k, v in world["referents"].items())
        )
    if world["open_world_markers"]:
        lines.append("open-world markers: " + "; ".join(world["open_world_markers"]))
    if rewritten:
        lines.append("rewritten as the canonical form:")
        lines += [f"  {r}" for r in rewritten]
    console.print("\n".join(lines), markup=False)


@bench_app.command("safeagentbench")
def bench_safeagentbench(
    files: Annotated[
        list[Path], typer.Argument(help="SafeAgentBench JSONL files (any split, any room).")
    ],
    as_json: Annotated[
        bool, typer.Option("--json", help="One JSON object per task, then a summary object.")
    ] = False,
    plans: Annotated[
        Path | None,
        typer.Option(help="JSONL of plans for tasks that ship none: {file, line, plan: [...]}."),
    ] = None,
    corrections: Annotated[
        Path | None, typer.Option(help="Label-corrections JSON (default: the bundled file).")
    ] = None,
    no_corrections: Annotated[
        bool, typer.Option("--no-corrections", help="Report raw labels only.")
    ] = False,
    markdown: Annotated[
        Path | None, typer.Option(help="Also write the Markdown report to this path.")
    ] = None,
    explain: Annotated[
        bool, typer.Option(help="Compute minimal explanations too (slower; verdicts are the same).")
    ] = False,
    engine: EngineOpt = "fast",
) -> None:
    """Verify every task's reference plan and print hazard recall, false alarms and fidelity."""
    from rich.console import Console

    from virf.api import LogicTutor
    from virf.bench.report import render_markdown
    from virf.bench.runner import (
        default_corrections_path,
        load_corrections,
        load_plans,
        run_benchmark,
        summarize,
    )
    from virf.bench.safeagentbench import load_tasks
    from virf.verify.verifier import Verifier

    try:
        tasks = [t for f in files for t in load_tasks(f)]
        if not tasks:
            raise VirfError(f"no tasks in {', '.join(str(f) for f in files)}")
        plan_map = load_plans(plans)
        known = {(t.file, t.line) for t in tasks}
        stray = sorted(k for k in plan_map if k not in known)
        if stray:
            raise VirfError(
                f"--plans names a task that is not among the files: {stray[0][0]} line {stray[0][1]}"
            )
        corr = {} if no_corrections else load_corrections(corrections or default_corrections_path())
        if markdown is not None:
            _check_writable(markdown)
        tutor = LogicTutor(engine=engine)
    except EnvironmentProblem as exc:
        raise _fail(str(exc), EXIT["ERROR"]) from None
    except VirfError as exc:
        raise _fail(str(exc)) from None
    verifier = Verifier(tutor.tbox, tutor.engine, explain=explain)
    err = Console(stderr=True)
    with _progress(err) as progress:
        bar = progress.add_task("verifying tasks", total=len(tasks))

        def tick(result: object) -> None:
            progress.advance(bar)
            if as_json:
                typer.echo(json.dumps(result.public(), sort_keys=True))  # type: ignore[attr-defined]

        results = run_benchmark(files, verifier, plan_map, corr, on_task=tick, tasks=tasks)
    summary = summarize(results)
    if as_json:
        typer.echo(json.dumps(summary, sort_keys=True))
    else:
        _print_bench(results, summary)
    if markdown:
        # The command as typed, so the report says how to regenerate it.
        command = " ".join(["virf", *sys.argv[1:]])
        text = render_markdown(results, summary, corr, command, tutor.engine.name, explain)
        tmp = markdown.with_name(markdown.name + ".tmp")
        try:
            tmp.write_text(text, encoding="utf-8")
            tmp.replace(markdown)  # no half-written report on failure
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise _fail(f"cannot write {markdown}: {exc.strerror}") from None
        err.print(f"wrote {markdown}")


@bench_app.command("latency")
def bench_latency(
    files: Annotated[
        list[Path],
        typer.Argument(help="SafeAgentBench JSONL files whose reference plans are timed."),
    ],
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object with every figure.")
    ] = False,
    repeats: Annotated[
        int, typer.Option(min=1, help="Fast-engine runs per plan (the median counts).")
    ] = 3,
    reference_sample: Annotated[
        int,
        typer.Option(min=0, help="Time the reference engine on this many plans (0 = all)."),
    ] = 0,
    paper_sample: Annotated[
        int,
        typer.Option(
            min=0, help="Time the paper's method on this many plans (0 = all; ~5 s per step)."
        ),
    ] = 20,
    paper_max_objects: Annotated[
        int, typer.Option(min=0, help="Largest synthetic scene the paper's method is timed on.")
    ] = 200,
    no_paper: Annotated[
        bool, typer.Option("--no-paper", help="Skip the paper's method (needs .venv-paper).")
    ] = False,
    sizes: Annotated[
        str, typer.Option(help="Synthetic scene sizes (objects), comma-separated.")
    ] = "20,50,200,1000",
    lengths: Annotated[
        str, typer.Option(help="Synthetic plan lengths (multiples of 10 steps), comma-separated.")
    ] = "10,20,40,80",
    tbox_factors: Annotated[
        str,
        typer.Option(help="TBox sizes to time, as multiples of the kitchen TBox, comma-separated."),
    ] = "1,4",
    markdown: Annotated[
        Path | None, typer.Option(help="Also write the figures as Markdown (docs/performance.md).")
    ] = None,
) -> None:
    """Time the paper's method, the reference engine and the fast engine on the same plans."""
    from rich.console import Console

    from virf.bench.latency import run_latency
    from virf.world.plan import MAX_PLAN_STEPS
    from virf.world.scene import MAX_INSTANCES

    try:
        for f in files:
            if not f.is_file():
                raise VirfError(f"no such file: {f}")
        try:
            size_list = [int(x) for x in sizes.split(",") if x.strip()]
        except ValueError:
            raise VirfError(f"--sizes '{sizes}': give whole numbers, e.g. 20,50,200") from None
        if not size_list or min(size_list) < 10 or max(size_list) > MAX_INSTANCES:
            raise VirfError(
                f"--sizes '{sizes}': every size must be at least 10 objects and at most "
                f"{MAX_INSTANCES} (the scene limit)"
            )
        try:
            factors = [int(x) for x in tbox_factors.split(",") if x.strip()]
        except ValueError:
            raise VirfError(
                f"--tbox-factors '{tbox_factors}': give whole numbers, e.g. 1,4"
            ) from None
        if not factors or min(factors) < 1 or max(factors) > 16:
            raise VirfError(f"--tbox-factors '{tbox_factors}': each factor must be 1 to 16")
        try:
            length_list = [int(x) for x in lengths.split(",") if x.strip()]
        except ValueError:
            raise VirfError(f"--lengths '{lengths}': give whole numbers, e.g. 10,20,40") from None
        if not length_list or any(n < 10 or n % 10 or n > MAX_PLAN_STEPS for n in length_list):
            raise VirfError(
                f"--lengths '{lengths}': each length must be a multiple of 10 steps, "
                f"at most {MAX_PLAN_STEPS} (the plan limit)"
            )
        if markdown is not None:
            _check_writable(markdown)
        err = Console(stderr=True)
        with _progress(err) as progress:

            def bar(label: str, total: int) -> Any:
                task = progress.add_task(label, total=total)
                return lambda: progress.advance(task)

            figures = run_latency(
                [str(f) for f in files],
                repeats=repeats,
                reference_sample=reference_sample,
                paper_sample=paper_sample,
                paper=not no_paper,
                sizes=size_list,
                paper_max_objects=paper_max_objects,
                tbox_factors=factors,
                lengths=length_list,
                progress=bar,
            )
    except EnvironmentProblem as exc:
        raise _fail(str(exc), EXIT["ERROR"]) from None
    except VirfError as exc:
        raise _fail(str(exc)) from None
    if as_json:
        typer.echo(json.dumps(figures, sort_keys=True))
    else:
        _print_latency(figures)
    if markdown:
        from virf.bench.latency import render_markdown

        _write_atomically(markdown, render_markdown(figures, " ".join(["virf", *sys.argv[1:]])))


def _print_latency(fig: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(highlight=False, width=140)
    m = fig["machine"]
    console.print(
        f"machine: {m['cpus']} CPUs, Python {m['python']}, Java {m['java']}, {m['platform']}"
    )
    table = Table(title=f"Per-plan verification latency ({fig['plans']} SafeAgentBench plans)")
    for col in ("method", "plans", "p50 ms", "p95 ms", "mean ms", "note"):
        table.add_column(col)
    paper = fig.get("paper")
    if paper:
        table.add_row(
            "(a) paper: owlready2 + Pellet per step",
            str(paper["plans"]),
            f"{paper['p50_ms']:.0f}",
            f"{paper['p95_ms']:.0f}",
            f"{paper['mean_ms']:.0f}",
            f"per call p50 {paper['per_call_p50_ms']:.0f} ms; owlready2 {paper['owlready2']}",
        )
    ref, fast = fig["reference"], fig["fast"]
    table.add_row(
        "(b) reference engine (HermiT)",
        str(ref["plans"]),
        f"{ref['p50_ms']:.0f}",
        f"{ref['p95_ms']:.0f}",
        f"{ref['mean_ms']:.0f}",
        "with minimal explanations",
    )
    table.add_row(
        "(c) fast engine",
        str(fig["plans"]),
        f"{fast['p50_ms']:.1f}",
        f"{fast['p95_ms']:.1f}",
        f"{fast['mean_ms']:.1f}",
        f"{fast['reasoner_calls']} calls, {fast['fallbacks']} fallbacks",
    )
    console.print(table)
    same = fig["identical_reports"]
    ratio = fig.get("ratio")
    console.print(
        f"ratio a/c (median over plans): {ratio if ratio is not None else 'n/a'}; "
        f"reports identical (b vs c): {same['identical']}/{same['compared']}"
    )
    mem = fig["memory"]
    console.print(
        f"memory: process RSS {mem['process_rss_after_tbox_mb']:.0f} MB after TBox load, "
        f"peak {mem['process_rss_peak_after_fast_mb']:.0f} MB after (c), "
        f"{mem['process_rss_peak_after_reference_mb']:.0f} MB after (b); "
        f"fast engine Python heap peak {mem['fast_python_heap_peak_mb']:.1f} MB"
        + (f"; paper method peak {paper['peak_rss_mb']} MB" if paper else "")
    )
    for key, title, per in (
        ("scene_scaling", "Scaling with scene size (10-step plan)", "objects"),
        ("length_scaling", "Scaling with plan length (50-object scene)", "steps"),
    ):
        scale = Table(title=title)
        for col in (
            per,
            "verdict",
            "fast ms",
            f"fast ms/{per.rstrip('s')}",
            "reference ms",
            "reference, 2 workers",
            "paper ms",
            "same",
        ):
            scale.add_column(col)
        for row in fig[key]:
            paper_ms = row.get("paper_ms")
            size = row["requested_objects"] if per == "objects" else row["steps"]
            scale.add_row(
                str(size),
                row["status"],
                f"{row['fast_ms']:.1f}",
                f"{row['fast_ms'] / size:.3f}",
                f"{row['reference_ms']:.0f}",
                f"{row['reference_2_workers_ms']:.0f}",
                "-" if paper_ms is None else f"{paper_ms:.0f}",
                "yes" if row["identical"] else "NO",
            )
        console.print(scale)
    tb = Table(title="Scaling with TBox size (50-object scene, 10-step plan)")
    for col in ("TBox", "logical axioms", "fast ms", "reference ms", "same"):
        tb.add_column(col)
    for row in fig["tbox_scaling"]:
        tb.add_row(
            f"x{row['factor']}",
            str(row["logical_axioms"]),
            f"{row['fast_ms']:.1f}",
            f"{row['reference_ms']:.0f}",
            "yes" if row["identical"] else "NO",
        )
    console.print(tb)
    from virf.bench.latency import chain_markdown

    # The containment-chain and deadline figures, as the Markdown report has them.
    for line in chain_markdown(fig):
        console.print(line, markup=False)


def _write_atomically(path: Path, text: str) -> None:
    """No half-written file on failure."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise _fail(f"cannot write {path}: {exc.strerror}") from None
    typer.echo(f"wrote {path}", err=True)


def _progress(console: Any) -> Any:
    """The progress bar of long runs, on stderr, only when it is a terminal."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        disable=not console.is_terminal,
    )


def _check_writable(path: Path) -> None:
    """Fail before a long run, not after it, when the report cannot be written."""
    if path.is_dir():
        raise VirfError(f"--markdown {path} is a directory; give a file path")
    if not path.parent.is_dir():
        raise VirfError(f"--markdown {path}: folder {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK):
        raise VirfError(f"--markdown {path}: folder {path.parent} is not writable")


def _print_bench(results: list[Any], summary: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console(highlight=False, width=160)
    table = Table(title="SafeAgentBench: reference plans")
    for col in ("task", "label", "verdict", "step", "rule", "goal", "ms", "instruction"):
        table.add_column(col)
    for r in results:
        label = r.label if r.corrected_label == r.label else f"{r.label}->{r.corrected_label}"
        table.add_row(
            escape(f"{r.file}:{r.line}"),
            label,
            r.status or "-",
            "-" if r.dangerous_step is None else str(r.dangerous_step),
            r.violated_concept or "-",
            {True: "met", False: "NOT met", None: "-"}[r.goal_satisfied],
            f"{r.time_ms:.0f}",
            escape(r.instruction[:60]),
        )
    console.print(table)
    figs = Table(title="Figures")
    for col in ("figure", "raw", "corrected"):
        figs.add_column(col)

    def pct(x: float | None) -> str:
        return "n/a" if x is None else f"{100 * x:.1f}%"

    raw, cor = summary["raw"], summary["corrected"]
    figs.add_row(
        "hazard recall",
        f"{pct(raw['hazard_recall'])} ({raw['detected']}/{raw['unsafe_tasks']})",
        f"{pct(cor['hazard_recall'])} ({cor['detected']}/{cor['unsafe_tasks']})",
    )
    figs.add_row(
        "false-alarm rate",
        f"{pct(raw['false_alarm_rate'])} ({raw['false_alarms']}/{raw['safe_tasks']})",
        f"{pct(cor['false_alarm_rate'])} ({cor['false_alarms']}/{cor['safe_tasks']})",
    )
    figs.add_row("fidelity (safe tasks)", pct(raw["fidelity_safe"]), pct(cor["fidelity_safe"]))
    figs.add_row("fidelity (all tasks)", pct(raw["fidelity_all"]), pct(cor["fidelity_all"]))
    figs.add_row(
        "time per task", f"p50 {summary['time_ms_p50']} ms, p95 {summary['time_ms_p95']} ms", ""
    )
    figs.add_row(
        "requirements parsed", f"{summary['requirements_parsed']}/{summary['requirements']}", ""
    )
    console.print(figs)
    cats = Table(title="Recall per risk category (raw / corrected)")
    for col in ("category", "raw", "corrected"):
        cats.add_column(col)
    for cat in sorted(set(raw["recall_per_category"]) | set(cor["recall_per_category"])):
        a, b = raw["recall_per_category"].get(cat), cor["recall_per_category"].get(cat)
        cats.add_row(
            cat,
            f"{a['detected']}/{a['unsafe']}" if a else "-",
            f"{b['detected']}/{b['unsafe']}" if b else "-",
        )
    console.print(cats)


@bench_app.command("agents")
def bench_agents(
    method: Annotated[
        list[str],
        typer.Option(
            "--method",
            "-m",
            help="Planning method(s), comma-separated or repeated: impulsive, thinker, committee, "
            "impulsive+rules, thinker+rules, thinker+diagnostic, virf-reject, virf-rag, "
            "virf-manual, virf.",
        ),
    ],
    planner: Annotated[
        str,
        typer.Option(
            "--planner", "-p", help="openai:MODEL (any OpenAI-compatible server) or replay:FILE."
        ),
    ],
    tasks: Annotated[
        list[Path],
        typer.Option("--tasks", help="SafeAgentBench JSONL file(s); more may follow as arguments."),
    ],
    more_tasks: Annotated[
        list[Path] | None, typer.Argument(help="More task files (after --tasks FILE).")
    ] = None,
    critic: Annotated[
        str | None,
        typer.Option(
            help="The committee's critic, as a planner spec (default: the planner itself)."
        ),
    ] = None,
    max_iter: Annotated[int, typer.Option(min=1, help="Refinement iterations (N_max).")] = 5,
    answers: Annotated[
        Path | None,
        typer.Option(help="JSON answers to the tutor's questions ({key: answer}); default: none."),
    ] = None,
    db: Annotated[
        Path | None,
        typer.Option(help="SQLite results (and run log) file; default OUT/results.sqlite."),
    ] = None,
    out: Annotated[
        Path, typer.Option(help="Folder for agents.md, agents.csv, har_gcr.png, fpr_fnr.png.")
    ] = Path("runs/agents"),
    limit: Annotated[
        int | None, typer.Option(min=1, help="Only the first N tasks (quick runs).")
    ] = None,
    base_url: BaseUrlOpt = None,
    api_key_env: ApiKeyEnvOpt = None,
    temperature: TemperatureOpt = None,
    top_p: TopPOpt = None,
    max_tokens: MaxTokensOpt = None,
    timeout: ModelTimeoutOpt = None,
    seed: SeedOpt = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object: metrics and per-task rows.")
    ] = False,
) -> None:
    """Run planning methods over SafeAgentBench tasks; HAR, GCR, FPR, FNR, RI, VL per method.

    Results go to SQLite; a rerun with the same settings resumes.  Exit 0 when
    done, 2 on bad input, 4 when the model cannot be reached.
    """
    from rich.console import Console

    from virf.api import LogicTutor
    from virf.bench.agents import AgentConfig, Harness, ResultStore, check_task_ids
    from virf.bench.agents_report import check_out_dir, collect, write_outputs
    from virf.bench.safeagentbench import load_tasks
    from virf.errors import InputError
    from virf.planner import make_apprentice
    from virf.planner.methods import METHODS, get_method
    from virf.planner.questions import answers_file, deny

    err = Console(stderr=True)
    closing: list[Any] = []
    try:
        names = [n.strip() for m in method for n in m.split(",") if n.strip()]
        if not names:
            raise InputError(f"--method names no method; choose from {', '.join(METHODS)}")
        methods = list(dict.fromkeys(get_method(n) for n in names))
        files = [*tasks, *(more_tasks or [])]
        task_list = [t for f in files for t in load_tasks(f)]
        if not task_list:
            raise InputError(f"no tasks in {', '.join(str(f) for f in files)}")
        check_task_ids(task_list)
        task_list = task_list[:limit] if limit is not None else task_list
        check_out_dir(out)
        db_path = db if db is not None else out / "results.sqlite"
        if db_path.is_dir():
            raise InputError(f"--db {db_path} is a directory; give a file path")
        policy = answers_file(answers) if answers is not None else deny
        # Models and recordings are checked before the knowledge base loads.
        sampling: dict[str, Any] = {
            k: v
            for k, v in {
                "temperature": temperature,
                "top_p": top_p,
                "max_tokens": max_tokens,
                "timeout_s": timeout,
                "seed": seed,
            }.items()
            if v is not None
        }
        apprentice = make_apprentice(
            planner, base_url=base_url, api_key_env=api_key_env, **sampling
        )
        closing.append(apprentice)
        judge = None
        if critic is not None:
            judge = make_apprentice(critic, base_url=base_url, api_key_env=api_key_env, **sampling)
            closing.append(judge)
        config = AgentConfig.build(
            planner,
            critic=critic,
            base_url=base_url,
            max_iter=max_iter,
            answers=answers,
            sampling=sampling,
        )
        tutor = LogicTutor(engine=config.engine)
        if db is None:
            out.mkdir(parents=True, exist_ok=True)
        store = ResultStore(db_path, config)
        closing.append(store)
        apprentice.run_log = store
        if judge is not None:
            judge.run_log = store
        harness = Harness(tutor, apprentice, store, critic=judge, answer=policy)
        stored = 0
        with _progress(err) as progress:
            bar = progress.add_task("planning", total=len(methods) * len(task_list))

            def tick(row: Any, resumed: bool) -> None:
                nonlocal stored
                stored += resumed
                progress.update(bar, advance=1, description=f"{row.method} {row.task_id}")

            try:
                harness.run(methods, task_list, on_row=tick)
            except KeyboardInterrupt:
                err.print(
                    f"interrupted: finished rows are stored in {db_path}; "
                    "run the same command again to resume"
                )
                raise typer.Exit(130) from None
        table = collect(store, task_list)
        settings = [
            ("planner", planner),
            ("critic (committee)", critic or "the planner itself"),
            ("max iterations", str(max_iter)),
            ("answers", str(answers) if answers is not None else "none (questions stay open)"),
            ("hazard check", "every Unsafe State Concept, fast engine"),
            ("configuration", config.id),
        ]
        written = write_outputs(table, out, settings, " ".join(["virf", *sys.argv[1:]]))
    except EnvironmentProblem as exc:
        raise _fail(str(exc), EXIT["ERROR"]) from None
    except VirfError as exc:
        raise _fail(str(exc)) from None
    finally:
        for thing in reversed(closing):
            thing.close()
    if stored:
        err.print(f"{stored} row(s) were already in {db_path} and were not run again")
    if as_json:
        payload = {"config_id": config.id, "config": config.to_dict(), **table.public()}
        payload["files"] = [str(p) for p in written]
        typer.echo(json.dumps(payload, sort_keys=True))
    else:
        _print_agents(table)
    for p in written:
        err.print(f"wrote {p}")


def _print_agents(table: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    from virf.bench.agents_report import MASTER_HEADER, master_rows

    console = Console(highlight=False, width=150)
    view = Table(title=f"Agent evaluation ({len(table.tasks)} tasks)")
    for col in MASTER_HEADER:
        view.add_column(col)
    for row in master_rows(table):
        view.add_row(*row)
    console.print(view)
    for name, n in table.partial.items():
        console.print(f"left out: {name} (stored for {n}/{len(table.tasks)} of these tasks)")


def main() -> None:
    try:
        code = app(standalone_mode=False)
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        sys.exit(130)
    except Exception as exc:
        # Errors before a command runs (the root's own options, no command at
        # all) and anything the root group let through take the same road.
        ending = _exit_for(exc)
        if isinstance(ending, typer.Exit):
            sys.exit(ending.exit_code)
        if "Abort" in {c.__name__ for c in type(ending).__mro__}:
            typer.echo("interrupted", err=True)
            sys.exit(130)
        exit_code = getattr(ending, "exit_code", EXIT["ERROR"])
        sys.exit(exit_code if isinstance(exit_code, int) else EXIT["ERROR"])
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
