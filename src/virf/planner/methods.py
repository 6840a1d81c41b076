"""The paper's planning methods, selectable by name (Appendix D).

| method | prompt | verification |
|---|---|---|
| ``impulsive`` | plan only | none (one shot) |
| ``thinker`` | reasoning, then plan | none (one shot) |
| ``committee`` | plan only | an LLM critic reviews; the planner revises until it approves |
| ``impulsive+rules`` / ``thinker+rules`` | as above plus every rule in words | none |
| ``thinker+diagnostic`` | reasoning, then plan | one retry with one tutor report |
| ``virf-reject`` | reasoning, then plan | Algorithm 1, feedback "the plan is invalid" |
| ``virf-rag`` / ``virf-manual`` | reasoning, then plan | Algorithm 1 with only the RAG-synthesised / manual rules |
| ``virf`` | reasoning, then plan | Algorithm 1 with the diagnostic report |

The VIRF variants use the reasoning prompt because the paper's own
comparison, Thinker+Diagnostic, builds on Thinker.  A method returns a
:class:`LoopResult`: the final plan (or ``TASK_REJECTED``) and the dialogue.
What happens to that plan (execution, metrics) is the harness's business.

The outcome says whether the tutor verified the final plan: ``APPROVED``
only when the tutor found that very plan SAFE (Algorithm 1, or
Thinker+Diagnostic's first plan); a plan the baselines accept without the
tutor (one shot, the critic's approval, the diagnostic retry) is
``APPROVED_UNVERIFIED``.  The methods themselves are the paper's: the label
changes what a caller may conclude, not what the method does.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from virf.errors import InputError, closest
from virf.ontology.tbox import UnsafeStateConcept, Vocabulary
from virf.planner.apprentices import Apprentice, Purpose
from virf.planner.deadline import DEFAULT_DEADLINE_S, Deadline
from virf.planner.focus import Focus
from virf.planner.loop import SYSTEM, LoopResult, Outcome, Transcript, Turn, Tutor, refine
from virf.planner.prompting import (
    REFUSAL,
    ReadPlan,
    apprentice_prompt,
    read_after_plan_marker,
    read_plan,
    render_rules,
    scene_objects,
    template,
)
from virf.planner.questions import AnswerPolicy, deny
from virf.render.feedback import feedback_prompt
from virf.world.scene import Scene

Mode = Literal["oneshot", "committee", "diagnostic", "loop"]
Knowledge = Literal["all", "manual", "rag"]


@dataclass(frozen=True)
class Method:
    name: str
    thinker: bool
    mode: Mode
    rules: bool = False
    feedback: Literal["diagnostic", "reject"] = "diagnostic"
    knowledge: Knowledge = "all"

    @property
    def verifies(self) -> bool:
        return self.mode in ("diagnostic", "loop")


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("impulsive", False, "oneshot"),
        Method("thinker", True, "oneshot"),
        Method("committee", False, "committee"),
        Method("impulsive+rules", False, "oneshot", rules=True),
        Method("thinker+rules", True, "oneshot", rules=True),
        Method("thinker+diagnostic", True, "diagnostic"),
        Method("virf-reject", True, "loop", feedback="reject"),
        Method("virf-rag", True, "loop", knowledge="rag"),
        Method("virf-manual", True, "loop", knowledge="manual"),
        Method("virf", True, "loop"),
    )
}


def get_method(name: str) -> Method:
    key = re.sub(r"\s*\+\s*", "+", name.strip().lower())
    key = re.sub(r"[\s_]+", "-", key)
    if key not in METHODS:
        near = closest(name, list(METHODS)) or list(METHODS)
        raise InputError(f"unknown method '{name}'; choose from {', '.join(near)}")
    return METHODS[key]


def knowledge_filter(usc: UnsafeStateConcept, knowledge: Knowledge) -> bool:
    """Whether a USC belongs to a method's knowledge base.

    The split follows each rule's *primary* source, the first clause of its
    ``source`` annotation: a manually written rule (``manual: ...``, or the
    paper's "manual rules") belongs to VIRF-Manual's knowledge base,
    anything synthesised from documents (agencies' texts, hazard tables,
    the knowledge-acquisition case study) to VIRF-RAG's.  Uncertainty and
    logical-consistency concepts are part of the tutor itself, so every
    variant keeps them."""
    if knowledge == "all" or usc.kind in ("uncertainty", "logical-inconsistency"):
        return True
    primary = usc.source.split(";")[0].lower()
    manual = primary.startswith("manual:") or "manual rule" in primary
    return manual if knowledge == "manual" else not manual


def run_method(
    method: Method,
    instruction: str,
    scene_data: Mapping[str, Any],
    apprentice: Apprentice,
    tutor: Tutor,
    build_scene: Callable[[Mapping[str, Any]], Scene],
    vocab: Vocabulary,
    *,
    max_iter: int = 5,
    answer: AnswerPolicy = deny,
    task_id: str = "task",
    critic: Apprentice | None = None,
    deadline: Deadline | float = DEFAULT_DEADLINE_S,
    on_turn: Callable[[Turn], None] | None = None,
    checker: Tutor | None = None,
) -> LoopResult:
    """Plan with ``method``; ``tutor`` must already hold the method's knowledge.

    The VIRF methods with the diagnostic report offer the corrections that
    ``checker`` (by default ``tutor``; the same knowledge) verified SAFE.

    ``deadline`` bounds the whole run: when it passes, the task is rejected.
    Seconds start it now; a :class:`Deadline` counts from when it was made."""
    deadline = Deadline.of(deadline)
    rules = render_rules(vocab) if method.rules else ""
    suffix = "\n" + template("thinker") if method.thinker else ""
    read = read_after_plan_marker if method.thinker else read_plan
    if method.mode == "loop":
        generic = template("reject").strip()
        return refine(
            instruction,
            scene_data,
            apprentice,
            tutor,
            build_scene,
            vocab,
            max_iter=max_iter,
            answer=answer,
            task_id=task_id,
            method=method.name,
            rules=rules,
            prompt_suffix=suffix,
            feedback=(lambda _r: generic) if method.feedback == "reject" else feedback_prompt,
            read=read,
            deadline=deadline,
            on_turn=on_turn,
            # VIRF-Reject's ablation gets the generic message and nothing more.
            corrections=(checker or tutor) if method.feedback == "diagnostic" else None,
        )
    scene = build_scene(scene_data)
    # These methods never change the scene: one constraint serves every proposal.
    constraint = (
        Focus.of(instruction, scene, vocab).constraint() if apprentice.constrained else None
    )
    messages = [
        {"role": "system", "content": SYSTEM},
        {"role": "user", "content": apprentice_prompt(instruction, scene, rules) + suffix},
    ]
    log: list[Turn] = Transcript(Turn(0, "user", "instruction", instruction), on_turn)

    def out_of_time(i: int) -> LoopResult | None:
        if not deadline.expired():
            return None
        return LoopResult("TASK_REJECTED", None, i, deadline.reason(), tuple(log))

    def propose(i: int) -> tuple[str, ReadPlan] | LoopResult:
        late = out_of_time(i)
        if late is not None:
            return late
        p = apprentice.propose(
            messages,
            task_id=task_id,
            iteration=i,
            method=method.name,
            # Every proposal after the first answers feedback: a report or a critique.
            purpose=Purpose.PLAN if i == 0 else Purpose.REPAIR,
            deadline=deadline,
            constraint=constraint,
        )
        if not p.ok or p.text is None:
            log.append(Turn(i, "apprentice", "failed-proposal", p.reason))
            return LoopResult(
                "TASK_REJECTED", None, i + 1, f"no usable proposal: {p.reason}", tuple(log)
            )
        got = read(p.text)
        if got.refused:
            log.append(Turn(i, "apprentice", "refusal", p.text))
            return LoopResult("TASK_REJECTED", None, i + 1, "the apprentice refused", tuple(log))
        if got.problem is not None:  # over the plan limit: refused, as `virf verify` does
            log.append(Turn(i, "apprentice", "unreadable", got.problem, data={"reply": p.text}))
            return LoopResult(
                "TASK_REJECTED", None, i + 1, f"the reply's plan: {got.problem}", tuple(log)
            )
        if not got.steps:
            log.append(Turn(i, "apprentice", "unreadable", p.text))
            return LoopResult("TASK_REJECTED", None, i + 1, "the reply holds no plan", tuple(log))
        log.append(
            Turn(
                i,
                "apprentice",
                "proposal",
                "\n".join(s.text for s in got.steps),
                data={"reply": p.text},
            )
        )
        return p.text, got

    first = propose(0)
    if isinstance(first, LoopResult):
        return first
    reply, got = first
    if method.mode == "oneshot":
        return _final(got, 1, "one-shot plan, not verified by the tutor", log)
    if method.mode == "diagnostic":
        report = tutor.verify(scene, got.steps)
        log.append(Turn(0, "tutor", "report", report.reason, report.status))
        if report.status == "SAFE":
            return _final(got, 1, "the tutor approved the plan", log, "APPROVED")
        messages += [
            {"role": "assistant", "content": reply},
            {"role": "user", "content": feedback_prompt(report)},
        ]
        retry = propose(1)
        if isinstance(retry, LoopResult):
            return retry
        return _final(
            retry[1], 2, "plan after one diagnostic retry, not verified by the tutor", log
        )
    # committee: an LLM critic reviews each plan; the planner revises.
    judge = critic or apprentice
    for i in range(max_iter):
        late = out_of_time(i)
        if late is not None:
            return late
        review = judge.propose(
            [
                {"role": "system", "content": "You review robot plans for safety."},
                {
                    "role": "user",
                    "content": template("critic").format(
                        instruction=instruction,
                        objects=scene_objects(scene),
                        plan="\n".join(s.text for s in got.steps),
                    ),
                },
            ],
            task_id=task_id,
            iteration=i,
            method=f"{method.name}-critic",
            purpose=Purpose.CRITIQUE,
            deadline=deadline,
        )
        verdict = (review.text or "").strip()
        log.append(Turn(i, "tutor", "critique", verdict or review.reason))
        if review.ok and critic_approves(verdict):
            return _final(
                got, i + 1, "the critic approved the plan; the tutor did not verify it", log
            )
        if i + 1 == max_iter:
            break
        messages += [
            {"role": "assistant", "content": reply},
            {"role": "user", "content": template("revise").format(critique=verdict or "(none)")},
        ]
        nxt = propose(i + 1)
        if isinstance(nxt, LoopResult):
            return nxt
        reply, got = nxt
    # An unapproved plan is not executed (fail closed).
    return LoopResult(
        "TASK_REJECTED", None, max_iter, "the critic never approved a plan", tuple(log)
    )


# The whole reply is the one word, markdown and closing punctuation allowed
# ("**APPROVE**", "APPROVE."), in any case.
_APPROVAL = re.compile(r"[\s*_`\"']*APPROVE[\s*_`\"'.!]*", re.IGNORECASE)


def critic_approves(reply: str) -> bool:
    """Whether a critic's reply is one clear APPROVE verdict.

    The critic is asked to reply with exactly APPROVE when the plan is safe
    and with a critique otherwise, so anything else is a critique: APPROVE
    followed by doubts or a REJECT, a verdict among reasons, "APPROVED? No".
    Reading a mixed reply as an approval would execute a plan its own critic
    doubted."""
    return _APPROVAL.fullmatch(reply) is not None


def _final(
    got: ReadPlan,
    iterations: int,
    reason: str,
    log: list[Turn],
    outcome: Outcome = "APPROVED_UNVERIFIED",
) -> LoopResult:
    if got.refused:
        return LoopResult("TASK_REJECTED", None, iterations, f"{REFUSAL}", tuple(log))
    plan = tuple(s.text for s in got.steps)
    return LoopResult(outcome, plan, iterations, reason, tuple(log))
