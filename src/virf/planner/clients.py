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
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import os
import re
import time
from collections.abc import Callable, Coroutine, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Final, Literal, NamedTuple, NoReturn, TypeVar
from urllib.parse import urlsplit

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
from virf.planner.apprentices import (
    Apprentice,
    Proposal,
    ProposalRequest,
    empty_reason,
    sum_known,
)
from virf.planner.runlog import RunLog

_T = TypeVar("_T")

DEFAULT_BASE_URL: Final = "https://api.openai.com/v1"
DEFAULT_API_KEY_ENV: Final = "OPENAI_API_KEY"
BASE_URL_ENV: Final = "OPENAI_BASE_URL"
# Sent to a server on this machine when no key is set: vLLM, Ollama, llama.cpp
# and LM Studio ignore the key unless started with one, but the SDK (and the
# protocol) needs some Authorization header.
LOCAL_PLACEHOLDER_KEY: Final = "no-key-required"
# Raw reply bodies can be large HTML error pages; the log keeps enough to debug.
_RAW_LOG_LIMIT: Final = 10_000
_ENV_NAME: Final = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_CONTEXT_OVERFLOW: Final = re.compile(
    r"context[_ ](length|window)|maximum context|too many tokens|prompt is too long|"
    r"exceeds the (model's )?(maximum|max)",
    re.IGNORECASE,
)


@dataclass(frozen=True)
class ClientSettings:
    """How to reach one model.  ``None`` leaves a sampling setting to the server.

    ``base_url`` falls back to ``$OPENAI_BASE_URL``, then to OpenAI.  The key
    is ``api_key`` when given (e.g. from a user config), else the environment
    variable named by ``api_key_env``.  ``seed`` is sent only when set: OpenAI,
    vLLM, Ollama and llama.cpp accept it, but not every compatible server does.
    ``max_tokens_field`` is ``max_completion_tokens`` for OpenAI's reasoning
    models, which reject ``max_tokens``; most other servers know only
    ``max_tokens``.
    """

    model: str
    base_url: str | None = None
    api_key: str | None = field(default=None, repr=False)
    api_key_env: str = DEFAULT_API_KEY_ENV
    temperature: float | None = 0.0
    top_p: float | None = None
    max_tokens: int | None = 2048
    max_tokens_field: Literal["max_tokens", "max_completion_tokens"] = "max_tokens"
    timeout_s: float = 120.0
    seed: int | None = None
    max_retries: int = 4

    def __post_init__(self) -> None:
        if not isinstance(self.model, str) or not self.model.strip():
            raise InputError("no model name: use openai:MODEL, e.g. openai:gpt-4o-mini")
        if not _ENV_NAME.match(self.api_key_env):
            raise InputError(
                f"API key variable name '{clip(self.api_key_env)}' is not a valid environment "
                "variable name; pass e.g. --api-key-env GEMINI_API_KEY"
            )
        if self.temperature is not None and not number_in(self.temperature, 0.0, 2.0):
            raise InputError(f"temperature {self.temperature!r} is out of range; choose 0 to 2")
        if self.top_p is not None and not (number_in(self.top_p, 0.0, 1.0) and self.top_p > 0):
            raise InputError(f"top_p {self.top_p!r} is out of range; choose a value in (0, 1]")
        if self.max_tokens is not None and not int_at_least(self.max_tokens, 1):
            raise InputError(f"max_tokens {self.max_tokens!r} must be an integer >= 1")
        if self.max_tokens_field not in ("max_tokens", "max_completion_tokens"):
            raise InputError(
                f"max_tokens_field '{clip(str(self.max_tokens_field))}' is unknown; "
                "choose max_tokens or max_completion_tokens"
            )
        if not number_in(self.timeout_s, 0.0, 86_400.0) or self.timeout_s <= 0:
            raise InputError(
                f"timeout {self.timeout_s!r} must be a number of seconds in (0, 86400]"
            )
        if self.seed is not None and not int_at_least(self.seed, 0):
            raise InputError(f"seed {self.seed!r} must be an integer >= 0")
        if not int_at_least(self.max_retries, 0):
            raise InputError(f"max_retries {self.max_retries!r} must be an integer >= 0")
        if self.base_url is not None:
            _check_base_url(self.base_url, "base URL")

    def resolve(self, environ: Mapping[str, str] | None = None) -> Endpoint:
        """Where to send requests and with which key; fails with what to set."""
        env = os.environ if environ is None else environ
        base_url = self.base_url or env.get(BASE_URL_ENV) or DEFAULT_BASE_URL
        _check_base_url(base_url, BASE_URL_ENV if not self.base_url else "base URL")
        base_url = base_url.rstrip("/")
        if self.api_key:
            return Endpoint(base_url, self.api_key, "the api_key setting")
        key = env.get(self.api_key_env, "").strip()
        if key:
            return Endpoint(base_url, key, self.api_key_env)
        if is_local(base_url):
            return Endpoint(base_url, LOCAL_PLACEHOLDER_KEY, self.api_key_env)
        flag = "" if self.api_key_env != DEFAULT_API_KEY_ENV else ", or pass --api-key-env NAME"
        raise EnvironmentProblem(
            f"no API key: set {self.api_key_env}{flag} "
            "(or api_key under [planner] in ~/.config/virf/config.toml)"
        )

    def request_body(self) -> dict[str, object]:
        """The sampling fields of a request; unset ones are left out, not nulled."""
        body: dict[str, object] = {}
        if self.temperature is not None:
            body["temperature"] = self.temperature
        if self.top_p is not None:
            body["top_p"] = self.top_p
        if self.max_tokens is not None:
            body[self.max_tokens_field] = self.max_tokens
        if self.seed is not None:
            body["seed"] = self.seed
        return body


