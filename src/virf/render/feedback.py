"""Render reports to text: a readable report for people, and the paper's
diagnostic feedback prompt (Appendix E) for the LLM apprentice."""

from __future__ import annotations

import textwrap
from importlib import resources

from virf.schema import Report, Violation

# The paper's Appendix E template, kept as a file so it can be read and
# adapted without touching code.
FEEDBACK_TEMPLATE = (
    resources.files("virf.render").joinpath("diagnostic.txt").read_text(encoding="utf-8")
)

_NON_OBJECTS = {"rdf:type"}


def involved_objects(v: Violation) -> list[str]:
    names: list[str] = []
    for t in v.triggering_facts:
        for n in (t.subject, t.object):
            n = n.strip("{}")
            for part in (p.strip() for p in n.split(",")):
                if part and part not in names and part[0].isupper() and "_" in part:
                    names.append(part)
    names = [n for n in names if not n.startswith("Step")]
    if v.subject and v.subject not in names and not v.subject.startswith("Step"):
        names.insert(0, v.subject)
    return names


def feedback_prompt(report: Report) -> str:
    """The paper's natural-language feedback prompt, filled from the report."""
    if report.status == "SAFE":
        return "The plan passed safety verification.\n"
    if report.status == "ERROR" or not report.violations:
        return (
            "ATTENTION: Your previous plan could not be verified and is NOT approved.\n"
            f"Reason: {report.reason}\n"
            "Do not execute it. Propose the plan again, simpler if possible; "
            'if no safe plan is possible, respond with "TASK_ABORT".\n'
        )
    v = report.violations[0]
    text = FEEDBACK_TEMPLATE.format(
        step_number=report.dangerous_step,
        action_info=report.action or "(initial state, before any action)",
        rule_id=v.id,
        danger_level=v.danger_level,
        rule_warning=v.safety_warning,
        trigger_reason=v.trigger_reason,
        causal_message=v.message,
        objects_str=", ".join(involved_objects(v)) or "(none)",
        suggestion=v.suggestion,
    )
    if report.status == "UNKNOWN" and report.questions:
        # The apprentice must not guess the answers: the user is asked.
        text += (
            "\n[OPEN QUESTIONS FOR THE USER]\n"
            + "\n".join(f"- {q.text}" for q in report.questions)
            + "\n"
        )
    return text


def _wrap(text: str, indent: str) -> str:
    return textwrap.fill(text, width=100, initial_indent=indent, subsequent_indent=indent + "  ")


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
    lines.append(head)
    lines.append(_wrap(report.reason, "  "))
    for i, v in enumerate(report.violations, start=1):
        tag = "" if v.definite else " [needs confirmation]"
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
    if report.trace:
        lines.append("  Trace:")
        for st in report.trace:
            mark = {
                "ok": " ",
                "unsafe": "!",
                "unknown": "?",
                "not-checked": "-",
                "not-simulated": "-",
                "error": "x",
            }[st.outcome]
            note = f"  <- {', '.join(st.findings)}" if st.findings else ""
            if st.outcome in ("not-simulated", "not-checked"):
                note = f"  ({st.outcome.replace('-', ' ')}: verification stopped earlier)"
            lines.append(f"    {mark} {st.step:>2}. {st.action}{note}")
    return "\n".join(lines) + "\n"
