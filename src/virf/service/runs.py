"""Tutor–apprentice runs over HTTP: ``POST /v1/plan`` starts one,
``GET /v1/runs/{id}`` shows it, ``GET /v1/runs/{id}/events`` streams its
turns as server-sent events, ``POST /v1/runs/{id}/answers`` answers the
questions of an UNKNOWN report and the run goes on.

A run is the loop ``virf plan`` runs (:func:`virf.planner.methods.run_method`)
in a thread of its own, so a slow model never holds up ``/v1/verify``.  Its
answer policy waits for the client's answers; a run nobody answers within
``answer_wait_s`` takes no answers (fail closed: the plan is not approved on
an open question).  Model calls go to the server's run log.

An event stream is a coroutine on the server's event loop, never a thread:
it awaits the run's next change (:class:`_Changes`, which the run's thread
bumps), so any number of open streams leave the request threads to
``/v1/verify`` and the rest.  A stream of another worker's run reads the run
log every ``POLL_S`` in one of ``LOG_READERS`` threads kept for that.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import queue
import threading
import time
import uuid
from collections.abc import AsyncIterator, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Final, Literal

import anyio
import anyio.to_thread
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
KEEP_ALIVE_S: Final = 15.0  # an idle stream says so this often (proxies drop silent ones)
LOG_READERS: Final = 4  # threads that read the run log for streams of other workers' runs
State = Literal["running", "waiting", "done", "failed"]
# The option that sets a run's deadline, as the rejection names it.
DEADLINE_OPTION: Final = "virf serve --deadline"


class PlanRequest(BaseModel):
    """``POST /v1/plan``."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    scene: dict[str, Any]
    instruction: str = Field(min_length=1, max_length=2000)
    planner: str | None = None  # one of the server's --planner; default: its first
    method: str = "virf"
    max_iter: int = Field(default=5, ge=1, le=20)
    task_id: str = Field(default="task", min_length=1, max_length=200)


class PlannerRefused(InputError):
    """A run named a planner the server was not started with (403)."""


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


