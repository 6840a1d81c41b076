"""The report as text for people: verdict, causal chain, questions and trace."""

from __future__ import annotations

import textwrap

from virf.schema import Report, Violation

# One mark per step outcome, so the trace reads as a column.
_TRACE_MARKS = {
    "ok": " ",
    "unsafe": "!",
    "unknown": "?",
    "not-checked": "-",
    "not-simulated": "-",
    "error": "x",
}


def _wrap(text: str, indent: str) -> str:
    return textwrap.fill(text, width=100, initial_indent=indent, subsequent_indent=indent + "  ")


def problem_words(report: Report) -> str:
    """The kind of problem at the reported step, in words ('' when none)."""
    open_ = report.status == "UNKNOWN"  # it depends on a fact the scene leaves open
    if report.problem == "hazard":
        return "possible hazard" if open_ else "hazard"
    if report.problem != "not-executable":
        return ""
    refuses = report.violations[0].ai2thor_refuses if report.violations else None
    simulator = {
        True: "; AI2-THOR would refuse this step too",
        False: "; AI2-THOR itself would not refuse it",
        None: "",
    }[refuses]
    can = "may not" if open_ else "cannot"
    return f"the plan {can} run here (not executable{simulator})"


def _violation_tag(v: Violation) -> str:
    tags = [] if v.definite else ["needs confirmation"]
    if v.problem == "not-executable":
        tags.append("not executable")
    return f" [{'; '.join(tags)}]" if tags else ""


def render_report(report: Report, title: str | None = None) -> str:
    """A human-readable report that shows the causal chain."""
    lines: list[str] = []
    if title:
        lines.append(f"== {title}")
    head = f"Verdict: {report.status}"
    if report.dangerous_step is not None:
        where = f"step {report.dangerous_step}"
        where += f" ({report.action})" if report.action else " (initial state)"
        head += f" at {where}"
    if problem_words(report):
        head += f" — {problem_words(report)}"
    lines.append(head)
    lines.append(_wrap(report.reason, "  "))
    for i, v in enumerate(report.violations, start=1):
        tag = _violation_tag(v)
        lines.append(f"  Violation {i}: {v.id} ({v.category}, danger {v.danger_level}){tag}")
        lines.append(_wrap(v.description, "    "))
        if v.triggering_facts:
            lines.append("    Triggering facts (minimal):")
            for t in v.triggering_facts:
                mark = "  (assumed)" if t in v.assumed_facts else ""
                lines.append(f"      - {t.subject} {t.predicate} {t.object}{mark}")
        if v.as_written:
            lines.append("    As the scene wrote them:")
            for t in v.as_written:
                lines.append(f"      - {t.subject} {t.predicate} {t.object}")
        if v.background:
            lines.append("    Background knowledge used:")
            for b in v.background:
                lines.append(_wrap(f"- {b.text}   [{b.id}; {b.source}]", "      "))
        lines.append(_wrap(f"Warning: {v.safety_warning}", "    "))
        lines.append(_wrap(f"Suggestion: {v.suggestion}", "    "))
    if report.questions:
        lines.append("  Questions for the user:")
        for q in report.questions:
            lines.append(_wrap(f"? {q.text}", "    "))
    if report.notes:
        lines.append("  How the input was read:")
        for n in report.notes:
            lines.append(_wrap(f"- {n}", "    "))
    if report.trace:
        lines.append("  Trace:")
        for st in report.trace:
            mark = _TRACE_MARKS[st.outcome]
            note = f"  <- {', '.join(st.findings)}" if st.findings else ""
            if st.outcome in ("not-simulated", "not-checked"):
                note = f"  ({st.outcome.replace('-', ' ')}: verification stopped earlier)"
            lines.append(f"    {mark} {st.step:>2}. {st.action}{note}")
    return "\n".join(lines) + "\n"
