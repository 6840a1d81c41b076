"""``virf bench``: the Logic Tutor on SafeAgentBench (hazards, latency, agents)."""

from __future__ import annotations

import json
import sys
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from virf.cli.app import (
    ApiKeyEnvOpt,
    BaseUrlOpt,
    ConstrainOpt,
    EngineOpt,
    KbOpt,
    MaxTokensOpt,
    ModelTimeoutOpt,
    RoomScenarioOpt,
    RoomTutors,
    SeedOpt,
    TemperatureOpt,
    TopPOpt,
    check_writable,
    interrupted,
    progress_bar,
    progress_ticks,
    write_output,
)
from virf.cli.bench_latency import bench_latency
from virf.errors import VirfError
from virf.processes import Terminated

if TYPE_CHECKING:
    from virf.bench.perception import PerceptionRun
    from virf.bench.runner import TaskResult
    from virf.bench.summary import Summary

bench_app = typer.Typer(help="Evaluate the Logic Tutor on benchmarks.", no_args_is_help=True)


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
        Path | None,
        typer.Option(
            help="Label corrections and per-task notes, JSON (default: the bundled file)."
        ),
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
    kb: KbOpt = None,
    scenario: RoomScenarioOpt = "auto",
) -> None:
    """Verify every task's reference plan and print hazard recall, hazard false alarms,
    plans that cannot run (not executable) and fidelity, overall and per room."""
    from rich.console import Console

    from virf.bench.report import render_markdown
    from virf.bench.runner import (
        default_corrections_path,
        load_annotations,
        load_plans,
        match_plans,
        run_benchmark,
    )
    from virf.bench.safeagentbench import Task, load_task_files
    from virf.bench.summary import summarize
    from virf.verify.verifier import Verifier

    tutors = RoomTutors(scenario, kb, explain, engine)
    tasks = load_task_files(files)
    if not tasks:
        raise VirfError(f"no tasks in {', '.join(str(f) for f in files)}")
    plan_map = match_plans(tasks, load_plans(plans))
    corr, notes = load_annotations(corrections or default_corrections_path())
    if no_corrections:
        corr = {}
    if markdown is not None:
        check_writable(markdown, "--markdown")

    def verifier_for(task: Task) -> Verifier:
        return tutors.for_task(task).verifier  # type: ignore[no-any-return]

    # Loaded before the progress bar starts: a bad scenario or workspace fails here.
    tutor = tutors.for_task(tasks[0])
    err = Console(stderr=True)
    with progress_bar(err) as progress:
        bar = progress.add_task("verifying tasks", total=len(tasks))

        def tick(result: TaskResult) -> None:
            progress.advance(bar)
            if as_json:
                typer.echo(json.dumps(result.public(), sort_keys=True))

        try:
            results = run_benchmark(
                files, verifier_for, plan_map, corr, on_task=tick, tasks=tasks, notes=notes
            )
        except (KeyboardInterrupt, Terminated) as exc:
            # The rows printed were computed; the task under way and the rest
            # were not, and a summary of part of the tasks would pass for the whole.
            kept = (
                "the rows printed are the tasks finished before it; no summary was computed"
                if as_json
                else "no report was written"
            )
            raise interrupted(exc, kept) from None
    summary = summarize(results)
    if as_json:
        typer.echo(json.dumps(summary.public(), sort_keys=True))
    else:
        _print_bench(results, summary)
    if markdown:
        # The command as typed, so the report says how to regenerate it.
        command = " ".join(["virf", *sys.argv[1:]])
        text = render_markdown(results, summary, command, tutor.engine.name, explain)
        write_output(markdown, text)
        err.print(f"wrote {markdown}")


bench_app.command("latency")(bench_latency)


def _print_bench(results: list[TaskResult], summary: Summary) -> None:
    from rich.console import Console

    from virf.bench.report import terminal_tables
    from virf.render.tables import to_rich

    console = Console(highlight=False, width=160)
    for table in terminal_tables(results, summary):
        console.print(to_rich(table))


