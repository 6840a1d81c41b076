"""Scripted OpenAI-compatible chat-completions servers on 127.0.0.1.

The client tests run the real ``openai`` SDK against it: it answers
POST /v1/chat/completions from a queue of ``Reply`` and records what it saw.
``SlowServer`` answers too slowly, for the deadline tests.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler
from typing import Any

import pytest
from http_support import LocalServer, running

from virf.planner import ClientSettings, OpenAIApprentice, RunLog

# Tiny server-directed backoff: the SDK honours retry-after-ms, so retry tests stay fast.
FAST_RETRY = {"retry-after-ms": "5"}


# ---------------------------------------------------------------------------
# The scripted chat-completions server


@dataclass
class Reply:
    status: int = 200
    body: Any = None
    headers: dict[str, str] = field(default_factory=dict)
    delay_s: float = 0.0


def completion(content: Any, prompt_tokens: int = 11, completion_tokens: int = 7) -> Reply:
    return Reply(
        body={
            "id": "chatcmpl-test",
            "object": "chat.completion",
            "created": 0,
            "model": "test-model",
            "choices": [
                {
                    "index": 0,
                    "message": {"role": "assistant", "content": content},
                    "finish_reason": "stop",
                }
            ],
            "usage": {
                "prompt_tokens": prompt_tokens,
                "completion_tokens": completion_tokens,
                "total_tokens": prompt_tokens + completion_tokens,
            },
        }
    )


def error(status: int, message: str, headers: dict[str, str] | None = None) -> Reply:
    return Reply(
        status=status,
        body={"error": {"message": message, "type": "test_error", "code": None}},
        headers=dict(headers or {}),
    )


@dataclass
class Seen:
    path: str
    body: dict[str, Any]
    authorization: str | None


class ChatServer(LocalServer):
    """A chat-completions endpoint that answers from a queue of ``Reply``."""

    def __init__(self) -> None:
        self.script: list[Reply] = []
        self.seen: list[Seen] = []
        self._lock = threading.Lock()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                length = int(self.headers.get("content-length") or 0)
                raw = self.rfile.read(length)
                with server._lock:
                    server.seen.append(
                        Seen(self.path, json.loads(raw), self.headers.get("authorization"))
                    )
                    reply = server.script.pop(0) if server.script else None
                if self.path != "/v1/chat/completions":
                    reply = error(404, f"no route {self.path}")
                if reply is None:
                    # An exhausted script must fail the test at once, not be retried.
                    reply = error(500, "script exhausted", {"x-should-retry": "false"})
                if reply.delay_s:
                    time.sleep(reply.delay_s)
                data = (
                    reply.body.encode()
                    if isinstance(reply.body, str)
                    else json.dumps(reply.body).encode()
                )
                try:
                    self.send_response(reply.status)
                    self.send_header("content-type", "application/json")
                    for name, value in reply.headers.items():
                        self.send_header(name, value)
                    self.send_header("content-length", str(len(data)))
                    self.end_headers()
                    self.wfile.write(data)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client gave up (timeout test); nothing to answer

            def log_message(self, format: str, *args: Any) -> None:
                pass

        self.serve(Handler)

    def queue(self, *replies: Reply) -> None:
        with self._lock:
            self.script.extend(replies)


@pytest.fixture
def server() -> Iterator[ChatServer]:
    with running(ChatServer()) as srv:
        yield srv


# Long enough that a client without a deadline would visibly overrun every
# bound below, short enough that a broken client fails the test, not the run.
TRICKLE_BYTES = 600
TRICKLE_EVERY_S = 0.1
MARGIN_S = 3.0


# ---------------------------------------------------------------------------
# A server that answers too slowly


class SlowServer(LocalServer):
    """POST /v1/chat/completions, answered in one of three slow ways:

    * ``body``: status and headers at once, then the body a byte at a time;
    * ``status``: the status line and headers themselves a byte at a time;
    * ``silent``: nothing at all.

    ``gone`` is set when a client closes a connection the server still holds.
    """

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.requests = 0
        self.gone = threading.Event()
        self._lock = threading.Lock()
        slow = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                self.rfile.read(int(self.headers.get("content-length") or 0))
                with slow._lock:
                    slow.requests += 1
                try:
                    slow.answer(self)
                except OSError:  # broken pipe, reset: the client went away
                    slow.gone.set()
                self.close_connection = True

            def log_message(self, format: str, *args: Any) -> None:
                pass

        self.serve(Handler)

    def answer(self, handler: BaseHTTPRequestHandler) -> None:
        sock: socket.socket = handler.connection
        if self.mode == "silent":
            sock.settimeout(TRICKLE_EVERY_S)
            for _ in range(TRICKLE_BYTES):
                try:
                    if sock.recv(1) == b"":
                        self.gone.set()
                        return
                except TimeoutError:
                    continue
            return
        body = b" " * TRICKLE_BYTES
        head = (
            b"HTTP/1.1 200 OK\r\ncontent-type: application/json\r\n"
            + f"content-length: {len(body)}\r\n".encode()
            + b"x-padding: "
            + b"a" * TRICKLE_BYTES
            + b"\r\n\r\n"
        )
        if self.mode == "body":
            sock.sendall(head)
            trickled = body
        else:
            trickled = head + body
        for byte in trickled:
            sock.sendall(bytes([byte]))
            time.sleep(TRICKLE_EVERY_S)


@pytest.fixture
def slow_server(request: pytest.FixtureRequest) -> Iterator[SlowServer]:
    with running(SlowServer(request.param)) as srv:
        yield srv


def client(slow: SlowServer, run_log: RunLog | None = None, **settings: Any) -> OpenAIApprentice:
    opts: dict[str, Any] = {"max_retries": 2, "timeout_s": 2.0} | settings
    return OpenAIApprentice(
        ClientSettings(model="test-model", base_url=slow.base_url, **opts),
        run_log=run_log,
        environ={},
    )


def lingering_threads() -> list[threading.Thread]:
    """Threads that would keep the interpreter from exiting."""
    return [t for t in threading.enumerate() if not t.daemon and t is not threading.main_thread()]
