"""Findings: what the verifier found at one step, before it becomes a report.

A :class:`Finding` is built either from a reasoner's answer (see
:mod:`virf.verify.explain`) or here, from what the simulation itself shows:
an inconsistent snapshot, a plan step naming an unclear, missing or living
object, a failed precondition, or a violated step-bounded requirement.  None
of these builders calls a reasoner; they get what they need as arguments.

:func:`problem` is the one place that says whether a finding is a hazard or
a step the plan cannot run (not executable), and :func:`ai2thor_refuses`
whether AI2-THOR itself would refuse such a step.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from virf.ontology.tbox import UnsafeStateConcept, Vocabulary
from virf.schema import BackgroundKnowledge, Fact, FactKind, Phase, Problem, Provenance, Question
from virf.verify.questions import (
    contradiction_question,
    requirement_question,
    where_question,
    which_question,
)
from virf.verify.requirements import Requirement, Unreadable, check_requirement, step_event
from virf.world.state import MissingObject, PreconditionFailure, ResolvedStep, WorldState

DANGER_RANK = {"critical": 0, "high": 1, "medium": 2, "low": 3}
# Which finding leads when several share a step (after definiteness and danger).
PHASE_RANK: dict[Phase, int] = {
    "requirement": 8,
    "precondition": 0,
    "action": 1,
    "initial": 2,
    "state": 3,
    "final": 4,
    "missing-object": 5,
    "inconsistency": 6,
    "error": 7,
}


@dataclass
class Finding:
    """One unsafe (or possibly unsafe) condition at one step of the plan.

    ``concept`` is the violated Unsafe State Concept (or a synthetic one for
    what the simulator finds itself); ``subject`` is the individual it holds
    for.  ``definite`` findings make the plan UNSAFE; the others make it
    UNKNOWN and carry the ``questions`` that would settle them.  ``facts`` is
    the minimal support (empty when not explained), with each fact's
    ``provenance`` in the snapshot it came from; ``background`` lists the
    TBox knowledge and catalogue defaults the proof relied on.  ``message``
    is the causal chain in words; final-state findings get their onset
    appended after they are built, hence not frozen.
    """

    concept: UnsafeStateConcept
    step: int
    phase: Phase
    subject: str
    definite: bool
    facts: list[Fact]
    provenance: Mapping[Fact, Provenance]
    background: list[BackgroundKnowledge] = field(default_factory=list)
    message: str = ""
    questions: list[Question] = field(default_factory=list)


# Synthetic concepts that are not what their phase or kind says: acting on a
# person is a hazard to them, and a contradictory world makes every
# conclusion unreliable; neither is a step the simulation merely cannot run.
HAZARD_CONCEPTS = frozenset({"ActionOnPerson", "InconsistentWorldModel"})
# Whether AI2-THOR itself refuses the step, for the simulator's own concepts
# (ontology concepts say it with ``:ai2thorRefuses``): an object that is not
# there cannot be acted on; for an ambiguous word the controller acts on one
# of the instances.
SIMULATOR_REFUSES = {"MissingObject": True, "AmbiguousObject": False}


def problem(f: Finding) -> Problem:
    """The kind of problem a finding is: a *hazard* (running the step would be
    unsafe) or a step the plan *cannot run* (a failed precondition, an object
    the scene lacks or cannot pin down, a plan-logic rule).  Both block the
    plan; the report, the bench and the docs keep them apart."""
    if f.concept.id in HAZARD_CONCEPTS:
        return "hazard"
    if f.phase in ("precondition", "missing-object"):
        return "not-executable"
    if f.concept.kind == "logical-inconsistency":
        return "not-executable"
    return "hazard"


def ai2thor_refuses(f: Finding) -> bool | None:
    """Whether AI2-THOR itself would refuse a step the plan cannot run (None
    for a hazard, and for a concept that does not say)."""
    if problem(f) != "not-executable":
        return None
    if f.concept.id in SIMULATOR_REFUSES:
        return SIMULATOR_REFUSES[f.concept.id]
    return {"yes": True, "no": False}.get(f.concept.ai2thor_refuses.strip().lower())


def rank(f: Finding) -> tuple[int, int, int, int, str, str]:
    """Sort key of the findings at one step: the first one leads the report.
    Hazards lead steps the plan cannot run, so a report whose step has a
    hazard leads with it."""
    return (
        0 if problem(f) == "hazard" else 1,
        0 if f.definite else 1,
        DANGER_RANK.get(f.concept.danger_level, 9),
        PHASE_RANK[f.phase],
        f.concept.id,
        f.subject,
    )


def synthetic(
    ident: str,
    kind: str,
    category: str,
    description: str,
    reason: str,
    suggestion: str,
    danger: str = "high",
) -> UnsafeStateConcept:
    """A finding the simulator makes itself (not an ontology concept)."""
    return UnsafeStateConcept(
        id=ident,
        name=ident,
        kind=kind,
        category=category,
        danger_level=danger,
        description=description,
        safety_warning=description,
        trigger_reason=reason,
        suggestion=suggestion,
        source="VIRF sandbox simulator",
    )


def requirement_concept(n: int, text: str, reason: str) -> UnsafeStateConcept:
    """The concept standing for the task's ``n``-th step-bounded requirement."""
    return UnsafeStateConcept(
        id=f"Requirement-{n}",
        name="StepBoundedRequirement",
        kind="temporal-requirement",
        category="Task Requirement",
        danger_level="medium",
        description=text,
        safety_warning="The task states this requirement to avoid a hazard.",
        trigger_reason=reason,
        suggestion="Reorder the plan so that the required action comes within the stated number of steps.",
        source="task instruction (step-bounded requirement)",
    )


