"""The chat-completions apprentice, over the official ``openai`` SDK.

One client serves every server that speaks OpenAI's chat-completions protocol;
only the base URL (and the key) change:

=================  ==========================================================
OpenAI             ``https://api.openai.com/v1`` (the default)
Gemini             ``https://generativelanguage.googleapis.com/v1beta/openai/``
vLLM               ``http://127.0.0.1:8000/v1``
Ollama             ``http://127.0.0.1:11434/v1``
llama.cpp server   ``http://127.0.0.1:8080/v1``
LM Studio          ``http://127.0.0.1:1234/v1``
=================  ==========================================================

The settings of a client and the reading of a reply body live in
:mod:`virf.planner.chat`; this module is the transport.

The SDK retries 429, 408/409, 5xx, timeouts and dropped connections with
exponential backoff (honouring ``retry-after-ms``/``retry-after``), so this
module only decides what each final outcome means for the refinement loop.

Two wall-clock deadlines bound a request, because httpx's timeouts bound each
network operation only and restart with every byte: a server that trickles
one byte a second would otherwise hold a request for as long as it likes.

* Each HTTP attempt must be over ``timeout_s`` seconds after it started.  A
  reply that has not begun by then (no status line and headers) is a timeout,
  retried like a silent server; one that began but is still arriving is
  abandoned and the proposal fails, without a retry or a re-ask.
* The run's deadline (:class:`virf.planner.deadline.Deadline`) bounds the
  whole request, retries and back-off included; when it passes the request is
  abandoned and the proposal fails.

Both are enforced by running the SDK's asynchronous client on an event loop
the apprentice owns and cancelling the request's task: cancellation stops the
pending read at once and closes the connection, and no thread is left behind.
The synchronous client offers no such handle: a read blocked in a worker
thread is not woken by closing the client from another thread, so the thread
would outlive the request.  Streaming with a check between chunks would still
wait for each whole chunk, and not every compatible server streams.

With ``constrain`` set, a request for a plan that carries the scene's
constraint asks for structured output (``response_format`` with a strict
JSON schema whose steps are the valid plan lines,
:meth:`virf.planner.constraint.PlanConstraint.json_schema`); the JSON reply
becomes plan text before it is logged or read, so replays and the reader see
what an unconstrained reply would look like.  A server that rejects the
option (HTTP 400 or 422, or an error that names ``response_format``) is
asked again at once in plain text, and for the rest of the run; a warning
and the logged call's reason say so.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import logging
import re
import time
from collections.abc import Callable, Coroutine, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Final, NoReturn, TypeVar

import openai
from openai.types.chat import (
    ChatCompletionAssistantMessageParam,
    ChatCompletionContentPartImageParam,
    ChatCompletionContentPartParam,
    ChatCompletionContentPartTextParam,
    ChatCompletionMessageParam,
    ChatCompletionSystemMessageParam,
    ChatCompletionUserMessageParam,
)

try:  # newer SDKs speak through httpx2, older ones through httpx
    import httpx2 as httpx
except ImportError:  # pragma: no cover
    import httpx  # type: ignore[no-redef, import-not-found, unused-ignore]

from virf.errors import EnvironmentProblem, InputError, VirfError, clip
from virf.planner.apprentices import Apprentice, Proposal, ProposalRequest, sum_known
from virf.planner.chat import BASE_URL_ENV, ClientSettings, one_line, read_reply
from virf.planner.runlog import RunLog

_T = TypeVar("_T")
_LOG = logging.getLogger(__name__)

# Raw reply bodies can be large HTML error pages; the log keeps enough to debug.
_RAW_LOG_LIMIT: Final = 10_000
_CONTEXT_OVERFLOW: Final = re.compile(
    r"context[_ ](length|window)|maximum context|too many tokens|prompt is too long|"
    r"exceeds the (model's )?(maximum|max)",
    re.IGNORECASE,
)


def _sdk_messages(request: ProposalRequest) -> list[ChatCompletionMessageParam]:
    out: list[ChatCompletionMessageParam] = []
    with_images = request.last_user() if request.images else -1
    for n, (role, content) in enumerate(request.messages):
        if role == "system":
            out.append(ChatCompletionSystemMessageParam(role="system", content=content))
        elif role == "user" and n == with_images:
            # The vision form every compatible server reads: text, then each
            # image as a data URL (no server here can fetch a file path).
            parts: list[ChatCompletionContentPartParam] = [
                ChatCompletionContentPartTextParam(type="text", text=content)
            ]
            parts += [
                ChatCompletionContentPartImageParam(
                    type="image_url", image_url={"url": image.data_url()}
                )
                for image in request.images
            ]
            out.append(ChatCompletionUserMessageParam(role="user", content=parts))
        elif role == "user":
            out.append(ChatCompletionUserMessageParam(role="user", content=content))
        else:
            out.append(ChatCompletionAssistantMessageParam(role="assistant", content=content))
    return out


@dataclass(frozen=True)
class _Reply:
    """One chat-completions call after the SDK's retries."""

    text: str | None
    problem: str | None
    raw: str | None
    prompt_tokens: int | None
    completion_tokens: int | None
    latency_ms: float
    attempts: int
    # A context overflow would fail the same way again, so it is not re-asked.
    reask: bool = True
    # What the log should know of a call that succeeded differently than asked.
    note: str = ""


