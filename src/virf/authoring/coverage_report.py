"""How ``virf kb coverage`` shows a :class:`~virf.authoring.coverage.CoverageResult`:
terminal tables, a Markdown page and a bar chart, from one set of
:class:`~virf.render.tables.TextTable` rows."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from virf.authoring.coverage import STATUS_TEXT, TOP_RULES, CoverageResult, RuleFiring
from virf.bench.metrics import percent
from virf.errors import InputError
from virf.render.tables import Column, TextTable, to_markdown


def _steps_text(steps: Sequence[int]) -> str:
    """Steps as runs: 3, 5-9."""
    runs: list[list[int]] = []
    for s in steps:
        if runs and s == runs[-1][-1] + 1:
            runs[-1].append(s)
        else:
            runs.append([s])
    return ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)


def firing_text(f: RuleFiring) -> str:
    """``Rule (steps)``; an uncertain-only firing says it would ask."""
    asks = "" if f.definite else ", asks"
    return f"{f.rule} (step {_steps_text(f.steps)}{asks})"


def _short(text: str, terminal: bool, limit: int = 70) -> str:
    text = " ".join(text.split())
    return text if not terminal or len(text) <= limit else text[: limit - 1] + "…"


def category_table(result: CoverageResult) -> TextTable:
    rows = [
        (
            c.category,
            str(c.unsafe_tasks),
            str(c.covered),
            str(c.definite),
            str(c.unsafe_tasks - c.covered),
            percent(c.ratio, 0),
            str(c.not_checked),
            ", ".join(f"{r} ({n})" for r, n in c.rules[:TOP_RULES]) or "-",
        )
        for c in result.categories
    ]
    s = result.summary()
    rows.append(
        (
            "all unsafe tasks",
            str(s.unsafe_checked),
            str(s.unsafe_covered),
            str(s.unsafe_definite),
            str(s.unsafe_checked - s.unsafe_covered),
            percent(s.coverage, 0),
            str(
                sum(t.label == "unsafe" and t.status in ("unparsed", "error") for t in result.tasks)
            ),
            "",
        )
    )
    return TextTable.of(
        (
            "hazard category",
            Column("unsafe", "right"),
            Column("covered", "right"),
            Column("definite", "right"),
            Column("uncovered", "right"),
            Column("coverage", "right"),
            Column("not checked", "right"),
            "rules firing most (tasks)",
        ),
        rows,
        title="Rule coverage of unsafe tasks per hazard category "
        "(a task may count in several categories)",
    )


def unsafe_task_table(result: CoverageResult, terminal: bool) -> TextTable:
    rows = [
        (
            t.ref.where,
            ", ".join(t.categories),
            "; ".join(firing_text(f) for f in t.firings) or "NONE",
            _short(t.ref.instruction, terminal),
        )
        for t in result.checked_unsafe
    ]
    return TextTable.of(
        ("task", "category", "rules that fire (steps)", "instruction"),
        rows,
        title="Unsafe tasks: every rule that fires on the reference plan",
    )


def uncovered_table(result: CoverageResult, terminal: bool) -> TextTable:
    rows = [
        (
            t.ref.where,
            ", ".join(t.categories),
            _short(t.ref.instruction, terminal),
            t.reason or "ran to the end; no rule fired",
        )
        for t in result.checked_unsafe
        if not t.covered
    ]
    return TextTable.of(
        ("task", "category", "instruction", "run"),
        rows,
        title="Uncovered unsafe tasks (no rule fires)",
    )


def false_alarm_table(result: CoverageResult) -> TextTable:
    rows = [
        (r.id, r.category, str(len(r.safe)), ", ".join(t.where for t in r.safe))
        for r in sorted(result.rules, key=lambda r: (-len(r.safe), r.id))
        if r.safe
    ]
    return TextTable.of(
        ("rule", "rule category", Column("safe tasks", "right"), "tasks"),
        rows,
        title="False alarms by rule (rules firing on safe tasks)",
    )


def safe_task_table(result: CoverageResult, terminal: bool) -> TextTable:
    rows = [
        (
            t.ref.where,
            "; ".join(firing_text(f) for f in t.firings),
            _short(t.ref.instruction, terminal),
        )
        for t in result.alarmed_safe
    ]
    return TextTable.of(
        ("task", "rules that fire (steps)", "instruction"),
        rows,
        title="Safe tasks where rules fire",
    )


def never_fired_table(result: CoverageResult) -> TextTable:
    rows = [(r.id, r.module, r.category, r.kind) for r in result.never_fired]
    return TextTable.of(
        ("rule", "module", "category", "kind"),
        rows,
        title="Rules that never fire on any task",
    )


def not_checked_table(result: CoverageResult, terminal: bool) -> TextTable:
    rows = [
        (
            t.ref.where,
            t.label,
            STATUS_TEXT[t.status],
            _short(t.reason, terminal, 100) if t.status != "no-plan" else "",
            _short(t.ref.instruction, terminal),
        )
        for t in result.not_checked
    ]
    return TextTable.of(
        ("task", "label", "status", "reason", "instruction"),
        rows,
        title="Tasks not checked (not counted as covered or uncovered)",
    )


def report_tables(result: CoverageResult, terminal: bool) -> list[TextTable]:
    """The report's tables, the category figures last (the terminal's last screen)."""
    tables = [
        unsafe_task_table(result, terminal),
        safe_task_table(result, terminal),
        false_alarm_table(result),
        never_fired_table(result),
        not_checked_table(result, terminal),
        uncovered_table(result, terminal),
        category_table(result),
    ]
    return [t for t in tables if t.rows]


def summary_line(result: CoverageResult) -> str:
    s = result.summary()
    return (
        f"{s.unsafe_covered}/{s.unsafe_checked} unsafe tasks covered "
        f"({percent(s.coverage, 0)}; {s.unsafe_definite} definite), "
        f"{s.safe_with_firing_rules}/{s.safe_checked} safe tasks with firing rules, "
        f"{s.rules_never_fired}/{s.rules} rules never fire; "
        f"not checked: {s.no_reference_plan} without a reference plan, "
        f"{s.plan_does_not_parse} whose plan does not parse, {s.errors} errors"
    )


def render_markdown(result: CoverageResult, command: str) -> str:
    lines = [
        "# Rule coverage of SafeAgentBench reference plans",
        "",
        f"Generated by `{command}`.",
        "",
        f"Scenario `{result.scenario}`"
        + (f", knowledge workspace `{result.kb}`" if result.kb else "")
        + "; files: "
        + ", ".join(f"`{f}`" for f in result.files)
        + ".",
        "",
        summary_line(result) + ".",
        "",
        "A rule *covers* an unsafe task when it fires in some state of the task's "
        "simulated reference plan; *definite* means at least one firing does not "
        "rest on an open-world assumption (the verifier would report UNSAFE rather "
        "than UNKNOWN). Steps are 1-based plan steps; step 0 is the initial scene.",
    ]
    for table in reversed(report_tables(result, terminal=False)):
        lines += ["", f"## {table.title}", "", *to_markdown(table)]
    return "\n".join(lines) + "\n"


def plot_coverage(result: CoverageResult, path: Path) -> None:
    """Covered and uncovered unsafe tasks per category, as horizontal bars.

    Written to a temporary file beside ``path`` and moved into place, so a
    failure leaves no half-written image."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    cats = [c for c in result.categories if c.unsafe_tasks]
    labels = [c.category for c in cats]
    covered = [c.covered for c in cats]
    uncovered = [c.unsafe_tasks - c.covered for c in cats]
    fig, ax = plt.subplots(figsize=(10, 1.6 + 0.55 * max(len(cats), 1)), dpi=120)
    try:
        ys = list(range(len(cats)))
        ax.barh(ys, covered, color="#2e7d32", label="covered (a rule fires)")
        ax.barh(ys, uncovered, left=covered, color="#c62828", label="uncovered (no rule fires)")
        top = max((c.unsafe_tasks for c in cats), default=1)
        for y, c in zip(ys, cats, strict=True):
            if c.covered:
                ax.text(
                    c.covered / 2,
                    y,
                    str(c.covered),
                    ha="center",
                    va="center",
                    color="white",
                    fontsize=9,
                    fontweight="bold",
                )
            if c.unsafe_tasks - c.covered:
                ax.text(
                    c.covered + (c.unsafe_tasks - c.covered) / 2,
                    y,
                    str(c.unsafe_tasks - c.covered),
                    ha="center",
                    va="center",
                    color="white",
                    fontsize=9,
                    fontweight="bold",
                )
            ax.text(
                c.unsafe_tasks + top * 0.01,
                y,
                f"{c.covered}/{c.unsafe_tasks}",
                va="center",
                fontsize=9,
            )
        ax.set_yticks(ys, labels)
        ax.invert_yaxis()  # the first category on top, as in the table
        ax.set_xlim(0, top * 1.12)
        ax.set_xlabel("unsafe tasks (reference plans checked)")
        s = result.summary()
        ax.set_title(
            f"Rule coverage per hazard category: {s.unsafe_covered}/{s.unsafe_checked} "
            f"unsafe tasks covered (scenario {result.scenario})"
        )
        # Below the axis, so it never hides a bar or a count.
        ax.legend(
            loc="upper center",
            # Anchored at the axis and pushed down in font units, so the gap
            # below the axis label is the same for any number of bars.
            bbox_to_anchor=(0.5, 0.0),
            borderaxespad=4.6,
            ncol=2,
            fontsize=9,
            frameon=False,
        )
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(axis="x", alpha=0.3)
        ax.set_axisbelow(True)
        fig.tight_layout()
        tmp = path.with_name(f".{path.name}.tmp")
        try:
            fig.savefig(tmp, format="png", bbox_inches="tight")
            os.replace(tmp, path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise InputError(f"cannot write --plot {path}: {exc.strerror}") from None
    finally:
        plt.close(fig)
