"""The chat-completions protocol without a transport: how to reach a model
(:class:`ClientSettings`, resolved to an :class:`Endpoint`) and what a reply
body holds (:func:`read_reply`).

The HTTP client (:mod:`virf.planner.clients`) and the in-process model
(:mod:`virf.planner.local`), whose llama.cpp answers in the same body, share
both; neither part needs the ``openai`` SDK.
"""

from __future__ import annotations

import ipaddress
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Literal, NamedTuple
from urllib.parse import urlsplit

from virf.errors import EnvironmentProblem, InputError, clip
from virf.planner.apprentices import empty_reason

DEFAULT_BASE_URL: Final = "https://api.openai.com/v1"
DEFAULT_API_KEY_ENV: Final = "OPENAI_API_KEY"
BASE_URL_ENV: Final = "OPENAI_BASE_URL"
# Sent to a server on this machine when no key is set: vLLM, Ollama, llama.cpp
# and LM Studio ignore the key unless started with one, but the SDK (and the
# protocol) needs some Authorization header.
LOCAL_PLACEHOLDER_KEY: Final = "no-key-required"
_ENV_NAME: Final = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class ClientSettings:
    """How to reach one model.  ``None`` leaves a sampling setting to the server.

    ``base_url`` falls back to ``$OPENAI_BASE_URL``, then to OpenAI.  The key
    is ``api_key`` when given (e.g. from a user config), else the environment
    variable named by ``api_key_env``.  ``seed`` is sent only when set: OpenAI,
    vLLM, Ollama and llama.cpp accept it, but not every compatible server does.
    ``max_tokens_field`` is ``max_completion_tokens`` for OpenAI's reasoning
    models, which reject ``max_tokens``; most other servers know only
    ``max_tokens``.  ``constrain`` asks the server for a plan as JSON whose
    steps are the scene's valid lines (``response_format``), where it can.
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
    constrain: bool = False

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


def one_line(text: str, limit: int = 200) -> str:
    """A server's words for a one-line message: whitespace runs as one space, clipped."""
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
        problem = f"the model refused: {one_line(refusal, 120)}"
    return ReplyContent(None if problem else text, problem, *tokens)