class _ReplyDeadline(openai.OpenAIError):
    """A reply still arriving when its attempt's time was up.

    An ``OpenAIError``, which the SDK passes on as it is instead of retrying:
    a server that was sending and did not finish would only be slow again.
    """

    def __init__(self, seconds: float, received: int) -> None:
        super().__init__(
            f"the reply did not finish within its {seconds:g} s deadline (--timeout); "
            f"abandoned after {received} bytes"
        )


class _RunDeadline(Exception):
    """The run's deadline passed while a request was running (or before it was sent)."""


class _DeadlineHttpClient(openai.DefaultAsyncHttpxClient):
    """The SDK's HTTP client, with each attempt bounded to ``reply_s`` seconds in all."""

    def __init__(self, reply_s: float, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.reply_s = reply_s
        self.sent = 0  # HTTP attempts, retries included

    async def send(
        self, request: httpx.Request, *, stream: bool = False, **kwargs: Any
    ) -> httpx.Response:
        self.sent += 1
        until = asyncio.get_running_loop().time() + self.reply_s
        try:
            async with asyncio.timeout_at(until):
                response = await super().send(request, stream=True, **kwargs)
        except TimeoutError:
            # Nothing began: the same outcome as httpx's own read timeout, so
            # the SDK retries it as it retries a silent server.
            raise httpx.ReadTimeout(
                f"no reply began within {self.reply_s:g} s", request=request
            ) from None
        if stream:  # a streamed body is the caller's to bound; proposals never stream
            return response
        try:
            async with asyncio.timeout_at(until):
                await response.aread()
        except BaseException as exc:
            # An unfinished body leaves the connection unusable: closing the
            # response closes it instead of returning it to the pool.
            await response.aclose()
            if isinstance(exc, TimeoutError):
                raise _ReplyDeadline(self.reply_s, response.num_bytes_downloaded) from None
            raise
        return response


class OpenAIApprentice(Apprentice):
    """An apprentice behind any OpenAI-compatible chat-completions server.

    An empty or malformed reply is asked for once more with the same messages;
    a second one makes a failed proposal.  Failures the loop cannot work around
    (no connection, a rejected key, an unknown model, retries exhausted) are
    logged and raised as one-line ``EnvironmentProblem``/``InputError``.
    """

    def __init__(
        self,
        settings: ClientSettings,
        *,
        run_log: RunLog | None = None,
        environ: Mapping[str, str] | None = None,
    ) -> None:
        super().__init__(run_log=run_log)
        self.settings = settings
        self.endpoint = settings.resolve(environ)
        self._http = _DeadlineHttpClient(settings.timeout_s)
        self._client = openai.AsyncOpenAI(
            api_key=self.endpoint.api_key,
            base_url=self.endpoint.base_url,
            timeout=settings.timeout_s,
            max_retries=settings.max_retries,
            http_client=self._http,
        )
        # One event loop for the apprentice's life, so that connections are
        # reused from one proposal to the next.
        self._runner = asyncio.Runner()
        self._closed = False
        # Why structured output is off for the rest of the run, once a server refused it.
        self.plain_text_reason: str | None = None

    @property
    def label(self) -> str:
        return f"openai:{self.settings.model}"

    @property
    def model(self) -> str:
        return self.settings.model

    @property
    def constrained(self) -> bool:
        return self.settings.constrain

    def _response_format(self, request: ProposalRequest) -> dict[str, Any] | None:
        constraint = request.constraint
        if (
            not self.settings.constrain
            or self.plain_text_reason is not None
            or constraint is None
            or not request.purpose.asks_for_plan
        ):
            return None
        return {
            "type": "json_schema",
            "json_schema": {"name": "plan", "strict": True, "schema": constraint.json_schema()},
        }

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._outside_loops(self._shut_down)

    def _shut_down(self) -> None:
        try:
            self._runner.run(self._client.close())
        finally:
            self._runner.close()

    def _run(self, work: Coroutine[Any, Any, _T]) -> _T:
        return self._outside_loops(lambda: self._runner.run(work))

    def _outside_loops(self, call: Callable[[], _T]) -> _T:
        try:
            asyncio.get_running_loop()
        except RuntimeError:
            return call()
        # Called from async code (a notebook): a loop cannot run inside a
        # running one, so the apprentice's loop runs in a helper thread for the
        # length of the call, which the deadlines bound.
        with ThreadPoolExecutor(max_workers=1) as pool:
            return pool.submit(call).result()

    def _propose(self, request: ProposalRequest) -> Proposal:
        replies: list[_Reply] = []
        for ask in (1, 2):
            reply = self._ask(request, ask)
            replies.append(reply)
            if reply.text is not None or not reply.reask or ask == 2:
                break
            self._log_reply(request, reply, ask, reply.problem or "")
        usage: dict[str, Any] = {
            "prompt_tokens": sum_known(r.prompt_tokens for r in replies),
            "completion_tokens": sum_known(r.completion_tokens for r in replies),
            "latency_ms": sum(r.latency_ms for r in replies),
            "attempts": sum(r.attempts for r in replies),
        }
        last = replies[-1]
        if last.text is not None:
            proposal = Proposal.accepted(last.text, **usage)
        else:
            problems = list(dict.fromkeys(r.problem or "no reply" for r in replies))
            asks = "1 ask" if len(replies) == 1 else f"{len(replies)} asks"
            proposal = Proposal.failed(
                f"no usable reply after {asks}: {'; '.join(problems)}", **usage
            )
        # The last call carries the proposal's outcome, so a replay exported
        # from the log reproduces the proposal exactly.
        self._log_reply(request, last, len(replies), proposal.reason or last.note)
        return proposal

    def _log_reply(self, request: ProposalRequest, reply: _Reply, ask: int, reason: str) -> None:
        self._log(
            request,
            reply=reply.raw,
            ok=reply.text is not None,
            reason=reason,
            prompt_tokens=reply.prompt_tokens,
            completion_tokens=reply.completion_tokens,
            latency_ms=reply.latency_ms,
            attempts=reply.attempts,
            ask=ask,
        )

    async def _create(
        self, request: ProposalRequest, response_format: dict[str, Any] | None = None
    ) -> Any:
        remaining = request.deadline.remaining() if request.deadline is not None else None
        if remaining is not None and remaining <= 0:
            raise _RunDeadline
        try:
            async with asyncio.timeout(remaining):
                return await self._client.chat.completions.with_raw_response.create(
                    model=self.settings.model,
                    messages=_sdk_messages(request),
                    extra_body=self.settings.request_body()
                    | ({"response_format": response_format} if response_format else {}),
                )
        except TimeoutError:
            raise _RunDeadline from None

    def _ask(self, request: ProposalRequest, ask: int) -> _Reply:
        started = time.perf_counter()
        sent = self._http.sent
        response_format = self._response_format(request)
        try:
            raw = self._run(self._create(request, response_format))
        except (_RunDeadline, _ReplyDeadline) as exc:
            latency_ms = (time.perf_counter() - started) * 1000
            if isinstance(exc, _RunDeadline):
                assert request.deadline is not None
                problem = f"{request.deadline.reason()}; the request to the model was abandoned"
            else:
                problem = str(exc)
            # Asking again would meet the same deadline, or the same slow server.
            attempts = self._http.sent - sent
            return _Reply(None, problem, None, None, None, latency_ms, attempts, reask=False)
        except openai.OpenAIError as exc:
            latency_ms = (time.perf_counter() - started) * 1000
            if response_format is not None and _refuses_option(exc):
                return self._in_plain_text(request, ask, exc, latency_ms)
            return self._failed_call(request, ask, exc, latency_ms)
        latency_ms = (time.perf_counter() - started) * 1000
        # Older SDKs lack the counter; the attempt itself is then all we know.
        attempts = int(getattr(raw, "retries_taken", 0)) + 1
        body = raw.http_response.text
        content = read_reply(body)
        if response_format is not None and content.text is not None:
            content = content._replace(text=plan_text(content.text))
        return _Reply(
            text=content.text,
            problem=content.problem,
            # A malformed body is logged raw: it is the evidence of what went wrong.
            raw=content.text if content.text is not None else clip(body, _RAW_LOG_LIMIT),
            prompt_tokens=content.prompt_tokens,
            completion_tokens=content.completion_tokens,
            latency_ms=latency_ms,
            attempts=attempts,
        )

    def _in_plain_text(
        self, request: ProposalRequest, ask: int, exc: openai.OpenAIError, latency_ms: float
    ) -> _Reply:
        """The server refused structured output: ask again without it, now
        and for the rest of the run, and say so."""
        assert isinstance(exc, openai.APIStatusError)
        self.plain_text_reason = (
            f"{self.endpoint.base_url} refused structured output (HTTP {exc.status_code}: "
            f"{self._server_message(exc)}); plans are asked for in plain text from now on"
        )
        _LOG.warning("%s", self.plain_text_reason)
        reply = self._ask(request, ask)
        return dataclasses.replace(
            reply,
            latency_ms=reply.latency_ms + latency_ms,
            attempts=reply.attempts + 1,
            note=self.plain_text_reason,
        )

    def _failed_call(
        self, request: ProposalRequest, ask: int, exc: openai.OpenAIError, latency_ms: float
    ) -> _Reply:
        """An SDK error as a failed reply (context overflow), else logged and raised."""
        outcome, attempts = self._classify(exc)
        if isinstance(outcome, str):
            return _Reply(None, outcome, None, None, None, latency_ms, attempts, reask=False)
        self._log(
            request,
            reply=None,
            ok=False,
            reason=str(outcome),
            prompt_tokens=None,
            completion_tokens=None,
            latency_ms=latency_ms,
            attempts=attempts,
            ask=ask,
        )
        _raise(outcome)

    def _classify(self, exc: openai.OpenAIError) -> tuple[VirfError | str, int]:
        """What an SDK error means here, and how many HTTP attempts it took."""
        where = self.endpoint.base_url
        retried = self.settings.max_retries + 1
        if isinstance(exc, openai.APIStatusError):
            code = exc.status_code
            msg = self._server_message(exc)
            if code in (401, 403):
                return EnvironmentProblem(
                    f"{where} rejected the API key (HTTP {code}): {msg}; "
                    f"set {self.endpoint.key_source} to a valid key"
                ), 1
            if code == 404:
                return InputError(
                    f"{where} has no model '{clip(self.settings.model)}' or no chat-completions "
                    f"endpoint (HTTP 404): {msg}; check the model name and that the base URL "
                    "includes the API prefix, e.g. /v1"
                ), 1
            if code in (400, 413, 422) and _CONTEXT_OVERFLOW.search(msg):
                return f"the prompt is too long for the model (HTTP {code}): {msg}", 1
            if code in (400, 422):
                return InputError(
                    f"{where} rejected the request (HTTP {code}): {msg}; check the model name "
                    "and unset options the server does not support (seed, top_p, max_tokens_field)"
                ), 1
            if code == 429:
                return EnvironmentProblem(
                    f"{where} is still rate-limiting (HTTP 429) after up to "
                    f"{self.settings.max_retries} retries: {msg}; wait, or raise max_retries"
                ), retried
            if code >= 500 or code in (408, 409):
                return EnvironmentProblem(
                    f"{where} failed with HTTP {code} after up to "
                    f"{self.settings.max_retries} retries: {msg}"
                ), retried
            return EnvironmentProblem(f"{where} answered HTTP {code}: {msg}"), 1
        if isinstance(exc, openai.APITimeoutError):
            return EnvironmentProblem(
                f"{where} did not answer within {self.settings.timeout_s:g} s "
                f"({retried} attempts); raise the timeout or check the server"
            ), retried
        if isinstance(exc, openai.APIConnectionError):
            cause = one_line(str(exc.__cause__ or exc), 120)
            return EnvironmentProblem(
                f"cannot reach {where}: {cause}; start the server or set the base URL "
                f"(--base-url or {BASE_URL_ENV})"
            ), retried
        return EnvironmentProblem(f"{where}: {self._redact(one_line(str(exc)))}"), 1

    def _server_message(self, exc: openai.APIStatusError) -> str:
        body = exc.body
        message: object = None
        if isinstance(body, dict):
            error = body.get("error")
            if isinstance(error, dict):
                message = error.get("message")
            elif isinstance(error, str):
                message = error
            if message is None:
                message = body.get("message") or body.get("detail")
        if not isinstance(message, str) or not message.strip():
            message = exc.response.text or exc.response.reason_phrase or "no details"
        return self._redact(one_line(str(message)))

    def _redact(self, text: str) -> str:
        # A proxy may echo the request headers; the key must not reach a log.
        key = self.endpoint.api_key
        return text.replace(key, "***") if len(key) >= 8 else text


def _refuses_option(exc: openai.OpenAIError) -> bool:
    """Whether an error is a server refusing a request with structured output:
    a 400 or 422 that is not a prompt too long, or any other status whose
    message names the option (llama.cpp's server answers a ``json_schema``
    it cannot validate with HTTP 500)."""
    if not isinstance(exc, openai.APIStatusError):
        return False
    said = str(exc.body) + exc.response.text
    if exc.status_code in (400, 422):
        return _CONTEXT_OVERFLOW.search(said) is None
    return "response_format" in said


def plan_text(reply: str) -> str:
    """A structured reply (``{"steps": [...]}``) as the plan text the reader
    reads, one step a line; any other reply unchanged, for the reader to judge."""
    try:
        data = json.loads(reply)
    except (json.JSONDecodeError, RecursionError):
        return reply
    steps = data.get("steps") if isinstance(data, dict) else None
    if not isinstance(steps, list) or not steps or not all(isinstance(x, str) for x in steps):
        return reply
    return "\n".join(steps)


def _raise(error: VirfError) -> NoReturn:
    # ``from None``: the SDK's chained traceback would only repeat the one line.
    raise error from None
