"""``virf verify`` and ``virf demo``: one plan, or every example folder."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from virf.cli.app import EXIT, EngineOpt, KbOpt, ScenarioOpt, _fail, loaded
from virf.cli.learning import (
    LearnOpt,
    StrictVocabularyOpt,
    WhoOpt,
    learn_lines,
    learning_kb,
    open_workspace,
    warn_unused,
    who_of,
)
from virf.errors import VirfError

if TYPE_CHECKING:
    from virf.schema import Report

# The render and world modules are imported inside the commands: `virf --help`
# stays fast, and tests can replace what a command calls.


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
    scenario: ScenarioOpt = None,
    engine: EngineOpt = "fast",
    kb: KbOpt = None,
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
    answers: Annotated[
        Path | None,
        typer.Option(
            "--answers",
            help="JSON answers to the report's questions ({key: answer}, as 'virf plan' reads): "
            "the scene is updated with them and the plan verified again.",
        ),
    ] = None,
    learn: LearnOpt = None,
    who: WhoOpt = None,
    strict_vocabulary: StrictVocabularyOpt = False,
) -> None:
    """Verify PLAN in SCENE.  Exit 0 SAFE, 1 UNSAFE, 3 UNKNOWN, 4 ERROR, 2 bad input.

    With --answers, the answers settle the report's questions and the plan is
    verified again (while they settle new ones); the last report is printed.
    With --learn, what they confirm about objects of classes the knowledge base
    lacks becomes candidate classes in that workspace, for a person to review."""
    from virf.api import LogicTutor, check_timeout
    from virf.render.text import render_report
    from virf.world.plan import load_plan_file
    from virf.world.scene import build_scene, load_scene_data

    # The options and the plan are checked before the knowledge base loads.
    check_timeout(timeout, "--timeout")
    if learn is not None and answers is None:
        raise VirfError("--learn needs --answers FILE: what is learned is what the answers confirm")
    if who is not None and learn is None:
        raise VirfError("--who names who answered, for --learn; give --learn WORKSPACE too")
    kb = learning_kb(kb, learn)
    who = who_of(who)
    steps = load_plan_file(plan)
    given = None
    if answers is not None:
        from virf.planner.questions import read_answers

        given = read_answers(answers)
    workspace = open_workspace(learn) if learn is not None else None
    tutor = LogicTutor(scenario=scenario, engine=engine, timeout_s=timeout, workers=workers, kb=kb)
    loaded()
    vocab = tutor.tbox.vocabulary
    data = load_scene_data(scene)
    name = scene.stem if scene.stem != "scene" else scene.parent.name

    def check(d: Any) -> Report:
        sc = build_scene(d, vocab, name=name, strict_vocabulary=strict_vocabulary)
        return tutor.verifier.verify(sc, steps)

    learned: list[str] = []
    if given is None:
        report = check(data)
    else:
        from virf.planner.questions import settle

        settled = settle(data, check, given, vocab)
        report = settled.report
        for key in settled.unused(given):
            warn_unused(key, settled.asked)
        if workspace is not None:
            learned = learn_lines(
                workspace, name, data, [s.text for s in steps], settled.answered, who, learn
            )
    if as_json:
        typer.echo(report.to_json())
    else:
        typer.echo(render_report(report, title=f"{scene} + {plan}"), nl=False)
        if feedback and report.status != "SAFE":
            # Only here: the module reads its template file when imported.
            from virf.render.feedback import feedback_prompt

            typer.echo("\n" + feedback_prompt(report), nl=False)
    for line in learned:
        typer.echo(line, err=True)
    raise typer.Exit(EXIT[report.status])


def demo(
    folder: Annotated[
        Path | None,
        typer.Argument(
            help="Folder of examples: one sub-folder per scene.json + plan.txt.",
            show_default="./examples if there is one, else the examples VIRF ships",
        ),
    ] = None,
    engine: EngineOpt = "fast",
    kb: KbOpt = None,
) -> None:
    """Verify every example and print the reports; checks each against its expected.json."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from virf.api import LogicTutor
    from virf.bundled import bundled_examples
    from virf.errors import read_json_file
    from virf.render.text import render_report

    if folder is None:
        # ./examples first, as before the examples were shipped; an installed
        # VIRF run from any other folder still has its own.
        here = Path("examples")
        folder = here if here.is_dir() else bundled_examples() or here
    cases = sorted(p.parent for p in folder.glob("*/plan.txt")) if folder.is_dir() else []
    if not cases:
        raise _fail(f"no examples in {folder} (expected <name>/scene.json and <name>/plan.txt)")
    # An example may name the scenario it reproduces (the paper's examples run
    # on the paper's rules); with --kb every example uses the workspace.
    tutors: dict[str | None, LogicTutor] = {}

    def tutor_for(expected: dict[str, Any]) -> LogicTutor:
        scenario = None if kb is not None else expected.get("scenario")
        if scenario is not None and not isinstance(scenario, str):
            raise VirfError("expected.json: 'scenario' must be a scenario name")
        if scenario not in tutors:
            tutors[scenario] = LogicTutor(scenario=scenario, engine=engine, kb=kb)
        return tutors[scenario]

    tutor_for({})  # a bad --engine or --kb fails here, before any example
    console = Console(highlight=False, width=150)
    # Not a shared TextTable: the mismatch cell is red, and no Markdown twin exists.
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
            report = tutor_for(expected).verify_files(case / "scene.json", case / "plan.txt")
        except VirfError as exc:
            # One broken example is a mismatch, not the end of the demo.
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
