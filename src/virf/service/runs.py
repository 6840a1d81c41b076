"""Tutor–apprentice runs over HTTP: ``POST /v1/plan`` starts one,
``GET /v1/runs/{id}`` shows it, ``GET /v1/runs/{id}/events`` streams its
turns as server-sent events, ``POST /v1/runs/{id}/answers`` answers the
questions of an UNKNOWN report and the run goes on.

A run is the loop ``virf plan`` runs (:func:`virf.planner.methods.run_method`)
in a thread of its own, so a slow model never holds up ``/v1/verify``.  Its
answer policy waits for the client's answers; a run nobody answers within
``answer_wait_s`` takes no answers (fail closed: the plan is not approved on
an open question).  Model calls go to the server's run log.
"""

from __future__ import annotations

import json
import queue
import threading
import uuid
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any, Final, Literal

from pydantic import BaseModel, ConfigDict, Field

from virf.api import LogicTutor
from virf.errors import InputError, VirfError, clip
from virf.planner import RunLog, make_apprentice
from virf.planner.loop import Turn
from virf.planner.methods import get_method, knowledge_filter, run_method
from virf.planner.questions import Answers, check_answer
from virf.schema import Question
from virf.world.scene import build_scene

MAX_RUNS: Final = 100  # kept in memory; the oldest finished ones go first
State = Literal["running", "waiting", "done", "failed"]


class PlanRequest(BaseModel):
    """``POST /v1/plan``."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    scene: dict[str, Any]
    instruction: str = Field(min_length=1, max_length=2000)
    planner: str | None = None  # openai:MODEL, replay:FILE; default: the server's
    method: str = "virf"
    max_iter: int = Field(default=5, ge=1, le=20)
    task_id: str = Field(default="task", min_length=1, max_length=200)


class AnswersRequest(BaseModel):
    """``POST /v1/runs/{id}/answers``: ``{question key: answer}``."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    answers: dict[str, str]


class _Locked:
    """The loop's tutor: the shared verifier, one verification at a time."""

    def __init__(self, tutor: LogicTutor, lock: threading.Lock) -> None:
        self._verifier, self._lock = tutor.verifier, lock

    def verify(self, scene: Any, plan: Sequence[Any]) -> Any:
        with self._lock:
            return self._verifier.verify(scene, plan)


class Run:
    def __init__(self, run_id: str) -> None:
        self.id = run_id
        self.state: State = "running"
        self.turns: list[dict[str, Any]] = []
        self.questions: list[Question] = []
        self.result: dict[str, Any] | None = None
        self.error: str | None = None
        self.asks = 0  # times the run has waited for answers
        self.changed = threading.Condition()
        self.answers: queue.Queue[Answers] = queue.Queue()

    def public(self) -> dict[str, Any]:
        with self.changed:
            return {
                "id": self.id,
                "state": self.state,
                "turns": list(self.turns),
                "questions": [q.model_dump(mode="json") for q in self.questions],
                "result": self.result,
                "error": self.error,
            }

    def _update(self, **changes: Any) -> None:
        with self.changed:
            for key, value in changes.items():
                setattr(self, key, value)
            self.changed.notify_all()

    def add_turn(self, turn: Turn) -> None:
        with self.changed:
            self.turns.append(asdict(turn))
            self.changed.notify_all()