@bench_app.command("service")
def bench_service(
    files: Annotated[
        list[Path],
        typer.Argument(help="SafeAgentBench JSONL files whose reference plans are sent."),
    ],
    concurrency: Annotated[
        str, typer.Option(help="Requests in flight, comma-separated levels.")
    ] = "1,8,32",
    server_workers: Annotated[
        int, typer.Option(min=1, max=64, help="Processes of the virf serve under test.")
    ] = 2,
    rounds: Annotated[
        int, typer.Option(min=1, max=100, help="Times each plan is sent per level.")
    ] = 1,
    as_json: Annotated[bool, typer.Option("--json", help="Print the figures as JSON.")] = False,
    markdown: Annotated[
        Path | None, typer.Option(help="Also write the table as Markdown to this file.")
    ] = None,
) -> None:
    """Throughput and p50/p99 latency of POST /v1/verify against a real virf serve."""
    from rich.console import Console

    from virf.render.tables import to_markdown, to_rich
    from virf.service.bench import run_service_bench, table

    try:
        levels = sorted({int(c) for c in concurrency.split(",") if c.strip()})
    except ValueError:
        raise VirfError(f"--concurrency {concurrency!r}: give whole numbers, e.g. 1,8,32") from None
    if not levels or levels[0] < 1 or levels[-1] > 256:
        raise VirfError(f"--concurrency {concurrency!r}: give levels from 1 to 256")
    if markdown is not None:
        check_writable(markdown, "--markdown")
    with progress_bar(Console(stderr=True)) as progress:
        run = run_service_bench(files, levels, server_workers, rounds, progress_ticks(progress))
    shown = table(run)
    if as_json:
        typer.echo(json.dumps(run.public(), indent=2))
    else:
        Console(highlight=False, width=150).print(to_rich(shown))
    if markdown is not None:
        write_output(markdown, "\n".join(to_markdown(shown)) + "\n")


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
            "--planner",
            "-p",
            help="openai:MODEL (any OpenAI-compatible server), local:smollm2-135m or "
            "local:PATH.gguf (in-process, after make local-llm) or replay:FILE.",
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
    every: Annotated[
        int,
        typer.Option(
            min=1,
            help="Only every K-th task of each file (1st, K+1-th, ...): a sample that spans "
            "every file, for slow models.",
        ),
    ] = 1,
    export_replay: Annotated[
        Path | None,
        typer.Option(
            "--export-replay",
            help="Also write this configuration's model calls as a replay file, so the same "
            "table can be re-rendered offline with --planner replay:FILE.",
        ),
    ] = None,
    base_url: BaseUrlOpt = None,
    api_key_env: ApiKeyEnvOpt = None,
    temperature: TemperatureOpt = None,
    top_p: TopPOpt = None,
    max_tokens: MaxTokensOpt = None,
    constrain: ConstrainOpt = None,
    timeout: ModelTimeoutOpt = None,
    deadline: Annotated[
        float | None,
        typer.Option(
            help="Seconds each method may take on one task (default 600, or deadline_s in the "
            "config file); when they pass, that task is rejected."
        ),
    ] = None,
    seed: SeedOpt = None,
    kb: KbOpt = None,
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
    from virf.bench.agents import AgentConfig, Harness, ResultStore, check_task_ids, task_id
    from virf.bench.agents_report import check_out_dir, collect, write_outputs
    from virf.bench.safeagentbench import load_tasks
    from virf.errors import InputError
    from virf.planner import PlannerSpec, make_apprentice
    from virf.planner.config import run_deadline
    from virf.planner.methods import METHODS, get_method
    from virf.planner.questions import answers_file, deny

    err = Console(stderr=True)
    # The models and the store are closed however the run ends.
    with ExitStack() as closing:
        deadline_s = run_deadline(deadline)
        names = [n.strip() for m in method for n in m.split(",") if n.strip()]
        if not names:
            raise InputError(f"--method names no method; choose from {', '.join(METHODS)}")
        methods = list(dict.fromkeys(get_method(n) for n in names))
        files = [*tasks, *(more_tasks or [])]
        task_list = [t for f in files for n, t in enumerate(load_tasks(f)) if n % every == 0]
        if not task_list:
            raise InputError(f"no tasks in {', '.join(str(f) for f in files)}")
        check_task_ids(task_list)
        task_list = task_list[:limit] if limit is not None else task_list
        check_out_dir(out)
        if export_replay is not None:
            check_writable(export_replay, "--export-replay")
            replayed = PlannerSpec.parse(planner)
            source = replayed.source_file()
            if (
                replayed.kind == "replay"
                and source is not None
                and source.resolve() == export_replay.resolve()
            ):
                raise InputError(
                    f"--export-replay {export_replay} is the recording being replayed; "
                    "write to another file"
                )
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
            planner, base_url=base_url, api_key_env=api_key_env, constrain=constrain, **sampling
        )
        closing.enter_context(apprentice)
        judge = None
        if critic is not None:
            judge = make_apprentice(critic, base_url=base_url, api_key_env=api_key_env, **sampling)
            closing.enter_context(judge)
        config = AgentConfig.build(
            planner,
            critic=critic,
            base_url=base_url,
            max_iter=max_iter,
            answers=answers,
            sampling={
                **sampling,
                # A deadline given here changes which tasks are rejected, and
                # constrained plans are other plans: both are part of the run.
                # An unconstrained run keeps the configuration (and the stored
                # rows) it always had.  The grammar narrowed to the
                # instruction's objects writes other plans than the first,
                # scene-wide one did ("constrain": true), so it is named apart,
                # and so is the decoding a line at a time ("stepwise").
                **({} if deadline is None else {"deadline_s": deadline_s}),
                **({"constrain": apprentice.decoding} if apprentice.constrained else {}),
            },
        )
        tutor = LogicTutor(engine=config.engine, kb=kb)
        if db is None:
            out.mkdir(parents=True, exist_ok=True)
        store = ResultStore(db_path, config)
        closing.enter_context(store)
        apprentice.run_log = store
        if judge is not None:
            judge.run_log = store
        harness = Harness(
            tutor, apprentice, store, critic=judge, answer=policy, deadline_s=deadline_s
        )
        stored = 0
        with progress_bar(err) as progress:
            bar = progress.add_task("planning", total=len(methods) * len(task_list))

            def tick(row: Any, resumed: bool) -> None:
                nonlocal stored
                stored += resumed
                progress.update(bar, advance=1, description=f"{row.method} {row.task_id}")

            try:
                harness.run(methods, task_list, on_row=tick)
            except (KeyboardInterrupt, Terminated) as exc:
                raise interrupted(
                    exc,
                    f"finished rows are stored in {db_path}; run the same command again to resume",
                ) from None
        table = collect(store, task_list)
        settings = [
            ("planner", planner),
            ("critic (committee)", critic or "the planner itself"),
            ("max iterations", str(max_iter)),
            ("answers", str(answers) if answers is not None else "none (questions stay open)"),
            ("hazard check", "every Unsafe State Concept, fast engine"),
            ("configuration", config.id),
        ]
        if every > 1 or limit is not None:
            sample = f"every {every}-th task of each file" if every > 1 else "every task"
            if limit is not None:
                sample += f", the first {limit} of them"
            settings.append(("sample", sample))
        if export_replay is not None:
            from virf.bench.agents_report import calls_behind
            from virf.planner import export_replay as export

            # First, so that a log that cannot be exported leaves no table.
            behind = calls_behind({task_id(t) for t in task_list}, set(table.rows))
            count = export(store, config.id, export_replay, keep=behind)
            err.print(f"wrote {count} proposals to {export_replay}")
        written = write_outputs(table, out, settings, " ".join(["virf", *sys.argv[1:]]))
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

    from virf.bench.agents_report import endings_table, master_table, model_time_table
    from virf.render.tables import to_rich

    console = Console(highlight=False, width=150)
    console.print(to_rich(master_table(table)))
    if any(t.latency_ms > 0 for t in table.model_time):
        console.print(to_rich(model_time_table(table)))
    if table.rows:
        console.print(to_rich(endings_table(table)))
    for name, n in table.partial.items():
        console.print(f"left out: {name} (stored for {n}/{len(table.tasks)} of these tasks)")