INCONSISTENT = UnsafeStateConcept(
    id="InconsistentWorldModel",
    name="InconsistentWorldModel",
    kind="logical-inconsistency",
    category="Uncertainty",
    danger_level="high",
    description="The world model contradicts the knowledge base: these facts cannot all be true.",
    safety_warning="A contradictory world model makes every conclusion unreliable.",
    trigger_reason="the facts contradict the ontology",
    suggestion="Confirm which of the contradictory facts is wrong and correct the scene.",
    source="OWL 2 DL consistency check",
)


def inconsistency(facts: list[Fact], snapshot: Mapping[Fact, Provenance], k: int) -> Finding:
    """Snapshot ``k`` is inconsistent; ``facts`` is a minimal contradictory subset."""
    listed = "; ".join(f.render() for f in facts)
    return Finding(
        INCONSISTENT,
        k,
        "inconsistency",
        facts[0].subject if facts else "",
        False,
        facts,
        dict(snapshot),
        [],
        f"These facts cannot all be true: {listed}.",
        [contradiction_question(k, facts)],
    )


def unclear(stop: MissingObject) -> Finding:
    """The plan's word fits several objects, or names a person as an object."""
    if stop.ambiguous:
        options = " or ".join(stop.near)
        concept = synthetic(
            "AmbiguousObject",
            "uncertainty",
            "Uncertainty",
            "The plan names a type that matches several objects, and nothing says which one is meant.",
            f"step {stop.step.index} refers to '{stop.term}', which could be {options}",
            "Name the object by its instance name in the plan.",
        )
        question = which_question(stop.step.index, stop.step.text, stop.term, stop.near)
        return Finding(
            concept,
            stop.step.index,
            "missing-object",
            stop.term,
            False,
            [],
            {},
            [],
            f"'{stop.term}' is ambiguous: {options}.",
            [question],
        )
    who = stop.near[0]
    concept = synthetic(
        "ActionOnPerson",
        "logical-inconsistency",
        "Logical Inconsistency",
        "The plan manipulates a person or agent as if it were an object.",
        f"step {stop.step.index} would {stop.step.verb} {who}, who is an agent",
        "Never pick up, move or act on a person; ask them, or choose an object.",
        danger="critical",
    )
    fact = Fact(who, "type", "Agent", FactKind.TYPE)
    return Finding(
        concept,
        stop.step.index,
        "precondition",
        who,
        True,
        [fact],
        {fact: Provenance.SCENE},
        [],
        f"{who} is an agent, not an object to {stop.step.verb}.",
    )


def stopped(
    stop: MissingObject | PreconditionFailure, state: WorldState, vocab: Vocabulary
) -> Finding:
    """Why the simulation stopped at ``stop``, in ``state`` (the last one reached)."""
    if isinstance(stop, MissingObject) and (stop.ambiguous or stop.agent):
        return unclear(stop)
    if isinstance(stop, MissingObject):
        near = f" (closest in the scene: {', '.join(stop.near)})" if stop.near else ""
        concept = UnsafeStateConcept(
            id="MissingObject",
            name="MissingObject",
            kind="uncertainty",
            category="Uncertainty",
            danger_level="high",
            description="The plan names an object the scene does not contain.",
            safety_warning="Acting on an object nobody has perceived is acting blind.",
            trigger_reason=f"step {stop.step.index} refers to '{stop.term}', which is not in the scene",
            suggestion=f"Confirm where the {stop.term} is (add it to the scene), or plan without it.",
            source="paper: noise test (object omission)",
        )
        receptacles = [o for o in state.order if vocab.any_is_a(state.objects[o], "Receptacle")]
        question = where_question(
            stop.step.index, stop.step.text, stop.term, stop.near, receptacles
        )
        return Finding(
            concept,
            stop.step.index,
            "missing-object",
            stop.term,
            False,
            [],
            {},
            [],
            f"'{stop.term}' is not in the scene{near}.",
            [question],
        )
    usc = vocab.preconditions[stop.precondition]
    facts = list(stop.facts)
    prov = {f: state.facts.get(f, Provenance.PLAN) for f in facts}
    return Finding(
        usc,
        stop.step.index,
        "precondition",
        stop.subject,
        True,
        facts,
        prov,
        [],
        f"Precondition failed: {stop.message}.",
    )


def requirement_findings(
    requirements: Sequence[Requirement | Unreadable],
    states: Sequence[WorldState],
    resolved: Sequence[ResolvedStep],
    plan_length: int,
    vocab: Vocabulary,
) -> list[Finding]:
    """Step-bounded requirements, checked over the simulated trace."""
    out: list[Finding] = []
    events = [step_event(r, states[i]) for i, r in enumerate(resolved)]
    for n, req in enumerate(requirements, start=1):
        if isinstance(req, Unreadable):
            concept = requirement_concept(n, req.text, "the requirement could not be read")
            question = requirement_question(n, req.text, req.reason, plan_length)
            out.append(
                Finding(
                    concept,
                    plan_length,
                    "requirement",
                    f"requirement {n}",
                    False,
                    [],
                    {},
                    [],
                    f"Unreadable requirement: {req.reason}.",
                    [question],
                )
            )
            continue
        violation = check_requirement(req, events, vocab, len(resolved))
        if violation is None:
            continue
        concept = requirement_concept(n, req.text, violation.message)
        step = (
            violation.deadline_step
            if violation.deadline_step is not None
            else violation.trigger_step
        )
        out.append(
            Finding(
                concept,
                step,
                "requirement",
                f"step {violation.trigger_step}",
                True,
                [],
                {},
                [],
                f"Requirement '{req.text}' is violated: {violation.message}.",
            )
        )
    return out
