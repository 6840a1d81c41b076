"""The agent harness's figures: per-method metrics (computed in
:mod:`virf.bench.agents_metrics`), the master table (Markdown and CSV) and
the paper's two quadrant plots (PNG).

The metric definitions are in :mod:`virf.bench.agents` and docs/agents.md.
Everything here is a pure function of the stored rows, so the same rows give
the same files byte for byte (VL is a measured time, so it differs between
runs that actually verified, but not between a run and its resumption).
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Final

from virf.bench.agents_metrics import (
    EARLY,
    ENDINGS,
    MethodMetrics,
    ModelTime,
    Table,
    calls_behind,
    collect,
    ending,
    ending_counts,
    metrics,
    stops_early,
)
from virf.bench.agents_store import TaskRow, task_id
from virf.bench.metrics import percent
from virf.errors import InputError
from virf.planner.methods import METHODS
from virf.render.tables import TextTable, to_markdown

# The metrics moved to agents_metrics; their names stay importable from here.
__all__ = [
    "EARLY",
    "ENDINGS",
    "FILES",
    "MethodMetrics",
    "ModelTime",
    "Table",
    "calls_behind",
    "check_out_dir",
    "collect",
    "ending",
    "ending_counts",
    "endings_table",
    "master_table",
    "metrics",
    "model_time_table",
    "plot_fpr_fnr",
    "plot_har_gcr",
    "render_csv",
    "render_markdown",
    "stops_early",
    "write_outputs",
]

FILES: Final = ("agents.md", "agents.csv", "har_gcr.png", "fpr_fnr.png")


def endings_table(table: Table) -> TextTable:
    """Where each method converged and where it gave up, task by task counted."""
    rows = []
    for method, task_rows in table.rows.items():
        counts = ending_counts(task_rows)
        approved = sum(not r.rejected for r in task_rows)
        rows.append(
            [
                method,
                *(str(counts[name]) for name, _ in ENDINGS),
                f"{counts[EARLY]}/{approved}",
            ]
        )
    return TextTable.of(
        ("method", *(name for name, _ in ENDINGS), EARLY),
        rows,
        title="How the tasks ended",
    )


def model_time_table(table: Table) -> TextTable:
    """Time per proposal and per verification, apart: a slow model and a slow
    tutor are different problems."""
    by_method = {m.method: m for m in table.metrics}
    rows = []
    for t in table.model_time:
        vl = by_method[t.method].vl_ms if t.method in by_method else None
        rows.append(
            [
                t.method,
                str(t.calls),
                "n/a" if t.seconds_per_call is None else f"{t.seconds_per_call:.2f}",
                "n/a" if t.tokens_per_second is None else f"{t.tokens_per_second:.1f}",
                "n/a" if vl is None else f"{vl:.1f}",
            ]
        )
    return TextTable.of(
        # Reply tokens over the whole call, prompt reading included: what a
        # user waits per token, not the model's writing speed alone.
        ("method", "model calls", "s per call", "reply tokens/s", "verify ms per proposal"),
        rows,
        title="Time: the model and the tutor",
    )


# ---------------------------------------------------------------------------
# Text


def _cell(rate: float | None, hits: int, total: int) -> str:
    return "n/a" if rate is None else f"{percent(rate, sign='')} ({hits}/{total})"


def master_rows(table: Table) -> list[list[str]]:
    out = []
    for m in table.metrics:
        out.append(
            [
                m.method,
                str(m.tasks),
                _cell(m.har, m.hazardous, m.tasks),
                _cell(m.gcr, m.goal_met, m.goal_tasks),
                _cell(m.fpr, m.unsafe_not_rejected, m.unsafe_tasks),
                _cell(m.fnr, m.safe_rejected, m.safe_tasks),
                "n/a" if m.ri is None else f"{m.ri:.2f}",
                "n/a" if m.vl_ms is None else f"{m.vl_ms:.1f}",
            ]
        )
    return out


MASTER_HEADER: Final = ("method", "tasks", "HAR %", "GCR %", "FPR %", "FNR %", "RI", "VL ms")


def master_table(table: Table) -> TextTable:
    """The figures per method: printed by ``virf bench agents`` and written into agents.md."""
    return TextTable.of(
        MASTER_HEADER, master_rows(table), title=f"Agent evaluation ({len(table.tasks)} tasks)"
    )


def task_cell(row: TaskRow) -> str:
    parts = ["rejected" if row.rejected else "approved"]
    if row.hazardous:
        parts.append(f"HAZARD {row.hazard_concept or ''}".rstrip())
    if row.goal_met is not None:
        parts.append("goal met" if row.goal_met else "goal not met")
    parts.append(f"{row.iterations} it.")
    return ", ".join(parts)


def render_markdown(table: Table, settings: Sequence[tuple[str, str]], command: str) -> str:
    tasks = table.tasks
    unsafe = sum(t.label == "unsafe" for t in tasks)
    goals = sum(t.final_state is not None for t in tasks)
    files = sorted({t.file for t in tasks})
    lines = [
        "# Agent evaluation on SafeAgentBench",
        "",
        f"Generated by `{command}`.",
        "",
        *to_markdown(
            TextTable.of(
                ("setting", "value"),
                [
                    *settings,
                    (
                        "tasks",
                        f"{len(tasks)} ({unsafe} unsafe, {len(tasks) - unsafe} safe; "
                        f"{goals} with goal conditions) from {', '.join(files)}",
                    ),
                ],
            )
        ),
        "",
        "## Master table",
        "",
        *to_markdown(master_table(table)),
        "",
    ]
    if any(t.latency_ms > 0 for t in table.model_time):
        lines += ["## Time", "", *to_markdown(model_time_table(table)), ""]
    if table.rows:
        lines += [
            "## How the tasks ended",
            "",
            *to_markdown(endings_table(table)),
            "",
            *(f"* {name}: {meaning}." for name, meaning in ENDINGS),
            f"* {EARLY}: the simulator could not carry the plan to its "
            "end (an object the scene lacks, a failed precondition).",
            "",
        ]
    if table.partial:
        left = ", ".join(f"{m} ({n}/{len(tasks)} tasks)" for m, n in table.partial.items())
        lines += [f"Left out (stored for only part of these tasks): {left}.", ""]
    lines += [
        "* HAR: final plans in which the full Logic Tutor finds a hazard / tasks (a rejected "
        "task, or a plan that only fails a precondition, is not hazardous).",
        "* GCR: tasks whose goal conditions hold after executing the final plan in the "
        "simulator / tasks with goal conditions (a rejected task meets none).",
        "* FPR: unsafe-labelled tasks not rejected / unsafe tasks.",
        "* FNR: safe-labelled tasks rejected / safe tasks.",
        "* RI: mean iterations (the first proposal counts, as in the paper) over "
        "successful tasks (approved, goal met, not hazardous); n/a for one-shot methods.",
        "* VL: verifier milliseconds per verified proposal (the Logic Tutor; the critic "
        "for the committee); n/a for one-shot methods.",
        "",
        "Definitions in detail: docs/agents.md.",
        "",
        "## Per task",
        "",
    ]
    methods = list(table.rows)
    per_task = []
    for i, task in enumerate(tasks):
        per_task.append(
            [
                task_id(task),
                task.label,
                task.instruction[:70],
                *[task_cell(table.rows[m][i]) for m in methods],
            ]
        )
    lines += to_markdown(TextTable.of(("task", "label", "instruction", *methods), per_task))
    return "\n".join(lines) + "\n"


CSV_HEADER: Final = (
    "method",
    "tasks",
    "hazardous",
    "har_pct",
    "goal_tasks",
    "goal_met",
    "gcr_pct",
    "unsafe_tasks",
    "unsafe_not_rejected",
    "fpr_pct",
    "safe_tasks",
    "safe_rejected",
    "fnr_pct",
    "successful",
    "ri",
    "verifications",
    "vl_ms",
)


def render_csv(table: Table) -> str:
    def num(x: float | None, fmt: str) -> str:
        return "" if x is None else format(x, fmt)

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_HEADER)
    for m in table.metrics:
        writer.writerow(
            [
                m.method,
                m.tasks,
                m.hazardous,
                num(None if m.har is None else 100 * m.har, ".1f"),
                m.goal_tasks,
                m.goal_met,
                num(None if m.gcr is None else 100 * m.gcr, ".1f"),
                m.unsafe_tasks,
                m.unsafe_not_rejected,
                num(None if m.fpr is None else 100 * m.fpr, ".1f"),
                m.safe_tasks,
                m.safe_rejected,
                num(None if m.fnr is None else 100 * m.fnr, ".1f"),
                m.successful,
                num(m.ri, ".2f"),
                m.verifications,
                num(m.vl_ms, ".1f"),
            ]
        )
    return buf.getvalue()


# ---------------------------------------------------------------------------
# Plots

# One colour per method, fixed by the paper's order, so a method keeps its
# colour across runs and plots.
_PALETTE: Final = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)


def _style(method: str) -> tuple[str, str]:
    names = list(METHODS)
    colour = _PALETTE[names.index(method) % len(_PALETTE)] if method in names else "#000000"
    # The paper draws the VIRF variants as triangles.
    return colour, "^" if method.startswith("virf") else "o"


def plot_quadrant(
    table: Table,
    path: Path,
    *,
    x: Callable[[MethodMetrics], float | None],
    y: Callable[[MethodMetrics], float | None],
    xlabel: str,
    ylabel: str,
    title: str,
    names: tuple[str, str],  # short names of the two rates, for the legend
    ideal: tuple[float, float, str],  # corner (x, y) in percent and its caption
) -> None:
    """One quadrant plot as PNG: each method a point, quadrants split at 50 %,
    the ideal quadrant shaded, and a legend that gives every method's exact
    figures.  Uses the Agg canvas directly (no pyplot state, no display)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 5.4), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.set_xlim(-5, 105)
    ax.set_ylim(-5, 105)
    ax.set_aspect("equal")
    ax.axvline(50, color="#999999", linestyle="--", linewidth=0.8)
    ax.axhline(50, color="#999999", linestyle="--", linewidth=0.8)
    cx, cy, caption = ideal
    ax.add_patch(
        _rectangle(min(cx, 50.0), min(cy, 50.0), 50.0, 50.0, facecolor="#2ca02c", alpha=0.08)
    )
    ax.text(
        25.0,
        cy + (6 if cy < 50 else -6),
        caption,
        ha="center",
        va="bottom" if cy < 50 else "top",
        fontsize=8,
        color="#2a7a2a",
    )
    # Methods with the same figures would hide one another: spread them on a
    # small circle around the true point (the legend gives the exact values).
    groups: dict[tuple[float, float], list[MethodMetrics]] = {}
    missing = []
    for m in table.metrics:
        vx, vy = x(m), y(m)
        if vx is None or vy is None:
            missing.append(m.method)
            continue
        groups.setdefault((100 * vx, 100 * vy), []).append(m)
    where: dict[str, tuple[float, float, float, float]] = {}
    for (px, py), members in groups.items():
        for i, m in enumerate(members):
            dx = dy = 0.0
            if len(members) > 1:
                angle = 2 * math.pi * i / len(members)
                dx, dy = 2.2 * math.cos(angle), 2.2 * math.sin(angle)
            where[m.method] = (px, py, dx, dy)
    for m in table.metrics:  # in table order, so the legend reads like the table
        if m.method in where:
            px, py, dx, dy = where[m.method]
            colour, marker = _style(m.method)
            ax.scatter(
                [px + dx],
                [py + dy],
                color=colour,
                marker=marker,
                s=55,
                zorder=3,
                edgecolors="white",
                linewidths=0.6,
                label=f"{m.method}  ({names[0]} {px:.1f}, {names[1]} {py:.1f})",
            )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=11)
    ax.grid(True, linewidth=0.3, alpha=0.5)
    if table.metrics and len(missing) < len(table.metrics):
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    if missing:
        ax.annotate(
            f"n/a, not drawn: {', '.join(missing)}",
            (1.02, 0.0),
            xycoords="axes fraction",
            fontsize=7,
            va="bottom",
        )
    # No software version in the file: the same figures give the same bytes.
    fig.savefig(path, format="png", metadata={"Software": None})


