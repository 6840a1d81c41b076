"""``virf plan``: the apprentice plans, the tutor verifies, until a plan is approved."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from virf.cli.app import (
    ApiKeyEnvOpt,
    BaseUrlOpt,
    ConstrainOpt,
    EngineOpt,
    KbOpt,
    MaxTokensOpt,
    SeedOpt,
    TemperatureOpt,
    TopPOpt,
    check_writable,
    write_output,
)
from virf.cli.learning import (
    LearnOpt,
    StrictVocabularyOpt,
    WhoOpt,
    learn_lines,
    learning_kb,
    open_workspace,
    who_of,
)
from virf.cli.perceive import (
    BboxUnitsOpt,
    DetectionsOpt,
    OpenContentsOpt,
    ThresholdOpt,
    run_perception,
)
from virf.errors import VirfError


def plan(
    instruction: Annotated[str, typer.Option("--instruction", "-i", help="What the user asks.")],
    planner: Annotated[
        str,
        typer.Option(
            "--planner",
            "-p",
            help="openai:MODEL (any OpenAI-compatible server), local:smollm2-135m or "
            "local:PATH.gguf (in-process, after make local-llm) or replay:FILE (a recorded run).",
        ),
    ],
    scene: Annotated[
        Path | None,
        typer.Option("--scene", help="Scene ABox JSON file (or perceive one with --images)."),
    ] = None,
    base_url: BaseUrlOpt = None,
    api_key_env: ApiKeyEnvOpt = None,
    temperature: TemperatureOpt = None,
    seed: SeedOpt = None,
    top_p: TopPOpt = None,
    max_tokens: MaxTokensOpt = None,
    constrain: ConstrainOpt = None,
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
    log: Annotated[
        str | None,
        typer.Option(help="Run log of every model call: a SQLite file or a postgresql:// URL."),
    ] = None,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json", help="Print one JSON object: outcome, plan, iterations, transcript."
        ),
    ] = False,
    engine: EngineOpt = "fast",
    kb: KbOpt = None,
    images: Annotated[
        list[Path] | None,
        typer.Option(
            "--images",
            help="Camera images to perceive the scene from, instead of --scene (repeat the "
            "option for several views); needs --vlm.",
        ),
    ] = None,
    vlm: Annotated[
        str | None,
        typer.Option(
            "--vlm",
            help="Vision model for --images: openai:MODEL or replay:FILE. --base-url and "
            "--api-key-env apply to it too.",
        ),
    ] = None,
    detections: DetectionsOpt = None,
    threshold: ThresholdOpt = 0.5,
    open_contents: OpenContentsOpt = False,
    bbox_units: BboxUnitsOpt = "pixels",
    scene_out: Annotated[
        Path | None,
        typer.Option("--scene-out", help="With --images: write the perceived scene here."),
    ] = None,
    learn: LearnOpt = None,
    who: WhoOpt = None,
    strict_vocabulary: StrictVocabularyOpt = False,
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
    from virf.world.scene import build_scene, load_scene_data

    if (scene is None) == (not images):
        raise VirfError("give the scene as --scene FILE or as --images IMAGE... (one of them)")
    if images and vlm is None:
        raise VirfError("--images needs a vision model: --vlm openai:MODEL or --vlm replay:FILE")
    if not images:
        for given, option in (
            (vlm, "--vlm"),
            (detections, "--detections"),
            (scene_out, "--scene-out"),
        ):
            if given is not None:
                raise VirfError(f"{option} is for camera images: give them with --images")
    if not instruction.strip():
        raise VirfError("--instruction is empty; say what the robot should do")
    chosen = get_method(method)
    if scene_out is not None:
        check_writable(scene_out, "--scene-out")
    if who is not None and learn is None:
        raise VirfError("--who names who answered, for --learn; give --learn WORKSPACE too")
    kb = learning_kb(kb, learn)
    who = who_of(who)
    workspace = open_workspace(learn) if learn is not None else None
    run_log: Any = None
    try:
        # Started first: the deadline bounds the whole run, loading included.
        clock = Deadline(run_deadline(deadline))
        tutor = LogicTutor(engine=engine, kb=kb)
        vocab = tutor.tbox.vocabulary
        if scene is not None:
            data = load_scene_data(scene)
            # Bad scenes fail here, before any model call.
            build_scene(data, vocab, strict_vocabulary=strict_vocabulary)
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
            constrain=constrain,
        )
        if chosen.knowledge != "all":
            tutor = tutor.restricted(
                {u.name for u in vocab.uscs.values() if knowledge_filter(u, chosen.knowledge)}
            )
        with apprentice:
            if images:
                assert vlm is not None
                # Every other input was checked first: a vision model's calls
                # cost money.  Uncertain readings become the tutor's questions,
                # asked like any other (Algorithm 1); the answers update this scene.
                data = run_perception(
                    images,
                    vlm,
                    vocab,
                    run_log=run_log,
                    detections=detections,
                    threshold=threshold,
                    open_contents=open_contents,
                    bbox_units=bbox_units,
                    deadline=clock,
                    base_url=base_url,
                    api_key_env=api_key_env,
                    timeout_s=timeout,
                ).scene
                if scene_out is not None:
                    write_output(scene_out, json.dumps(data, indent=2, ensure_ascii=False) + "\n")
            name = scene.stem if scene is not None else "perceived"
            result = run_method(
                chosen,
                instruction,
                data,
                apprentice,
                tutor.verifier,
                lambda d: build_scene(d, vocab, name=name, strict_vocabulary=strict_vocabulary),
                vocab,
                max_iter=max_iter,
                answer=policy,
                task_id=task_id,
                deadline=clock,
            )
    finally:
        if run_log is not None:
            run_log.close()
    learned: list[str] = []
    if workspace is not None:
        from virf.authoring.learn import answered_from_transcript

        answered, asked_about = answered_from_transcript(result.transcript, vocab)
        learned = learn_lines(workspace, name, data, asked_about, answered, who, learn)
    if as_json:
        typer.echo(result.to_json())
    else:
        _print_dialogue(result)
        if result.outcome == "APPROVED_UNVERIFIED":
            typer.echo(
                f"Not verified: the method '{chosen.name}' did not have the Logic Tutor "
                "check this plan (exit 5)."
            )
    for line in learned:
        typer.echo(line, err=True)
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

    from virf.render.text import render_report
    from virf.schema import Report

    console = Console(highlight=False, width=110)
    for t in result.transcript:
        label = f"iteration {t.iteration} · {t.speaker} · {t.kind}"
        if t.status:
            label += f" · {t.status}"
        chose = (t.data or {}).get("chose") if t.kind == "proposal" else None
        if chose is not None:
            label += f" · took correction {chose}"
        away = (t.data or {}).get("turned_away", []) if t.kind == "proposal" else []
        console.print(Rule(label, align="left"))
        if t.kind == "report" and t.data:
            console.print(render_report(Report.model_validate(t.data)).rstrip(), markup=False)
        else:
            console.print(t.text, markup=False)
        if away:
            # Written a line at a time, the tutor refused these on the way.
            console.print(f"(turned away as it was written: {'; '.join(away)})", markup=False)
    console.print(Rule())
    console.print(
        f"{result.outcome} after {result.iterations} iteration(s): {result.reason}", markup=False
    )
    if result.plan:
        console.print("\n".join(result.plan), markup=False)
