"""``virf bench latency``: the paper's method, the reference engine and the fast
engine timed on the same plans."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated

import typer

from virf.cli.app import check_writable, progress_bar, progress_ticks, write_output
from virf.errors import VirfError


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
    with progress_bar(Console(stderr=True)) as progress:
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
            progress=progress_ticks(progress),
        )
    if as_json:
        typer.echo(json.dumps(figures.public(), sort_keys=True))
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