@dataclass(frozen=True)
class _View:
    """A run as it stands at one moment, for an event stream."""

    state: State
    turns: tuple[dict[str, Any], ...]
    questions: tuple[dict[str, Any], ...]
    result: dict[str, Any] | None
    error: str | None
    asks: int

    @classmethod
    def of(cls, run: Any) -> _View:
        """The view of anything holding a run's fields (a run, or one read
        from the run log)."""
        return cls(
            run.state,
            tuple(run.turns),
            tuple(q.model_dump(mode="json") for q in run.questions),
            run.result,
            run.error,
            run.asks,
        )


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class _Changes:
    """How many times a run has changed: bumped by the run's thread, awaited by
    its event streams on the event loop, so that a stream waits without a
    thread of its own."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.count = 0
        self._waiters: set[tuple[asyncio.AbstractEventLoop, asyncio.Future[None]]] = set()

    def bump(self) -> None:
        with self._lock:
            self.count += 1
            waiters, self._waiters = self._waiters, set()
        for loop, future in waiters:
            with contextlib.suppress(RuntimeError):  # that loop has closed: nobody waits
                loop.call_soon_threadsafe(_wake, future)

    async def wait(self, seen: int, timeout: float) -> None:
        """Until the count is no longer ``seen``, or ``timeout`` seconds pass."""
        loop = asyncio.get_running_loop()
        waiter = (loop, loop.create_future())
        with self._lock:
            if self.count != seen:
                return
            self._waiters.add(waiter)
        try:
            await asyncio.wait_for(waiter[1], timeout)
        except TimeoutError:
            pass
        finally:
            with self._lock:
                self._waiters.discard(waiter)


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
        # Held only while the run's fields are read or set, never during I/O:
        # an event stream takes it on the event loop.
        self.lock: Any = threading.Lock()
        self.changes = _Changes()
        # Answers with the wait they answer (``asks``): answers that come too
        # late for one wait must not answer the next one's questions.
        self.answers: queue.Queue[tuple[int, Answers]] = queue.Queue()
        self._store = store
        if store is not None:  # a log that cannot be written refuses the run
            store.save_run(self.id, self.state, self.asks, self.public())

    def public(self) -> dict[str, Any]:
        with self.lock:
            return _public(self)

    def view(self) -> _View:
        with self.lock:
            return _View.of(self)

    async def wait_change(self, seen: int, timeout: float) -> None:
        await self.changes.wait(seen, timeout)

    def _changed(self, body: dict[str, Any]) -> None:
        """After a change: record it for the other workers (outside the lock:
        the log may be slow), then wake this worker's streams, so that what a
        stream has told, every worker shows.  Only the run's own thread
        changes a run, so the records keep their order."""
        if self._store is not None:
            try:
                self._store.save_run(self.id, body["state"], body["asks"], body)
            except VirfError as exc:
                # The run goes on; the other workers show it as last recorded.
                _logger.warning("run %s: %s", self.id, exc)
        self.changes.bump()

    def _update(self, **changes: Any) -> None:
        with self.lock:
            for key, value in changes.items():
                setattr(self, key, value)
            body = _public(self)
        self._changed(body)

    def add_turn(self, turn: Turn) -> None:
        with self.lock:
            self.turns.append(asdict(turn))
            body = _public(self)
        self._changed(body)


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


@dataclass(frozen=True)
class _Recorded:
    """A run as the run log last recorded it."""

    state: State
    turns: list[dict[str, Any]]
    questions: list[Question]
    result: dict[str, Any] | None
    error: str | None
    asks: int


class SharedRun:
    """A run another worker (or machine) is carrying out, as its run log
    records it: shown, streamed and answered through the log."""

    def __init__(self, run_id: str, store: RunLog, body: Mapping[str, Any]) -> None:
        self.id = run_id
        self._store = store
        self.lock = contextlib.nullcontext()  # its state is the log's, as last read
        self.changes = _Changes()
        self._read(body)

    def _read(self, body: Mapping[str, Any]) -> None:
        # Read whole, then swapped in at once: a stream may look at any time.
        self._recorded = _Recorded(
            body["state"],
            list(body["turns"]),
            [Question.model_validate(q) for q in body["questions"]],
            body["result"],
            body["error"],
            int(body["asks"]),
        )
        self.changes.bump()

    @property
    def state(self) -> State:
        return self._recorded.state

    @property
    def turns(self) -> list[dict[str, Any]]:
        return self._recorded.turns

    @property
    def questions(self) -> list[Question]:
        return self._recorded.questions

    @property
    def result(self) -> dict[str, Any] | None:
        return self._recorded.result

    @property
    def error(self) -> str | None:
        return self._recorded.error

    @property
    def asks(self) -> int:
        return self._recorded.asks

    def reload(self) -> None:
        body = self._store.load_run(self.id)
        if body is not None:
            self._read(body)

    def public(self) -> dict[str, Any]:
        return _public(self)

    def view(self) -> _View:
        return _View.of(self._recorded)


class Runs:
    def __init__(
        self,
        tutors: Any,
        *,
        planners: Sequence[str] = (),
        run_log: str | Path | None,
        answer_wait_s: float = 600.0,
        deadline_s: float = DEFAULT_DEADLINE_S,
    ) -> None:
        """``deadline_s`` bounds each run as ``virf plan --deadline`` bounds
        one (the time it waits for answers does not count)."""
        self.tutors, self.run_log = tutors, run_log
        # The planners a run may name, as the server's --planner options wrote them.
        self.planners = tuple(dict.fromkeys(p.strip() for p in planners))
        self.answer_wait_s = answer_wait_s
        self.deadline_s = deadline_seconds(deadline_s, DEADLINE_OPTION)
        self._runs: dict[str, Run] = {}
        self._lock = threading.Lock()
        # The runs' own record: what lets another worker show a run.
        self.store = RunLog(run_log, run_id="service") if run_log is not None else None
        # Streams of other workers' runs read the log in at most this many
        # threads at once, never in the ones that serve requests.
        self._readers = anyio.CapacityLimiter(LOG_READERS)

    def planner(self, named: str | None) -> str:
        """The planner of a run that names ``named`` (None: the server's first).

        A client names only a planner the server was started with: anything
        else is refused before it is read, so a path a client writes
        (``replay:/etc/...``, ``local:/...gguf``) is never opened, and no
        answer tells whether it exists."""
        if named is None:
            if not self.planners:
                raise InputError(
                    "no planner: this service was started without --planner, so it runs none"
                )
            return self.planners[0]
        if named.strip() in self.planners:
            return named.strip()
        if not self.planners:
            raise PlannerRefused(
                f"planner '{clip(named)}' is not one this service runs: it runs none "
                "(start it with --planner SPEC, once per planner a run may name)"
            )
        raise PlannerRefused(
            f"planner '{clip(named)}' is not one this service runs; "
            f"choose from {', '.join(self.planners)}"
        )

    def start(self, request: PlanRequest) -> Run:
        spec = self.planner(request.planner)
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
        with run.lock:
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
            with run.lock:
                if run.state != "waiting" or run.asks != asks:
                    raise InputError(f"run {run.id} stopped waiting for these answers")
                run.answers.put((asks, settled))
        else:  # another worker's run: it finds them in the log
            assert self.store is not None
            self.store.post_answers(run.id, asks, settled)

    async def events(self, run: Run | SharedRun) -> AsyncIterator[str]:
        """Server-sent events: each turn as it comes, the questions each time
        the run waits for answers, and the result (or the failure) at the end.

        A coroutine on the event loop: between events it awaits the run's
        next change and holds no thread (a client that goes away cancels it)."""
        sent = 0
        announced = 0  # how many times the run has waited for answers, as told
        while True:
            seen = run.changes.count
            view = run.view()
            idle = sent == len(view.turns) and (
                view.state == "running" or (view.state == "waiting" and view.asks == announced)
            )
            if idle:
                await self._next_change(run, seen)
                view = run.view()
            turns = view.turns[sent:]
            for turn in turns:
                yield _event("turn", turn)
            sent += len(turns)
            if view.state == "waiting" and view.asks > announced:
                announced = view.asks
                yield _event("questions", list(view.questions))
            elif view.state == "done":
                yield _event("result", view.result)
                return
            elif view.state == "failed":
                yield _event("error", {"error": view.error})
                return
            elif not turns:
                yield ": keep-alive\n\n"

    async def _next_change(self, run: Run | SharedRun, seen: int) -> None:
        """Until ``run`` changes, or a keep-alive is due.  Another worker's run
        is read again from the log every ``POLL_S``."""
        if isinstance(run, Run):
            await run.wait_change(seen, KEEP_ALIVE_S)
            return
        await asyncio.sleep(POLL_S)
        try:
            await anyio.to_thread.run_sync(run.reload, limiter=self._readers)
        except VirfError as exc:  # the log is unreachable: show the run as last read
            _logger.warning("run %s: %s", run.id, exc)


def _event(kind: str, data: Any) -> str:
    return f"event: {kind}\ndata: {json.dumps(data, sort_keys=True)}\n\n"
