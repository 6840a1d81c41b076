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
import logging
import queue
import threading
import time
import uuid
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any, Final, Literal

from pydantic import BaseModel, ConfigDict, Field

from virf.api import LogicTutor
from virf.errors import InputError, VirfError, clip
from virf.planner import RunLog, make_apprentice
from virf.planner.deadline import DEFAULT_DEADLINE_S, Deadline, deadline_seconds
from virf.planner.loop import Turn
from virf.planner.methods import get_method, knowledge_filter, run_method
from virf.planner.questions import Answers, check_answer
from virf.schema import Question
from virf.world.scene import build_scene

_logger = logging.getLogger(__name__)
MAX_RUNS: Final = 100  # kept in memory; the oldest finished ones go first
POLL_S: Final = 0.5  # how often a run log is read for another worker's run or answers
State = Literal["running", "waiting", "done", "failed"]
# The option that sets a run's deadline, as the rejection names it.
DEADLINE_OPTION: Final = "virf serve --deadline"


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
    """A run this worker is carrying out.  With a run log, every change is
    also recorded there, for the other workers to show."""

    def __init__(self, run_id: str, store: RunLog | None = None) -> None:
        self.id = run_id
        self.state: State = "running"
        self.turns: list[dict[str, Any]] = []
        self.questions: list[Question] = []
        self.result: dict[str, Any] | None = None
        self.error: str | None = None
        self.asks = 0  # times the run has waited for answers
        self.changed: Any = threading.Condition()
        # Answers with the wait they answer (``asks``): answers that come too
        # late for one wait must not answer the next one's questions.
        self.answers: queue.Queue[tuple[int, Answers]] = queue.Queue()
        self._store = store
        if store is not None:  # a log that cannot be written refuses the run
            store.save_run(self.id, self.state, self.asks, self.public())

    def public(self) -> dict[str, Any]:
        with self.changed:
            return _public(self)

    def _save(self) -> None:
        if self._store is None:
            return
        try:
            self._store.save_run(self.id, self.state, self.asks, self.public())
        except VirfError as exc:
            # The run goes on; the other workers show it as last recorded.
            _logger.warning("run %s: %s", self.id, exc)

    def _update(self, **changes: Any) -> None:
        with self.changed:
            for key, value in changes.items():
                setattr(self, key, value)
            self._save()
            self.changed.notify_all()

    def add_turn(self, turn: Turn) -> None:
        with self.changed:
            self.turns.append(asdict(turn))
            self._save()
            self.changed.notify_all()


def _public(run: Run | SharedRun) -> dict[str, Any]:
    """What ``GET /v1/runs/{id}`` shows of a run, and what the run log keeps."""
    return {
        "id": run.id,
        "state": run.state,
        "turns": list(run.turns),
        "questions": [q.model_dump(mode="json") for q in run.questions],
        "result": run.result,
        "error": run.error,
        "asks": run.asks,
    }


class _Polled:
    """Stands in for a run's condition when the run is another worker's: a
    wait is a pause, then a fresh read of the run log."""

    def __init__(self, run: SharedRun) -> None:
        self._run = run

    def __enter__(self) -> None:
        return None

    def __exit__(self, *_: object) -> None:
        return None

    def wait(self, timeout: float) -> None:
        time.sleep(min(timeout, POLL_S))
        self._run.reload()


class SharedRun:
    """A run another worker (or machine) is carrying out, as its run log
    records it: shown, streamed and answered through the log."""

    def __init__(self, run_id: str, store: RunLog, body: Mapping[str, Any]) -> None:
        self.id = run_id
        self._store = store
        self.changed = _Polled(self)
        self._read(body)

    def _read(self, body: Mapping[str, Any]) -> None:
        self.state: State = body["state"]
        self.turns: list[dict[str, Any]] = list(body["turns"])
        self.questions = [Question.model_validate(q) for q in body["questions"]]
        self.result: dict[str, Any] | None = body["result"]
        self.error: str | None = body["error"]
        self.asks: int = int(body["asks"])

    def reload(self) -> None:
        body = self._store.load_run(self.id)
        if body is not None:
            self._read(body)

    def public(self) -> dict[str, Any]:
        return _public(self)