class Runs:
    def __init__(
        self,
        tutors: Any,
        *,
        planner: str | None,
        run_log: str | Path | None,
        answer_wait_s: float = 600.0,
    ) -> None:
        self.tutors, self.planner, self.run_log = tutors, planner, run_log
        self.answer_wait_s = answer_wait_s
        self._runs: dict[str, Run] = {}
        self._lock = threading.Lock()

    def start(self, request: PlanRequest) -> Run:
        spec = request.planner or self.planner
        if spec is None:
            raise InputError(
                "no planner: give 'planner' (openai:MODEL or replay:FILE) or start the "
                "service with --planner"
            )
        method = get_method(request.method)
        tutor, lock = self.tutors.get(None, None)
        vocab = tutor.tbox.vocabulary
        build_scene(request.scene, vocab)  # a bad scene is a 400 now, not a failed run
        log = RunLog(self.run_log) if self.run_log is not None else None
        try:
            apprentice = make_apprentice(spec, run_log=log)
        except BaseException:
            if log is not None:
                log.close()
            raise
        run = Run(uuid.uuid4().hex[:12])
        with self._lock:
            finished = [k for k, r in self._runs.items() if r.state in ("done", "failed")]
            for old in finished[: max(0, len(self._runs) - MAX_RUNS + 1)]:
                del self._runs[old]
            if len(self._runs) >= MAX_RUNS:
                apprentice.close()
                raise InputError(f"{MAX_RUNS} runs are in progress; wait for one to finish")
            self._runs[run.id] = run
        checked = tutor
        if method.knowledge != "all":
            checked = tutor.restricted(
                {u.name for u in vocab.uscs.values() if knowledge_filter(u, method.knowledge)}
            )

        def policy(questions: Sequence[Question]) -> Answers:
            run._update(state="waiting", questions=list(questions), asks=run.asks + 1)
            try:
                given = run.answers.get(timeout=self.answer_wait_s)
            except queue.Empty:
                given = {}
            run._update(state="running", questions=[])
            return given

        def work() -> None:
            try:
                with apprentice:
                    result = run_method(
                        method,
                        request.instruction,
                        request.scene,
                        apprentice,
                        _Locked(checked, lock),
                        lambda d: build_scene(d, vocab),
                        vocab,
                        max_iter=request.max_iter,
                        answer=policy,
                        task_id=request.task_id,
                        on_turn=run.add_turn,
                    )
                run._update(state="done", result=result.to_dict())
            except VirfError as exc:
                run._update(state="failed", error=str(exc))
            except Exception as exc:  # a bug: the run fails, the service lives on
                run._update(state="failed", error=f"internal error: {type(exc).__name__}: {exc}")
            finally:
                if log is not None:
                    log.close()

        threading.Thread(target=work, name=f"virf-run-{run.id}", daemon=True).start()
        return run

    def get(self, run_id: str) -> Run:
        with self._lock:
            run = self._runs.get(run_id)
        if run is None:
            raise KeyError(run_id)
        return run

    def answer(self, run: Run, answers: Mapping[str, str]) -> None:
        with run.changed:
            if run.state != "waiting":
                raise InputError(f"run {run.id} is {run.state}, not waiting for answers")
            asked = {q.key: q for q in run.questions}
        vocab = self.tutors.get(None, None)[0].tbox.vocabulary
        settled: dict[str, str] = {}
        for key, value in answers.items():
            question = asked.get(key)
            if question is None:
                raise InputError(
                    f"run {run.id} asked no question '{clip(key)}'; it asked: {', '.join(asked)}"
                )
            # The canonical answer, None for one that leaves the question
            # open, an InputError naming the valid choices for one that cannot be used.
            canonical = check_answer(question, value, vocab)
            if canonical is not None:
                settled[key] = canonical
        run.answers.put(settled)

    def events(self, run: Run) -> Iterator[str]:
        """Server-sent events: each turn as it comes, the questions each time
        the run waits for answers, and the result (or the failure) at the end."""
        sent = 0
        announced = 0  # how many times the run has waited for answers, as told
        while True:
            with run.changed:
                idle = sent == len(run.turns) and (
                    run.state == "running" or (run.state == "waiting" and run.asks == announced)
                )
                if idle:
                    run.changed.wait(timeout=15.0)
                turns = run.turns[sent:]
                state, result, error, asks = run.state, run.result, run.error, run.asks
                questions = [q.model_dump(mode="json") for q in run.questions]
            for turn in turns:
                yield _event("turn", turn)
            sent += len(turns)
            if state == "waiting" and asks > announced:
                announced = asks
                yield _event("questions", questions)
            elif state == "done":
                yield _event("result", result)
                return
            elif state == "failed":
                yield _event("error", {"error": error})
                return
            elif not turns:
                yield ": keep-alive\n\n"


def _event(kind: str, data: Any) -> str:
    return f"event: {kind}\ndata: {json.dumps(data, sort_keys=True)}\n\n"