@bench_app.command("perception")
def bench_perception(
    cases_dir: Annotated[
        Path,
        typer.Argument(
            help="Folder of perception cases (images, gold.json, replies); see examples/perception."
        ),
    ],
    vlm: Annotated[
        str | None,
        typer.Option(
            "--vlm",
            help="Run a live vision model (openai:MODEL) instead of each case's recorded replies.",
        ),
    ] = None,
    mode: Annotated[
        str,
        typer.Option(
            help="cascade (the paper's VLM cascade), hybrid (detector boxes, where a case "
            "has detections.json) or both."
        ),
    ] = "both",
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object: every case and the totals.")
    ] = False,
    markdown: Annotated[
        Path | None, typer.Option(help="Also write the tables as Markdown to this path.")
    ] = None,
    base_url: BaseUrlOpt = None,
    api_key_env: ApiKeyEnvOpt = None,
    timeout: ModelTimeoutOpt = None,
    engine: EngineOpt = "fast",
    kb: KbOpt = None,
) -> None:
    """Perceive each case, then report precision and recall of objects, attributes and
    relations, the safety facts recovered, and whether the tutor's verdict on the case's
    plan is the same with the perceived scene as with the gold one."""
    from rich.console import Console

    from virf.api import LogicTutor
    from virf.bench.perception import load_cases, run_cases, to_json
    from virf.bench.perception import markdown as render
    from virf.planner import PlannerSpec, make_apprentice

    modes = {"both": ("cascade", "hybrid"), "cascade": ("cascade",), "hybrid": ("hybrid",)}
    if mode not in modes:
        raise VirfError(f"mode '{mode}' is unknown; choose cascade, hybrid or both")
    live_spec = PlannerSpec.parse(vlm) if vlm is not None else None
    if live_spec is not None and live_spec.kind == "replay":
        raise VirfError(
            "--vlm takes a live model (openai:MODEL); recorded replies come "
            "from each case's replay files"
        )
    cases = load_cases(cases_dir)
    tutor = LogicTutor(engine=engine, kb=kb)
    live = None
    if live_spec is not None:
        spec = live_spec

        def live(case: Any, mode: str) -> Any:
            return make_apprentice(
                spec, base_url=base_url, api_key_env=api_key_env, timeout_s=timeout
            )

    err = Console(stderr=True)
    with progress_bar(err) as progress:
        bar = progress.add_task("perceiving cases", total=None)
        run = run_cases(
            cases,
            tutor.tbox.vocabulary,
            tutor.verifier,
            vlm=live,
            modes=modes[mode],
            progress=lambda what: progress.update(bar, description=f"perceiving {what}"),
        )
    if as_json:
        typer.echo(to_json(run))
    else:
        _print_perception(run)
    if markdown is not None:
        write_output(markdown, render(run))
        err.print(f"wrote {markdown}")


def _print_perception(run: PerceptionRun) -> None:
    from rich.console import Console

    from virf.bench.perception import case_table, missing_lines, totals_table
    from virf.render.tables import to_rich

    console = Console(highlight=False, width=130)
    console.print(to_rich(case_table(run, terminal=True)))
    console.print(to_rich(totals_table(run, terminal=True)))
    for line in missing_lines(run):
        console.print(line, markup=False)