class Runs:
    def __init__(
        self,
        tutors: Any,
        *,
        planner: str | None,
        run_log: str | Path | None,
        answer_wait_s: float = 600.0,
        deadline_s: float = DEFAULT_DEADLINE_S,
    ) -> None:
        """``deadline_s`` bounds each run as ``virf plan --deadline`` bounds
        one (the time it waits for answers does not count)."""
        self.tutors, self.planner, self.run_log = tutors, planner, run_log
        self.answer_wait_s = answer_wait_s
        self.deadline_s = deadline_seconds(deadline_s, DEADLINE_OPTION)
        self._runs: dict[str, Run] = {}
        self._lock = threading.Lock()
        # The runs' own record: what lets another worker show a run.
        self.store = RunLog(run_log, run_id="service") if run_log is not None else None

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
        with self._lock:
            finished = [k for k, r in self._runs.items() if r.state in ("done", "failed")]
            for old in finished[: max(0, len(self._runs) - MAX_RUNS + 1)]:
                del self._runs[old]
            try:
                if len(self._runs) >= MAX_RUNS:
                    raise InputError(f"{MAX_RUNS} runs are in progress; wait for one to finish")
                # A whole uuid: runs of several machines share one log.
                run = Run(uuid.uuid4().hex, self.store)
            except BaseException:
                apprentice.close()
                if log is not None:
                    log.close()
                raise
            self._runs[run.id] = run
        checked = tutor
        if method.knowledge != "all":
            checked = tutor.restricted(
                {u.name for u in vocab.uscs.values() if knowledge_filter(u, method.knowledge)}
            )

        # From the moment the run is accepted, as `virf plan` counts from its start.
        clock = Deadline(self.deadline_s, option=DEADLINE_OPTION)

        @clock.excluding  # a person's time to answer is not the machine's
        def policy(questions: Sequence[Question]) -> Answers:
            run._update(state="waiting", questions=list(questions), asks=run.asks + 1)
            given = self._wait_for_answers(run)
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
                        deadline=clock,
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

    def _wait_for_answers(self, run: Run) -> Answers:
        """The answers posted to this worker, or to any worker through the
        run log; none when nobody answers in time (fail closed)."""
        end = time.monotonic() + self.answer_wait_s
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return {}
            try:
                asks, given = run.answers.get(timeout=min(left, POLL_S) if self.store else left)
                if asks == run.asks:
                    return given
                # Answers to an earlier wait, which ended without them.
            except queue.Empty:
                if self.store is not None:
                    posted = self.store.posted_answers(run.id, run.asks)
                    if posted is not None:
                        return posted

    def get(self, run_id: str) -> Run | SharedRun:
        with self._lock:
            run = self._runs.get(run_id)
        if run is not None:
            return run
        body = self.store.load_run(run_id) if self.store is not None else None
        if self.store is None or body is None:
            raise KeyError(run_id)
        return SharedRun(run_id, self.store, body)

    def answer(self, run: Run | SharedRun, answers: Mapping[str, str]) -> None:
        with run.changed:
            if run.state != "waiting":
                raise InputError(f"run {run.id} is {run.state}, not waiting for answers")
            asked = {q.key: q for q in run.questions}
            asks = run.asks
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
        if isinstance(run, Run):
            with run.changed:
                if run.state != "waiting" or run.asks != asks:
                    raise InputError(f"run {run.id} stopped waiting for these answers")
                run.answers.put((asks, settled))
        else:  # another worker's run: it finds them in the log
            assert self.store is not None
            self.store.post_answers(run.id, asks, settled)

    def events(self, run: Run | SharedRun) -> Iterator[str]:
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
