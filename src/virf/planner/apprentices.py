"""The apprentice interface the refinement loop calls, and the offline apprentices.

An apprentice turns a chat (the loop's prompt messages) into one plan proposal.
The loop never sees transport details: retries, re-asks and run logging happen
behind ``propose``.  A failed proposal (the model answered nothing usable) is a
``Proposal`` with ``ok=False`` and ``text=None``, so it can never be mistaken
for a plan; problems the loop cannot work around (no server, a rejected key, a
bad replay file) raise a ``VirfError`` with one line.

Offline apprentices:

* ``ReplayApprentice`` re-serves proposals recorded in a JSONL file, one object
  per line, so a recorded LLM run can be re-scored exactly::

      {"task_id": "t1", "iteration": 1, "method": "virf", "text": "find Pot\\npick Pot"}

  ``method`` is optional (an entry without one serves every method); ``ok``,
  ``reason``, ``prompt_tokens``, ``completion_tokens``, ``latency_ms`` and
  ``attempts`` are optional and default to what the text implies.
  ``export_replay`` writes such a file from a run log.
* ``ScriptedApprentice`` serves a fixed queue of replies, for tests.
"""

from __future__ import annotations

import base64
import hashlib
import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Annotated, Any, Final, Self

from pydantic import Field

from virf.errors import InputError, Record, Says, read_input_file
from virf.planner.deadline import Deadline
from virf.planner.runlog import CallRecord, RunLog, last_attempts

if TYPE_CHECKING:
    from virf.planner.constraint import PlanConstraint

ROLES: Final = ("system", "user", "assistant")


class Purpose(StrEnum):
    """What a request asks the model for.  Every caller says it, so an
    apprentice that treats requests differently (a small local model gets
    worked plan examples only when asked for a plan) never has to guess it
    from the prompt's wording."""

    PLAN = "plan"  # the first plan for a task
    # A new plan after feedback: a tutor's report, an unreadable reply, a critique.
    REPAIR = "repair"
    CRITIQUE = "critique"  # the committee's critic reviewing a plan
    DRAFT = "draft"  # candidate knowledge-base rules drafted from evidence passages
    PERCEIVE = "perceive"  # a vision model reading camera images

    @property
    def asks_for_plan(self) -> bool:
        return self in (Purpose.PLAN, Purpose.REPAIR)


@dataclass(frozen=True)
class Proposal:
    """One answer of the apprentice to one request of the loop.

    ``text`` is the model's reply when ``ok``; a failed proposal carries
    ``None`` so no caller can parse it as a plan by accident.  Token counts are
    ``None`` when the server did not report them (they are summed over re-asks).
    ``latency_ms`` is the wall time of every HTTP attempt; ``attempts`` counts
    them, SDK retries and re-asks included.  ``turned_away`` holds the lines
    the tutor refused while the reply was being written, a line at a time
    (:mod:`virf.planner.stepwise`).
    """

    text: str | None
    ok: bool
    reason: str = ""
    prompt_tokens: int | None = None
    completion_tokens: int | None = None
    latency_ms: float = 0.0
    attempts: int = 1
    turned_away: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        # The invariant is what makes "never returned as a plan" checkable.
        if self.ok and (self.text is None or not self.text.strip()):
            raise ValueError("an ok proposal needs non-empty text")
        if not self.ok and self.text is not None:
            raise ValueError("a failed proposal carries no text")
        if not self.ok and not self.reason:
            raise ValueError("a failed proposal needs a reason")

    @classmethod
    def accepted(cls, text: str, **usage: Any) -> Proposal:
        return cls(text=text, ok=True, reason="", **usage)

    @classmethod
    def failed(cls, reason: str, **usage: Any) -> Proposal:
        return cls(text=None, ok=False, reason=reason, **usage)


@dataclass(frozen=True)
class Attachment:
    """An image sent with a request's last user message (a vision model's input).

    The bytes travel as a data URL; the run log keeps only ``ref``, because a
    log holding every camera frame would grow by megabytes a call.
    """

    name: str
    media_type: str
    data: bytes = field(repr=False)

    @property
    def digest(self) -> str:
        return hashlib.sha256(self.data).hexdigest()

    @property
    def ref(self) -> str:
        return f"{self.name} ({self.media_type}, sha256:{self.digest[:16]})"

    def data_url(self) -> str:
        return f"data:{self.media_type};base64,{base64.b64encode(self.data).decode('ascii')}"