@dataclass(frozen=True)
class Endpoint:
    """A resolved base URL and key.  ``key_source`` names what to fix on a 401."""

    base_url: str
    api_key: str = field(repr=False)
    key_source: str


def number_in(value: object, low: float, high: float) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and low <= value <= high


def int_at_least(value: object, low: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def _check_base_url(url: str, source: str) -> None:
    parts = urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise InputError(
            f"{source} '{clip(url)}' is not an http(s) URL; set it to e.g. "
            "http://127.0.0.1:8000/v1 or https://api.openai.com/v1"
        )


def is_local(base_url: str) -> bool:
    """True for a server on this machine (loopback address or ``localhost``)."""
    host = (urlsplit(base_url).hostname or "").lower()
    if host == "localhost" or host.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


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


def _one_line(text: str, limit: int = 200) -> str:
    return clip(" ".join(text.split()), limit)


def _usage(data: Mapping[str, Any], name: str) -> int | None:
    usage = data.get("usage")
    if not isinstance(usage, dict):
        return None
    value = usage.get(name)
    return value if int_at_least(value, 0) else None


def _content(message: Mapping[str, Any]) -> str | None:
    content = message.get("content")
    if isinstance(content, str):
        return content
    # Some compatible servers send content as a list of typed parts.
    if isinstance(content, list):
        parts = [p.get("text") for p in content if isinstance(p, dict)]
        texts = [p for p in parts if isinstance(p, str)]
        return "".join(texts) if texts else None
    return None


class ReplyContent(NamedTuple):
    """What a chat-completions body holds: the text, or why there is none, and usage."""

    text: str | None
    problem: str | None
    prompt_tokens: int | None
    completion_tokens: int | None


def read_reply(body: str) -> ReplyContent:
    """Read a chat-completions body without trusting its shape."""
    try:
        data = json.loads(body)
    except json.JSONDecodeError:
        return ReplyContent(None, "the reply was not JSON", None, None)
    if not isinstance(data, dict):
        return ReplyContent(None, "the reply was not a JSON object", None, None)
    tokens = _usage(data, "prompt_tokens"), _usage(data, "completion_tokens")
    choices = data.get("choices")
    if not isinstance(choices, list) or not choices:
        return ReplyContent(None, "the reply had no choices", *tokens)
    first = choices[0]
    message = first.get("message") if isinstance(first, dict) else None
    if not isinstance(message, dict):
        return ReplyContent(None, "the reply's first choice had no message", *tokens)
    text = _content(message)
    problem = empty_reason(text)
    refusal = message.get("refusal")
    if problem and isinstance(refusal, str) and refusal.strip():
        problem = f"the model refused: {_one_line(refusal, 120)}"
    return ReplyContent(None if problem else text, problem, *tokens)


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

    @property
    def label(self) -> str:
        return f"openai:{self.settings.model}"

    @property
    def model(self) -> str:
        return self.settings.model

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
        self._log_reply(request, last, len(replies), proposal.reason)
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

    async def _create(self, request: ProposalRequest) -> Any:
        remaining = request.deadline.remaining() if request.deadline is not None else None
        if remaining is not None and remaining <= 0:
            raise _RunDeadline
        try:
            async with asyncio.timeout(remaining):
                return await self._client.chat.completions.with_raw_response.create(
                    model=self.settings.model,
                    messages=_sdk_messages(request),
                    extra_body=self.settings.request_body(),
                )
        except TimeoutError:
            raise _RunDeadline from None

    def _ask(self, request: ProposalRequest, ask: int) -> _Reply:
        started = time.perf_counter()
        sent = self._http.sent
        try:
            raw = self._run(self._create(request))
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
            return self._failed_call(request, ask, exc, latency_ms)
        latency_ms = (time.perf_counter() - started) * 1000
        # Older SDKs lack the counter; the attempt itself is then all we know.
        attempts = int(getattr(raw, "retries_taken", 0)) + 1
        body = raw.http_response.text
        content = read_reply(body)
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
            cause = _one_line(str(exc.__cause__ or exc), 120)
            return EnvironmentProblem(
                f"cannot reach {where}: {cause}; start the server or set the base URL "
                f"(--base-url or {BASE_URL_ENV})"
            ), retried
        return EnvironmentProblem(f"{where}: {self._redact(_one_line(str(exc)))}"), 1

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
        return self._redact(_one_line(str(message)))

    def _redact(self, text: str) -> str:
        # A proxy may echo the request headers; the key must not reach a log.
        key = self.endpoint.api_key
        return text.replace(key, "***") if len(key) >= 8 else text


def _raise(error: VirfError) -> NoReturn:
    # ``from None``: the SDK's chained traceback would only repeat the one line.
    raise error from None
