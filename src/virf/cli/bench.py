"""``virf bench``: the Logic Tutor on SafeAgentBench (hazards, latency, agents)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from virf.cli.app import (
    ApiKeyEnvOpt,
    BaseUrlOpt,
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
    write_output,
)
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
            min=0,
            help="Time the paper's method on this many plans (0 = all; seconds to minutes "
            "per step).",
        ),
    ] = 20,
    paper_max_objects: Annotated[
        int, typer.Option(min=0, help="Largest synthetic scene the paper's method is timed on.")
    ] = 200,
    paper_call_limit: Annotated[
        float,
        typer.Option(
            "--paper-call-limit",
            min=1.0,
            help="Seconds one reasoner call of the paper's method may take; a call still "
            "running is stopped and its plan's time reported as a lower bound.",
        ),
    ] = 60.0,  # virf.bench.paper.PAPER_CALL_LIMIT_S, unimported: commands load their modules late
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
    cold_example: Annotated[
        Path,
        typer.Option(
            help="Example folder (scene.json + plan.txt) whose cold start to first verdict "
            "is timed as fresh 'virf verify' processes."
        ),
    ] = Path("examples/walkthrough"),
    cold_runs: Annotated[
        int, typer.Option(min=0, help="Fresh processes per engine for the cold start (0 = skip).")
    ] = 5,
    cold_engines: Annotated[
        str,
        typer.Option(
            help="Engines whose cold start is timed, comma-separated (the reference "
            "engine's takes about 10 s a process)."
        ),
    ] = "fast,reference",
) -> None:
    """Time the paper's method, the reference engine and the fast engine on the same plans."""
    from rich.console import Console

    from virf.bench.latency import run_latency
    from virf.bench.latency_report import print_latency, render_markdown
    from virf.world.plan import MAX_PLAN_STEPS
    from virf.world.scene import MAX_INSTANCES

    for f in files:
        if not f.is_file():
            raise VirfError(f"no such file: {f}")
    size_list = _whole_numbers("--sizes", sizes, "20,50,200")
    if not size_list or min(size_list) < 10 or max(size_list) > MAX_INSTANCES:
        raise VirfError(
            f"--sizes '{sizes}': every size must be at least 10 objects and at most "
            f"{MAX_INSTANCES} (the scene limit)"
        )
    factors = _whole_numbers("--tbox-factors", tbox_factors, "1,4")
    if not factors or min(factors) < 1 or max(factors) > 16:
        raise VirfError(f"--tbox-factors '{tbox_factors}': each factor must be 1 to 16")
    length_list = _whole_numbers("--lengths", lengths, "10,20,40")
    if not length_list or any(n < 10 or n % 10 or n > MAX_PLAN_STEPS for n in length_list):
        raise VirfError(
            f"--lengths '{lengths}': each length must be a multiple of 10 steps, "
            f"at most {MAX_PLAN_STEPS} (the plan limit)"
        )
    cold_list = [e.strip() for e in cold_engines.split(",") if e.strip()]
    for name in cold_list or [cold_engines]:
        if name not in COLD_ENGINES:
            raise VirfError(
                f"--cold-engines: unknown engine '{name}'; choose from {', '.join(COLD_ENGINES)}"
            )
    cold: tuple[Path, Path] | None = None
    if cold_runs:
        cold = (cold_example / "scene.json", cold_example / "plan.txt")
        missing = [p for p in cold if not p.is_file()]
        if missing:
            raise VirfError(
                f"--cold-example {cold_example}: no {missing[0].name} there; "
                "give an example folder or --cold-runs 0"
            )
    if markdown is not None:
        check_writable(markdown, "--markdown")
    err = Console(stderr=True)
    with progress_bar(err) as progress:

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
            paper_call_limit_s=paper_call_limit,
            tbox_factors=factors,
            lengths=length_list,
            cold=cold,
            cold_runs=cold_runs,
            cold_engines=cold_list,
            progress=bar,
        )
    if as_json:
        typer.echo(json.dumps(figures, sort_keys=True))
    else:
        print_latency(figures)
    if markdown:
        write_output(markdown, render_markdown(figures, " ".join(["virf", *sys.argv[1:]])))
        typer.echo(f"wrote {markdown}", err=True)


COLD_ENGINES = ("fast", "reference")


def _whole_numbers(option: str, text: str, example: str) -> list[int]:
    """A comma-separated option of whole numbers."""
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise VirfError(f"{option} '{text}': give whole numbers, e.g. {example}") from None


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
    from functools import partial

    from rich.console import Console

    from virf.render.tables import to_markdown, to_rich
    from virf.service.bench import Server, measure, request_bodies, table

    try:
        levels = sorted({int(c) for c in concurrency.split(",") if c.strip()})
    except ValueError:
        raise VirfError(f"--concurrency {concurrency!r}: give whole numbers, e.g. 1,8,32") from None
    if not levels or levels[0] < 1 or levels[-1] > 256:
        raise VirfError(f"--concurrency {concurrency!r}: give levels from 1 to 256")
    if markdown is not None:
        check_writable(markdown, "--markdown")
    bodies = request_bodies(files)
    err = Console(stderr=True)
    server = Server(server_workers)
    try:
        server.wait_ready()
        measure(server.url, bodies[:8], 1, 1)  # warm every worker's tutor and caches
        results = []
        with progress_bar(err) as progress:
            for level in levels:
                bar = progress.add_task(f"concurrency {level}", total=len(bodies) * rounds)
                results.append(
                    measure(server.url, bodies, level, rounds, partial(progress.advance, bar))
                )
    finally:
        server.close()
    shown = table(results, server_workers, len(bodies))
    if as_json:
        typer.echo(
            json.dumps(
                {
                    "plans": len(bodies),
                    "server_workers": server_workers,
                    "levels": [r.public() for r in results],
                },
                indent=2,
            )
        )
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
    from virf.planner import make_apprentice
    from virf.planner.config import run_deadline
    from virf.planner.methods import METHODS, get_method
    from virf.planner.questions import answers_file, deny

    err = Console(stderr=True)
    closing: list[Any] = []
    try:
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
            source = planner.strip().partition(":")
            if (
                source[0] == "replay"
                and Path(source[2].strip()).resolve() == export_replay.resolve()
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
            # A deadline given here changes which tasks are rejected: part of the run.
            sampling=sampling if deadline is None else {**sampling, "deadline_s": deadline_s},
        )
        tutor = LogicTutor(engine=config.engine, kb=kb)
        if db is None:
            out.mkdir(parents=True, exist_ok=True)
        store = ResultStore(db_path, config)
        closing.append(store)
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
    from virf.planner import make_apprentice

    modes = {"both": ("cascade", "hybrid"), "cascade": ("cascade",), "hybrid": ("hybrid",)}
    if mode not in modes:
        raise VirfError(f"mode '{mode}' is unknown; choose cascade, hybrid or both")
    if vlm is not None and vlm.startswith("replay:"):
        raise VirfError(
            "--vlm takes a live model (openai:MODEL); recorded replies come "
            "from each case's replay files"
        )
    cases = load_cases(cases_dir)
    tutor = LogicTutor(engine=engine, kb=kb)
    live = None
    if vlm is not None:
        spec = vlm

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
