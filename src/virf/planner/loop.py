"""The VIRF refinement loop (the paper's Algorithm 1).

The apprentice proposes a plan and the tutor verifies it:

* **SAFE**: the plan is approved (``APPROVED``: the tutor verified it).
* **UNSAFE** or **ERROR**: the diagnostic report goes back to the apprentice
  as its next prompt, and it proposes again.
* **A refusal** (``TASK_ABORT``): ``TASK_REJECTED``.
* **UNKNOWN**: the report's questions that an answer can settle go to the
  user (:mod:`virf.planner.questions`). When the answers settle something,
  the scene is updated and the same plan is verified again, within the same
  iteration. When nothing is settled, the report goes to the apprentice like
  an unsafe one: the plan cannot be approved on assumptions. A question is
  asked at most ``MAX_ASKS`` times per plan, in at most ``MAX_ROUNDS``
  rounds; the questions still open are listed in the transcript
  (``unsettled``) before the report goes back.

Each proposal uses one of ``max_iter`` iterations. When they run out, the
outcome is ``TASK_REJECTED``; so it is when the run's deadline passes
(:mod:`virf.planner.deadline`), checked before every proposal and every round
of questions.  Every run has one: a caller that gives none gets
``DEFAULT_DEADLINE_S``, the default of ``virf plan --deadline``.  The
baselines of :mod:`virf.planner.methods` that do not have
the tutor verify their final plan end ``APPROVED_UNVERIFIED`` instead of
``APPROVED``.

This module does not import the reasoner. The tutor comes in as any object
with ``verify(scene, plan) -> Report``, and scenes are built by the function
it is given.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, Protocol

from virf.errors import clip
from virf.ontology.tbox import Vocabulary
from virf.planner.apprentices import Apprentice, Purpose
from virf.planner.deadline import DEFAULT_DEADLINE_S, Deadline
from virf.planner.focus import Focus
from virf.planner.prompting import ReadPlan, apprentice_prompt, read_plan, unreadable_message
from virf.planner.questions import SETTLEABLE, AnswerPolicy, Answers, apply_answers, deny
from virf.render.feedback import (
    CHOICE,
    corrections_section,
    corrections_summary,
    feedback_prompt,
)
from virf.schema import Question, Report
from virf.verify.repairs import Candidate, candidates
from virf.world.plan import PlanStep
from virf.world.scene import Scene

# APPROVED: the tutor found the final plan SAFE.  APPROVED_UNVERIFIED: a
# baseline method accepted its plan without the tutor (a one-shot plan, the
# committee's critic, Thinker+Diagnostic's retry).
Outcome = Literal["APPROVED", "APPROVED_UNVERIFIED", "TASK_REJECTED"]
# An answer can settle a question and still leave it open in the next report
# (a referent the simulator cannot use, a receptacle that changes nothing):
# asking again once is enough to let a person correct a slip.
MAX_ASKS = 2
# Every round asks all open questions at once, so another round is needed
# only when an answer brings up a new question (a placed object's material).
# The questions a plan can raise are bounded by the scene and the plan, and
# MAX_ASKS bounds each of them; this bound holds whatever a tutor reports.
MAX_ROUNDS = 8
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
    # instruction, proposal, refusal, failed-proposal, unreadable, report,
    # questions, answers, unsettled, critique, corrections
    kind: str
    text: str
    status: str | None = None
    data: Mapping[str, Any] | None = None


class Transcript(list[Turn]):
    """The dialogue as it grows: each turn is also handed to ``on_turn`` (a
    service streams the run to its client as it happens)."""

    def __init__(self, first: Turn, on_turn: Callable[[Turn], None] | None = None) -> None:
        super().__init__()
        self._on_turn = on_turn
        self.append(first)

    def append(self, turn: Turn) -> None:
        super().append(turn)
        if self._on_turn is not None:
            self._on_turn(turn)


@dataclass(frozen=True)
class LoopResult:
    outcome: Outcome
    plan: tuple[str, ...] | None
    iterations: int
    reason: str
    transcript: tuple[Turn, ...] = field(default_factory=tuple)

    @property
    def verified(self) -> bool:
        """Whether the tutor verified the final plan (found it SAFE)."""
        return self.outcome == "APPROVED"

    def to_dict(self) -> dict[str, Any]:
        return {
            "outcome": self.outcome,
            "verified": self.verified,
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
    deadline: Deadline | float = DEFAULT_DEADLINE_S,
    on_turn: Callable[[Turn], None] | None = None,
    corrections: Tutor | None = None,
) -> LoopResult:
    """Run Algorithm 1 for one instruction in one scene.

    ``feedback`` turns a rejected report into the apprentice's next prompt
    (the paper's diagnostic template by default; VIRF-Reject's generic
    message for that ablation). ``prompt_suffix`` and ``read`` let a method
    ask for reasoning before the plan and read the plan after it.
    ``deadline`` bounds the run: when it passes, the task is rejected.  A
    number of seconds starts it now; a :class:`Deadline` started earlier
    (before loading, as ``virf plan`` does) counts from then.
    ``on_turn`` sees each turn of the transcript as it is added.
    ``corrections``, a tutor with the same knowledge as ``tutor`` (usually
    the same one), adds to an UNSAFE report's feedback the corrected plans it
    has already verified SAFE (:mod:`virf.verify.repairs`), recorded as a
    ``corrections`` turn; a harness that times ``tutor`` passes its untimed
    tutor here, so the checks are not counted as verifications of proposals."""
    if max_iter < 1:
        raise ValueError("max_iter must be at least 1")
    deadline = Deadline.of(deadline)
    data = dict(scene_data)
    scene = build_scene(data)
    prompt = apprentice_prompt(instruction, scene, rules) + prompt_suffix
    messages: list[dict[str, str]] = [
        {"role": "system", "content": SYSTEM},
        {"role": "user", "content": prompt},
    ]
    log: list[Turn] = Transcript(Turn(0, "user", "instruction", instruction), on_turn)
    plan: tuple[PlanStep, ...] | None = None  # the plan under verification
    offered_lines: list[str] = []  # the plan lines of the corrections offered
    last_offered: tuple[Candidate, ...] = ()  # those the last feedback offered
    reply = ""
    for i in range(max_iter):
        if deadline.expired():
            return LoopResult(
                "TASK_REJECTED",
                None,
                i,
                f"{deadline.reason()} before iteration {i + 1}",
                tuple(log),
            )
        if plan is None:
            proposal = apprentice.propose(
                messages,
                task_id=task_id,
                iteration=i,
                method=method,
                # Past the first iteration the last message is feedback to act on.
                purpose=Purpose.PLAN if i == 0 else Purpose.REPAIR,
                deadline=deadline,
                # From the scene as it is now: answers may have changed it.
                # (and widened by every correction offered so far, which the
                # apprentice may copy).
                constraint=(
                    Focus.of(instruction, scene, vocab, line_judge(corrections or tutor, scene))
                    .widen(offered_lines)
                    .constraint()
                    .with_choices(len(last_offered))
                    if apprentice.constrained
                    else None
                ),
            )
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
            chose = got.choice
            if chose is not None and not got.refused:
                got = _chosen(chose, last_offered)
            if got.refused:
                log.append(Turn(i, "apprentice", "refusal", reply))
                return LoopResult(
                    "TASK_REJECTED", None, i + 1, "the apprentice refused", tuple(log)
                )
            if got.problem is not None or got.unreadable or not got.steps:
                if got.problem is not None:
                    # A plan over the limits of a plan file: refused as `virf
                    # verify` refuses it, never verified, never approved.
                    turn = Turn(i, "apprentice", "unreadable", got.problem, data={"reply": reply})
                else:
                    turn = Turn(i, "apprentice", "unreadable", reply)
                log.append(turn)
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
                    # The plan as read, the words it came in, the
                    # correction it took ('USE 2'), if it took one, and the
                    # lines the tutor turned away as it was written.
                    data={"reply": reply}
                    | ({"chose": chose} if chose is not None else {})
                    | ({"turned_away": list(proposal.turned_away)} if proposal.turned_away else {}),
                )
            )
        report = tutor.verify(scene, plan)
        log.append(
            Turn(i, "tutor", "report", report.reason, report.status, json.loads(report.to_json()))
        )
        # UNKNOWN: ask, update the scene, verify the same plan again. This is
        # part of the same iteration, so answers given in the last one count.
        # It ends: every round asks a question at least once more, each
        # question at most MAX_ASKS times, in at most MAX_ROUNDS rounds.
        asked: Counter[str] = Counter()
        given: dict[str, str] = {}
        rounds = 0
        while report.status == "UNKNOWN":
            if deadline.expired():
                log.append(_unsettled(i, report.questions, asked, given))
                return LoopResult(
                    "TASK_REJECTED",
                    None,
                    i + 1,
                    f"{deadline.reason()} while the tutor's questions were open",
                    tuple(log),
                )
            questions = [
                q for q in report.questions if q.kind in SETTLEABLE and asked[q.key] < MAX_ASKS
            ]
            if not questions or rounds == MAX_ROUNDS:
                break
            rounds += 1
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
            given.update(_texts(answers))
            update = apply_answers(data, questions, answers, vocab)
            log.append(
                Turn(
                    i,
                    "user",
                    "answers",
                    json.dumps(dict(answers), sort_keys=True),
                    data={"settled": list(update.applied), "open": list(update.unsettled)},
                )
            )
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
        if report.status == "UNKNOWN":
            log.append(_unsettled(i, report.questions, asked, given))
        if report.status == "SAFE":
            steps = tuple(s.text for s in plan)
            return LoopResult("APPROVED", steps, i + 1, "the tutor approved the plan", tuple(log))
        # UNSAFE, ERROR, or UNKNOWN nobody could settle: the apprentice repairs.
        text = feedback(report)
        if corrections is not None:
            # Searched within what is left of the run; whatever the apprentice
            # replies is verified again like any other proposal.
            left = time.monotonic() + deadline.remaining()
            offered = candidates(scene, plan, report, corrections, vocab, deadline=left)
            last_offered = tuple(offered)
            if offered:
                offered_lines += [line for c in offered for line in c.plan]
                text += corrections_section(offered)
                log.append(
                    Turn(
                        i,
                        "tutor",
                        "corrections",
                        corrections_summary(offered),
                        data={"candidates": [c.to_dict() for c in offered]},
                    )
                )
        messages += [
            {"role": "assistant", "content": reply},
            {"role": "user", "content": text},
        ]
        plan = None
    return LoopResult(
        "TASK_REJECTED", None, max_iter, f"no approved plan after {max_iter} iterations", tuple(log)
    )


def _texts(answers: Answers) -> dict[str, str]:
    return {k: v for k, v in answers.items() if isinstance(k, str) and isinstance(v, str)}


def _unsettled(
    iteration: int, questions: Sequence[Question], asked: Counter[str], given: Mapping[str, str]
) -> Turn:
    """The questions an UNKNOWN report still holds after the answers, and why."""
    rows = []
    for q in questions:
        if q.kind not in SETTLEABLE:
            why = "no answer can settle it"
        elif not asked[q.key]:
            why = "not asked"
        elif not given.get(q.key, "").strip():
            why = "not answered"
        else:
            why = f"answered '{clip(given[q.key].strip())}', still open"
        if asked[q.key] > 1:
            why += f" (asked {asked[q.key]} times)"
        rows.append({"key": q.key, "why": why})
    text = "Still open: " + "; ".join(f"{r['key']} ({r['why']})" for r in rows)
    return Turn(iteration, "tutor", "unsettled", text, data={"unsettled": rows})


def _chosen(n: int, offered: Sequence[Candidate]) -> ReadPlan:
    """The reply 'USE n' read as the n-th correction's plan; a number that
    names none is an unreadable line, answered with what may be said."""
    if 1 <= n <= len(offered):
        return read_plan("\n".join(offered[n - 1].plan))
    choices = f"corrections 1 to {len(offered)} were offered" if offered else "none was offered"
    return ReadPlan((), (f"{CHOICE} {n}: no correction {n}; {choices}",), False)


def line_judge(tutor: Tutor, scene: Scene) -> Callable[[tuple[str, ...]], bool]:
    """The tutor's word on a plan being written a line at a time: whether its
    last line makes nothing unsafe at that step.  A hazard only the plan's end
    shows is left to the verification of the whole plan (a later line may
    settle it); an ERROR turns the line away (fail closed)."""

    def judge(lines: tuple[str, ...]) -> bool:
        got = read_plan("\n".join(lines))
        if got.problem is not None or got.unreadable or len(got.steps) != len(lines):
            return False
        report = tutor.verify(scene, got.steps)
        if report.status == "ERROR":
            return False
        last = len(got.steps)
        return not any(
            v.definite and v.phase != "final" and v.step == last for v in report.violations
        )

    return judge
