"""Report assembly: the verifier's findings, step by step, become a :class:`Report`.

The status follows from the findings: UNSAFE at the first step with a
definite finding, else UNKNOWN at the first step with any finding, else SAFE.
The report leads with the highest-ranked finding of that step, lists every
finding there as a violation, and gathers the questions of every step up to
it (an UNKNOWN report: of every step).  Its problem is a hazard when any
finding at that step is one, else a step the plan cannot run; hazards rank
first, so a hazard leads when there is one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Literal

from virf.schema import (
    CausalChain,
    Fact,
    Problem,
    Provenance,
    Question,
    Report,
    Status,
    StepTrace,
    ViolatedConcept,
    Violation,
)
from virf.verify.findings import Finding, ai2thor_refuses, problem, rank
from virf.world.plan import PlanStep
from virf.world.simulate import Trace
from virf.world.state import diff

Outcome = Literal["ok", "unsafe", "unknown", "not-checked", "not-simulated", "error"]


def build_report(
    plan: Sequence[PlanStep],
    trace: Trace,
    findings: Mapping[int, Sequence[Finding]],
    first_definite: int | None,
    spelling: Mapping[Fact, Fact],
    *,
    checked: int,
    rules: int,
    scenario: str,
    engine: str,
    notes: Sequence[str] = (),
) -> Report:
    """The report on ``plan``, simulated as ``trace``.

    ``findings`` are by step; ``first_definite`` is the step the verifier
    stopped at for a definite finding (``None`` if none); ``spelling`` maps
    canonical scene facts to the scene's own statements; ``checked`` is the
    last snapshot the reasoner answered for; ``rules`` is how many safety
    rules were checked."""
    status: Status
    if first_definite is not None:
        status, step = "UNSAFE", first_definite
    elif findings:
        status, step = "UNKNOWN", min(findings)
    else:
        status, step = "SAFE", None
    at_step = sorted(findings.get(step, []) if step is not None else [], key=rank)
    questions: dict[str, Question] = {}  # by key: the first finding asking it words it
    for s in sorted(findings):
        if step is not None and s > step and status == "UNSAFE":
            break
        for f in sorted(findings[s], key=rank):
            for q in f.questions:
                questions.setdefault(q.key, q)
    violations = tuple(build_violation(f, spelling) for f in at_step)
    primary = violations[0] if violations else None
    kind: Problem | None = None
    if primary is not None:
        kind = "hazard" if any(v.problem == "hazard" for v in violations) else "not-executable"
    action = None
    if step is not None and 1 <= step <= len(plan):
        action = plan[step - 1].text
    if primary is None:
        reason = (
            f"every simulated state and action satisfies the {rules} safety rules "
            f"of scenario '{scenario}'"
        )
    elif status == "UNSAFE":
        reason = f"step {step}: {primary.description}"
    else:
        reason = f"step {step}: safety depends on facts that are not known ({primary.description})"
    return Report(
        status=status,
        problem=kind,
        dangerous_step=step,
        action=action,
        violated_concept=ViolatedConcept(id=primary.id, description=primary.description)
        if primary
        else None,
        causal_chain=CausalChain(
            message=primary.message,
            triggering_facts=primary.triggering_facts,
            background=primary.background,
        )
        if primary
        else None,
        violations=violations,
        questions=tuple(questions.values()),
        suggestion=primary.suggestion if primary else None,
        danger_level=primary.danger_level if primary else None,
        category=primary.category if primary else None,
        reason=reason,
        plan=tuple(s.text for s in plan),
        trace=build_trace(plan, trace, findings, checked),
        notes=tuple(notes),
        engine=engine,
        scenario=scenario,
    )


def build_violation(f: Finding, spelling: Mapping[Fact, Fact]) -> Violation:
    """One finding as the report lists it."""
    u = f.concept
    trig = tuple(x.triple() for x in f.facts if f.provenance.get(x) is not Provenance.DEFAULT)
    assumed = tuple(x.triple() for x in f.facts if f.provenance.get(x) is Provenance.ASSUMED)
    # The canonical facts are what every spelling of the scene shares; the
    # user's own statements behind them are shown beside them.
    written = tuple(
        dict.fromkeys(
            spelling[x].triple()
            for x in f.facts
            if x in spelling and f.provenance.get(x) is Provenance.SCENE
        )
    )
    return Violation(
        id=u.id,
        name=u.name,
        kind=u.kind,
        category=u.category,
        danger_level=u.danger_level,
        description=u.description,
        safety_warning=u.safety_warning,
        trigger_reason=u.trigger_reason,
        suggestion=u.suggestion,
        source=u.source,
        step=f.step,
        phase=f.phase,
        problem=problem(f),
        ai2thor_refuses=ai2thor_refuses(f),
        subject=f.subject,
        definite=f.definite,
        message=f.message,
        triggering_facts=trig,
        assumed_facts=assumed,
        as_written=written,
        background=tuple(f.background),
    )


def build_trace(
    plan: Sequence[PlanStep],
    trace: Trace,
    findings: Mapping[int, Sequence[Finding]],
    checked: int,
) -> tuple[StepTrace, ...]:
    """Each plan step's outcome and what it changed in the world."""
    states, stop = trace.states, trace.stop
    out = []
    for i, step in enumerate(plan, start=1):
        ids = tuple(sorted({f.concept.id for f in findings.get(i, [])}))
        fs = findings.get(i, [])
        outcome: Outcome = "unsafe" if any(f.definite for f in fs) else "unknown" if fs else "ok"
        if i > checked and not fs:
            outcome = "not-checked"
        if i < len(states):
            added, removed = diff(states[i - 1], states[i])
            out.append(
                StepTrace(
                    step=i,
                    action=step.text,
                    outcome=outcome,
                    findings=ids,
                    added=added,
                    removed=removed,
                )
            )
        else:
            stopped_here = stop is not None and stop.step.index == i
            out.append(
                StepTrace(
                    step=i,
                    action=step.text,
                    outcome=outcome if stopped_here else "not-simulated",
                    findings=ids,
                )
            )
    return tuple(out)


def error_report(plan: Sequence[PlanStep], reason: str, *, engine: str, scenario: str) -> Report:
    """An ERROR report: the plan could not be verified, so it is not approved."""
    return Report(
        status="ERROR",
        dangerous_step=None,
        action=None,
        violated_concept=None,
        causal_chain=None,
        violations=(),
        questions=(),
        suggestion=None,
        danger_level=None,
        category=None,
        reason=reason + " (fail closed: the plan is not approved)",
        plan=tuple(s.text for s in plan),
        trace=(),
        engine=engine,
        scenario=scenario,
    )
