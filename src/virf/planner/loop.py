"""The VIRF refinement loop (the paper's Algorithm 1).

The apprentice proposes a plan and the tutor verifies it:

* **SAFE**: the plan is approved.
* **UNSAFE** or **ERROR**: the diagnostic report goes back to the apprentice
  as its next prompt, and it proposes again.
* **A refusal** (``TASK_ABORT``): ``TASK_REJECTED``.
* **UNKNOWN**: the report's questions that an answer can settle go to the
  user (:mod:`virf.planner.questions`). When the answers settle something,
  the scene is updated and the same plan is verified again, within the same
  iteration. When nothing is settled, the report goes to the apprentice like
  an unsafe one: the plan cannot be approved on assumptions. A question is
  asked at most ``MAX_ASKS`` times per plan.

Each proposal uses one of ``max_iter`` iterations. When they run out, the
outcome is ``TASK_REJECTED``.

This module does not import the reasoner. The tutor comes in as any object
with ``verify(scene, plan) -> Report``, and scenes are built by the function
it is given.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, Protocol

from virf.feedback import feedback_prompt
from virf.kb.scene import Scene
from virf.kb.tbox import Vocabulary
from virf.planner.apprentices import Apprentice
from virf.planner.prompting import ReadPlan, apprentice_prompt, read_plan, unreadable_message
from virf.planner.questions import SETTLEABLE, AnswerPolicy, apply_answers, deny
from virf.schema import Report
from virf.sim.plan import PlanStep

Outcome = Literal["APPROVED", "TASK_REJECTED"]
# An answer can settle a question and still leave it open in the next report
# (a referent the simulator cannot use, a receptacle that changes nothing):
# asking again once is enough to let a person correct a slip.
MAX_ASKS = 2
SYSTEM = (
    "You plan actions for a household robot. Answer with a plan in the requested "
    "format, or TASK_ABORT when the task cannot be done safely."
)


class Tutor(Protocol):
    def verify(self, scene: Scene, plan: Sequence[PlanStep]) -> Report: ...


@dataclass(frozen=True)
class Turn:
    """One entry of the dialogue transcript."""

    iteration: int
    speaker: Literal["user", "apprentice", "tutor"]
    kind: str  # instruction, proposal, refusal, failed-proposal, unreadable, report, questions, answers
    text: str
    status: str | None = None
    data: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class LoopResult:
    outcome: Outcome
    plan: tuple[str, ...] | None
    iterations: int
    reason: str
    transcript: tuple[Turn, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        return {
            "outcome": self.outcome,
            "plan": list(self.plan) if self.plan is not None else None,
            "iterations": self.iterations,
            "reason": self.reason,
            "transcript": [asdict(t) for t in self.transcript],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)


def refine(
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
    method: str = "virf",
    rules: str = "",
    prompt_suffix: str = "",
    feedback: Callable[[Report], str] = feedback_prompt,
    read: Callable[[str], ReadPlan] = read_plan,
) -> LoopResult:
    """Run Algorithm 1 for one instruction in one scene.

    ``feedback`` turns a rejected report into the apprentice's next prompt
    (the paper's diagnostic template by default; VIRF-Reject's generic
    message for that ablation). ``prompt_suffix`` and ``read`` let a method
    ask for reasoning before the plan and read the plan after it."""
    if max_iter < 1:
        raise ValueError("max_iter must be at least 1")
    data = dict(scene_data)
    scene = build_scene(data)
    prompt = apprentice_prompt(instruction, scene, rules) + prompt_suffix
    messages: list[dict[str, str]] = [
        {"role": "system", "content": SYSTEM},
        {"role": "user", "content": prompt},
    ]
    log: list[Turn] = [Turn(0, "user", "instruction", instruction)]
    plan: tuple[PlanStep, ...] | None = None  # the plan under verification
    reply = ""
    for i in range(max_iter):
        if plan is None:
            proposal = apprentice.propose(messages, task_id=task_id, iteration=i, method=method)
            if not proposal.ok or proposal.text is None:
                log.append(Turn(i, "apprentice", "failed-proposal", proposal.reason))
                return LoopResult(
                    "TASK_REJECTED",
                    None,
                    i + 1,
                    f"no usable proposal: {proposal.reason}",
                    tuple(log),
                )
            reply = proposal.text
            got = read(reply)
            if got.refused:
                log.append(Turn(i, "apprentice", "refusal", reply))
                return LoopResult(
                    "TASK_REJECTED", None, i + 1, "the apprentice refused", tuple(log)
                )
            if got.unreadable or not got.steps:
                log.append(Turn(i, "apprentice", "unreadable", reply))
                messages += [
                    {"role": "assistant", "content": reply},
                    {"role": "user", "content": unreadable_message(got)},
                ]
                continue
            plan = got.steps
            log.append(
                Turn(
                    i,
                    "apprentice",
                    "proposal",
                    "\n".join(s.text for s in plan),
                    data={"reply": reply},  # the plan as read, and the words it came in
                )
            )
        report = tutor.verify(scene, plan)
        log.append(
            Turn(i, "tutor", "report", report.reason, report.status, json.loads(report.to_json()))
        )
        # UNKNOWN: ask, update the scene, verify the same plan again. This is
        # part of the same iteration, so answers given in the last one count.
        # It ends: every round asks a question at least once more, and the
        # questions a plan can raise are bounded by the scene and the plan
        # (an answer adds at most the one object a question named).
        asked: Counter[str] = Counter()
        while report.status == "UNKNOWN":
            questions = [
                q for q in report.questions if q.kind in SETTLEABLE and asked[q.key] < MAX_ASKS
            ]
            if not questions:
                break
            asked.update(q.key for q in questions)
            log.append(
                Turn(
                    i,
                    "tutor",
                    "questions",
                    "\n".join(q.text for q in questions),
                    data={"questions": [q.model_dump(mode="json") for q in questions]},
                )
            )
            answers = answer(questions)
            update = apply_answers(data, questions, answers, vocab)
            log.append(Turn(i, "user", "answers", json.dumps(dict(answers), sort_keys=True)))
            if not update.applied:
                break
            data = update.scene
            scene = build_scene(data)
            report = tutor.verify(scene, plan)
            log.append(
                Turn(
                    i, "tutor", "report", report.reason, report.status, json.loads(report.to_json())
                )
            )
        if report.status == "SAFE":
            steps = tuple(s.text for s in plan)
            return LoopResult("APPROVED", steps, i + 1, "the tutor approved the plan", tuple(log))
        # UNSAFE, ERROR, or UNKNOWN nobody could settle: the apprentice repairs.
        messages += [
            {"role": "assistant", "content": reply},
            {"role": "user", "content": feedback(report)},
        ]
        plan = None
    return LoopResult(
        "TASK_REJECTED", None, max_iter, f"no approved plan after {max_iter} iterations", tuple(log)
    )