@dataclass(frozen=True)
class ProposalRequest:
    """What the loop asked for: the chat, where in the run it belongs and
    what it is for.

    ``deadline`` is the run's: a client abandons a request still running when
    it passes.  It is not part of what is logged or replayed, nor is
    ``purpose`` (a replay is keyed by task, iteration and method, as before).
    ``images`` go with the last user message.  ``constraint`` holds the
    plan lines the scene allows, for an apprentice that can restrict its
    decoding to them (:mod:`virf.planner.constraint`); it is not logged or
    replayed either: the messages say everything the model was told.
    """

    messages: tuple[tuple[str, str], ...]
    task_id: str
    iteration: int
    method: str
    purpose: Purpose
    deadline: Deadline | None = None
    images: tuple[Attachment, ...] = ()
    constraint: PlanConstraint | None = None

    def as_messages(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = [
            {"role": role, "content": content} for role, content in self.messages
        ]
        if self.images:
            out[self.last_user()]["images"] = [image.ref for image in self.images]
        return out

    def last_user(self) -> int:
        """The index of the message the images go with."""
        return max(i for i, (role, _) in enumerate(self.messages) if role == "user")


def check_request(
    messages: Sequence[Mapping[str, str]],
    task_id: str,
    iteration: int,
    method: str,
    purpose: Purpose,
    deadline: Deadline | None = None,
    images: Sequence[Attachment] = (),
    constraint: PlanConstraint | None = None,
) -> ProposalRequest:
    """Validate the loop's arguments once, for every apprentice alike."""
    try:
        purpose = Purpose(purpose)  # its value ("plan") names it too
    except ValueError:
        choices = ", ".join(p.value for p in Purpose)
        raise InputError(f"purpose {purpose!r} is unknown; choose from {choices}") from None
    if not isinstance(task_id, str) or not task_id:
        raise InputError("task_id must be a non-empty string")
    if isinstance(iteration, bool) or not isinstance(iteration, int) or iteration < 0:
        raise InputError(f"iteration must be an integer >= 0, got {iteration!r}")
    if not isinstance(method, str) or not method:
        raise InputError("method must be a non-empty string (the name of the planning method)")
    if not messages:
        raise InputError(f"no messages to send for task {task_id} iteration {iteration}")
    pairs: list[tuple[str, str]] = []
    for n, msg in enumerate(messages, start=1):
        role, content = msg.get("role"), msg.get("content")
        if role not in ROLES:
            raise InputError(f"message {n} has role {role!r}; choose one of {', '.join(ROLES)}")
        if not isinstance(content, str):
            raise InputError(f"message {n} ({role}) has no text 'content'")
        extra = sorted(set(msg) - {"role", "content"})
        if extra:
            raise InputError(
                f"message {n} has unsupported keys {', '.join(extra)}; use role and content"
            )
        pairs.append((role, content))
    if images and not any(role == "user" for role, _ in pairs):
        raise InputError("images need a user message to go with")
    if not all(isinstance(image, Attachment) for image in images):
        raise InputError("images must be Attachment objects")
    return ProposalRequest(
        tuple(pairs), task_id, iteration, method, purpose, deadline, tuple(images), constraint
    )


def empty_reason(text: str | None) -> str | None:
    """Why a reply cannot be a plan, or ``None`` when it can be one."""
    if text is None:
        return "the reply had no text content"
    if not text.strip():
        return "the reply was empty" if not text else "the reply was only whitespace"
    return None


class Apprentice(ABC):
    """An LLM task planner, as the refinement loop sees it.

    Implementations log every request and reply to ``run_log`` when one is
    given, so online and offline runs leave the same trail.
    """

    def __init__(self, *, run_log: RunLog | None = None) -> None:
        self.run_log = run_log

    @property
    @abstractmethod
    def label(self) -> str:
        """The spec this apprentice was built from, e.g. ``openai:gpt-4o``; logged."""

    @property
    def model(self) -> str | None:
        """The model name sent to a server, when there is one."""
        return None

    @property
    def constrained(self) -> bool:
        """Whether plans are decoded within the request's constraint; the
        loop builds one only for an apprentice that uses it."""
        return False

    @property
    def decoding(self) -> str:
        """How a constrained apprentice holds its plans to the constraint
        (a benchmark's configuration records it: other decoding, other plans):
        ``focused`` (the lines about the instruction's objects, at once)."""
        return "focused"

    def propose(
        self,
        messages: Sequence[Mapping[str, str]],
        *,
        task_id: str,
        iteration: int,
        method: str,
        purpose: Purpose,
        deadline: Deadline | None = None,
        images: Sequence[Attachment] = (),
        constraint: PlanConstraint | None = None,
    ) -> Proposal:
        """Ask for what ``purpose`` names: a plan, a repaired plan, a critique,
        a draft or (with ``images``) one reading of them.  Never returns an
        empty or malformed reply as ``ok``.

        A request still running when ``deadline`` passes is abandoned and
        comes back as a failed proposal; offline apprentices answer at once.
        ``constraint`` (the plan lines the scene allows) is a hint an
        apprentice may decode within; the reply is read and verified as any."""
        request = check_request(
            messages, task_id, iteration, method, purpose, deadline, images, constraint
        )
        return self._propose(request)

    @abstractmethod
    def _propose(self, request: ProposalRequest) -> Proposal: ...

    def _log(
        self,
        request: ProposalRequest,
        *,
        reply: str | None,
        ok: bool,
        reason: str,
        prompt_tokens: int | None,
        completion_tokens: int | None,
        latency_ms: float,
        attempts: int,
        ask: int = 1,
    ) -> None:
        if self.run_log is None:
            return
        self.run_log.log_call(
            method=request.method,
            task_id=request.task_id,
            iteration=request.iteration,
            ask=ask,
            apprentice=self.label,
            model=self.model,
            messages=request.as_messages(),
            reply=reply,
            ok=ok,
            reason=reason,
            prompt_tokens=prompt_tokens,
            completion_tokens=completion_tokens,
            latency_ms=latency_ms,
            attempts=attempts,
        )

    def _log_proposal(
        self, request: ProposalRequest, proposal: Proposal, reply: str | None
    ) -> None:
        self._log(
            request,
            reply=reply,
            ok=proposal.ok,
            reason=proposal.reason,
            prompt_tokens=proposal.prompt_tokens,
            completion_tokens=proposal.completion_tokens,
            latency_ms=proposal.latency_ms,
            attempts=proposal.attempts,
        )

    def close(self) -> None:
        """Release network resources; offline apprentices hold none."""
        return None

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


# ---------------------------------------------------------------------------
# Replay

_ReplayKey = tuple[str, int, str | None]
_Count = Annotated[int, Field(ge=0)]


class ReplayEntry(Record):
    """One line of a replay file (the module docstring shows one)."""

    when_not_object = "{where} is not a JSON object"
    when_unknown_key = "{where} has unknown field '{key}'; fields are {expected}"

    task_id: Annotated[str, Field(min_length=1), Says("{where} needs a string 'task_id'")]
    iteration: Annotated[_Count, Says("{where} needs an integer 'iteration' >= 0")]
    method: Annotated[
        Annotated[str, Field(min_length=1)] | None,
        Says("{where}: 'method' must be a non-empty string when given"),
    ] = None
    text: Annotated[str | None, Says("{where}: 'text' must be a string or null")] = None
    ok: Annotated[bool | None, Says("{where}: 'ok' must be true or false")] = None
    reason: Annotated[str | None, Says("{where}: 'reason' must be a string")] = None
    latency_ms: Annotated[
        float, Field(ge=0), Says("{where}: 'latency_ms' must be a number >= 0")
    ] = 0.0
    prompt_tokens: Annotated[_Count | None, Says("{where}: '{key}' must be an integer >= 0")] = None
    completion_tokens: Annotated[
        _Count | None, Says("{where}: '{key}' must be an integer >= 0")
    ] = None
    attempts: Annotated[_Count | None, Says("{where}: '{key}' must be an integer >= 0")] = None


def _replay_entry(entry: Any, where: str) -> tuple[_ReplayKey, Proposal]:
    line = ReplayEntry.parse(entry, where)
    usage: dict[str, Any] = {
        "prompt_tokens": line.prompt_tokens,
        "completion_tokens": line.completion_tokens,
        "latency_ms": line.latency_ms,
        "attempts": line.attempts or 1,
    }
    problem = empty_reason(line.text)
    if line.ok is True and problem is not None:
        raise InputError(f"{where} says ok but {problem}")
    if line.ok is False or problem is not None:
        # A recorded failure replays as the same failure, so re-scoring is exact.
        proposal = Proposal.failed(line.reason or problem or "recorded as failed", **usage)
    else:
        assert line.text is not None
        proposal = Proposal.accepted(line.text, **usage)
    return (line.task_id, line.iteration, line.method), proposal


def load_replay(path: str | Path) -> dict[_ReplayKey, Proposal]:
    """Read a replay JSONL file; every malformed line is a one-line input error."""
    source = read_input_file(path, "replay")
    entries: dict[_ReplayKey, Proposal] = {}
    for lineno, line in enumerate(source.splitlines(), start=1):
        if not line.strip():
            continue
        where = f"replay file {path} line {lineno}"
        try:
            raw = json.loads(line)
        except json.JSONDecodeError as exc:
            raise InputError(f"{where} is not JSON: {exc.msg}") from None
        key, proposal = _replay_entry(raw, where)
        if key in entries:
            task_id, iteration, method = key
            also = f" method {method}" if method else ""
            raise InputError(f"{where} repeats task {task_id} iteration {iteration}{also}")
        entries[key] = proposal
    if not entries:
        raise InputError(f"replay file {path} holds no proposals")
    return entries


class ReplayApprentice(Apprentice):
    """Serves recorded proposals keyed by (task, iteration[, method])."""

    def __init__(self, path: str | Path, *, run_log: RunLog | None = None) -> None:
        super().__init__(run_log=run_log)
        self.path = Path(path)
        self._entries = load_replay(self.path)
        self._uses_methods = any(method is not None for _, _, method in self._entries)

    @property
    def label(self) -> str:
        return f"replay:{self.path}"

    def _propose(self, request: ProposalRequest) -> Proposal:
        found = self._entries.get((request.task_id, request.iteration, request.method))
        if found is None:
            found = self._entries.get((request.task_id, request.iteration, None))
        if found is None:
            also = f" method {request.method}" if self._uses_methods else ""
            raise InputError(
                f"replay file {self.path} has no proposal for task {request.task_id} "
                f"iteration {request.iteration}{also}"
            )
        self._log_proposal(request, found, found.text)
        return found


def export_replay(
    run_log: RunLog,
    run_id: str,
    path: str | Path,
    keep: Callable[[CallRecord], bool] | None = None,
) -> int:
    """Write the proposals of one logged run as a replay file; returns how many.

    A re-asked proposal spans several logged calls; the last call carries the
    outcome, and the usage of all of them is summed, as ``propose`` reported it.
    Only each task's last attempt is written (:func:`last_attempts`), and only
    the calls ``keep`` accepts.  Nothing is written when the log cannot be
    exported.
    """
    grouped: dict[tuple[str, int, str], list[CallRecord]] = {}
    order: list[tuple[str, int, str]] = []
    chosen = [c for c in run_log.calls(run_id=run_id) if keep is None or keep(c)]
    for call in last_attempts(chosen):
        key = (call.task_id, call.iteration, call.method)
        if call.ask == 1:
            if key in grouped:
                raise InputError(
                    f"run {run_id} asked twice for task {call.task_id} iteration "
                    f"{call.iteration} method {call.method}; a replay file keeps one proposal each"
                )
            grouped[key] = []
            order.append(key)
        elif key not in grouped:
            raise InputError(f"run log call {call.id} is a re-ask without a first ask")
        grouped[key].append(call)
    if not order:
        raise InputError(f"run log {run_log.path} has no calls for run '{run_id}'")
    lines = []
    for key in order:
        calls = grouped[key]
        last = calls[-1]
        lines.append(
            json.dumps(
                {
                    "task_id": key[0],
                    "iteration": key[1],
                    "method": key[2],
                    "text": last.reply if last.ok else None,
                    "ok": last.ok,
                    "reason": last.reason,
                    "prompt_tokens": sum_known(c.prompt_tokens for c in calls),
                    "completion_tokens": sum_known(c.completion_tokens for c in calls),
                    "latency_ms": round(sum(c.latency_ms for c in calls), 3),
                    "attempts": sum(c.attempts for c in calls),
                },
                ensure_ascii=False,
                sort_keys=True,
            )
        )
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return len(lines)


def sum_known(values: Iterable[int | None]) -> int | None:
    """A total only when every part is known; a partial sum would understate usage."""
    total = 0
    for value in values:
        if value is None:
            return None
        total += value
    return total


# ---------------------------------------------------------------------------
# Scripted


class ScriptedApprentice(Apprentice):
    """Answers each ``propose`` with the next scripted reply, for tests.

    A string reply is an ok proposal unless it is empty or whitespace (then it
    fails like an empty server reply, without a re-ask: one reply per call); a
    ``Proposal`` is returned as given.  ``requests`` records what was asked.
    """

    def __init__(self, replies: Iterable[str | Proposal], *, run_log: RunLog | None = None) -> None:
        super().__init__(run_log=run_log)
        self.replies = list(replies)
        for n, reply in enumerate(self.replies, start=1):
            if not isinstance(reply, str | Proposal):
                raise InputError(f"scripted reply {n} must be a string or a Proposal")
        self.requests: list[ProposalRequest] = []
        self._served = 0

    @property
    def label(self) -> str:
        return "scripted"

    @property
    def remaining(self) -> int:
        return len(self.replies) - self._served

    def _propose(self, request: ProposalRequest) -> Proposal:
        if self._served >= len(self.replies):
            raise InputError(
                f"no more scripted replies: all {len(self.replies)} were used before "
                f"task {request.task_id} iteration {request.iteration}"
            )
        reply = self.replies[self._served]
        self._served += 1
        self.requests.append(request)
        if isinstance(reply, Proposal):
            proposal = reply
            raw = reply.text
        else:
            problem = empty_reason(reply)
            proposal = Proposal.failed(problem) if problem else Proposal.accepted(reply)
            raw = reply
        self._log_proposal(request, proposal, raw)
        return proposal
