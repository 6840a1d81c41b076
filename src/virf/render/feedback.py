"""The paper's diagnostic feedback prompt (Appendix E) for the LLM apprentice.

The report as text for people is :func:`virf.render.text.render_report`."""

from __future__ import annotations

from collections.abc import Sequence

from virf.files import read_prompt
from virf.schema import Report, Violation
from virf.verify.repairs import Candidate

# The paper's Appendix E template, kept as a file so it can be read and
# adapted without touching code.
FEEDBACK_TEMPLATE = read_prompt("virf.render", "diagnostic.txt")

_NON_OBJECTS = {"rdf:type"}


def involved_objects(v: Violation) -> list[str]:
    names: list[str] = []
    for t in v.triggering_facts:
        for n in (t.subject, *((t.object,) if t.members is None else t.members)):
            if n and n not in names and n[0].isupper() and "_" in n:
                names.append(n)
    names = [n for n in names if not n.startswith("Step")]
    if v.subject and v.subject not in names and not v.subject.startswith("Step"):
        names.insert(0, v.subject)
    return names


# The reply that takes a checked correction as it is: 'USE 2'.  A small model
# copies a short answer far more reliably than a whole plan (copying is what
# llama.cpp's repeat penalty works against), and a large one saves the tokens.
CHOICE = "USE"


def corrections_section(corrections: Sequence[Candidate]) -> str:
    """The checked corrections, each with its whole plan (a small model copies
    better than it edits); '' when there are none, so the paper's prompt is
    left exactly as it was."""
    if not corrections:
        return ""
    parts = [
        "\n[CHECKED CORRECTIONS]\n"
        "Each corrected plan below has been simulated and passes safety verification. "
        f'To take one as it is, reply with exactly "{CHOICE} n" for correction n '
        f'(for example "{CHOICE} 1"); or reply with a plan of your own.\n'
    ]
    for n, c in enumerate(corrections, start=1):
        parts.append(
            f"\nCorrection {n}: {c.edit}\nWhy: {c.why}\nPlan:\n" + "\n".join(c.plan) + "\n"
        )
    return "".join(parts)


def corrections_summary(corrections: Sequence[Candidate]) -> str:
    """The corrections for people reading a run: each edit and its plan."""
    lines = ["Checked corrections (each verified SAFE):"]
    for n, c in enumerate(corrections, start=1):
        lines.append(f"{n}. {c.edit}")
        lines += (f"     {line}" for line in c.plan)
    return "\n".join(lines)


def feedback_prompt(report: Report, corrections: Sequence[Candidate] = ()) -> str:
    """The paper's natural-language feedback prompt, filled from the report,
    and the checked corrections when there are any."""
    return _feedback(report) + corrections_section(corrections)


def _feedback(report: Report) -> str:
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
