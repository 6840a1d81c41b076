"""``virf kb coverage``: which safety rules fire on each benchmark task's reference plan."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Annotated

import typer

from virf.cli.app import KbOpt, RoomScenarioOpt, RoomTutors, progress_bar, write_output
from virf.errors import InputError, clip


def register(kb_app: typer.Typer) -> None:
    """Add the ``coverage`` command to the ``virf kb`` group."""
    kb_app.command("coverage")(kb_coverage)


def kb_coverage(
    files: Annotated[
        list[Path],
        typer.Argument(help="SafeAgentBench JSONL task files (any split, any room)."),
    ],
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the whole result as one JSON object.")
    ] = False,
    scenario: RoomScenarioOpt = "auto",
    kb: KbOpt = None,
    plot: Annotated[
        Path | None,
        typer.Option(help="Also draw covered vs uncovered unsafe tasks per category (PNG)."),
    ] = None,
    markdown: Annotated[
        Path | None, typer.Option(help="Also write the report as a Markdown page.")
    ] = None,
) -> None:
    """Which safety rules fire on each task's reference plan, per hazard category.

    Every rule that fires at any step counts (not only the first violation a
    verification report names).  Tasks without a reference plan are listed,
    not counted."""
    from rich.console import Console

    from virf.authoring.coverage import compute_coverage, load_coverage_tasks
    from virf.authoring.coverage_report import (
        plot_coverage,
        render_markdown,
        report_tables,
        summary_line,
    )
    from virf.render.tables import to_rich

    # Every input is checked before the knowledge base loads and the run starts,
    # so a bad option fails in milliseconds and nothing is half-written.
    if plot is not None:
        _check_output("--plot", plot)
        if plot.suffix.lower() != ".png":
            raise InputError(f"--plot {clip(str(plot))}: give a file name ending in .png")
    if markdown is not None:
        _check_output("--markdown", markdown)
    if plot is not None and markdown is not None and plot.resolve() == markdown.resolve():
        raise InputError("--plot and --markdown name the same file")
    # Verdicts only: coverage never prints an explanation, and they are the same.
    tutors = RoomTutors(scenario, kb, explain=False)
    tasks = load_coverage_tasks(files)
    started = time.perf_counter()
    # With 'auto', the rules are listed from the household scenario (every room's).
    tutor = tutors.named(tutors.fixed or "household")
    err = Console(stderr=True)
    with progress_bar(err) as progress:
        bar = progress.add_task("checking reference plans", total=len(tasks))
        result = compute_coverage(
            tutor,
            tasks,
            kb=None if kb is None else str(kb),
            on_task=lambda _: progress.advance(bar),
            tutor_for=tutors.for_task if tutors.fixed is None else None,
        )
    elapsed = time.perf_counter() - started
    if as_json:
        typer.echo(json.dumps(result.public(), indent=2, sort_keys=True))
    else:
        console = Console(highlight=False, width=160)
        for table in report_tables(result, terminal=True):
            console.print(to_rich(table))
        console.print(summary_line(result), markup=False)
    if markdown is not None:
        # The command as typed, so the page says how to regenerate it.
        command = " ".join(["virf", *sys.argv[1:]])
        write_output(markdown, render_markdown(result, command))
        err.print(f"wrote {markdown}", markup=False, highlight=False)
    if plot is not None:
        plot_coverage(result, plot)
        err.print(f"wrote {plot}", markup=False, highlight=False)
    err.print(f"{len(tasks)} tasks in {elapsed:.1f}s", markup=False, highlight=False)


def _check_output(option: str, path: Path) -> None:
    """Fail before a long run, not after it, when an output cannot be written."""
    if path.is_dir():
        raise InputError(f"{option} {clip(str(path))} is a directory; give a file path")
    if not path.parent.is_dir():
        raise InputError(
            f"{option} {clip(str(path))}: folder {clip(str(path.parent))} does not exist"
        )
    if not os.access(path.parent, os.W_OK):
        raise InputError(
            f"{option} {clip(str(path))}: folder {clip(str(path.parent))} is not writable"
        )