def _rectangle(x: float, y: float, w: float, h: float, **style: Any) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((x, y), w, h, linewidth=0, **style)


def plot_har_gcr(table: Table, path: Path) -> None:
    plot_quadrant(
        table,
        path,
        x=lambda m: m.har,
        y=lambda m: m.gcr,
        xlabel="HAR: hazardous action rate (%) ↓",
        ylabel="GCR: goal-condition rate (%) ↑",
        title="Safety vs. efficacy (HAR vs. GCR)",
        names=("HAR", "GCR"),
        ideal=(0.0, 100.0, "safe and effective"),
    )


def plot_fpr_fnr(table: Table, path: Path) -> None:
    plot_quadrant(
        table,
        path,
        x=lambda m: m.fpr,
        y=lambda m: m.fnr,
        xlabel="FPR: unsafe tasks not rejected (%) ↓",
        ylabel="FNR: safe tasks rejected (%) ↓",
        title="Safety mechanism (FPR vs. FNR)",
        names=("FPR", "FNR"),
        ideal=(0.0, 0.0, "rejects exactly the unsafe tasks"),
    )


# ---------------------------------------------------------------------------
# Files


def check_out_dir(out: Path) -> None:
    """Fail before a long run when the outputs could not be written."""
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} is a file; give a folder")
    probe = out
    while not probe.exists():
        probe = probe.parent
    if not os.access(probe, os.W_OK):
        raise InputError(f"--out {out}: folder {probe} is not writable")


def write_outputs(
    table: Table, out: Path, settings: Sequence[tuple[str, str]], command: str
) -> list[Path]:
    """Write the four files, all or none: each goes to a temporary name first
    and the renames happen only once every file is complete."""
    temps: list[tuple[Path, Path]] = []
    try:
        out.mkdir(parents=True, exist_ok=True)
        texts = {
            "agents.md": render_markdown(table, settings, command),
            "agents.csv": render_csv(table),
        }
        for name, text in texts.items():
            tmp = out / f".{name}.tmp"
            temps.append((tmp, out / name))
            tmp.write_text(text, encoding="utf-8")
        for name, plot in (("har_gcr.png", plot_har_gcr), ("fpr_fnr.png", plot_fpr_fnr)):
            tmp = out / f".{name}.tmp"
            temps.append((tmp, out / name))
            plot(table, tmp)
        for tmp, final in temps:
            tmp.replace(final)
    except OSError as exc:
        raise InputError(f"cannot write the results into {out}: {exc.strerror or exc}") from None
    finally:
        for tmp, _ in temps:
            tmp.unlink(missing_ok=True)
    return [final for _, final in temps]
