"""What VIRF's HTTP apps share: the service (``virf serve``) and the review
page (``virf kb review``, also the service's ``/review/`` section).

* **One error shape.** Every 4xx and 5xx answer is ``{"status": "BAD_INPUT"
  | "ERROR", "error": "one line"}``, the shape of the CLI's JSON errors;
  FastAPI's and Starlette's own 404, 405 and 413 answers included.
* **One reader of bytes.** A JSON request body is read by the function the
  CLI reads its files with (:func:`virf.errors.json_of`): UTF-8, strict JSON
  (a key twice, NaN and Infinity refused), the same error lines.
* **Bytes read, not bytes declared.** A body is cut off at the limit as it
  arrives, whatever its Content-Length or its framing says.
* **This machine only.** A server that answers without a key answers only
  requests that name this machine (Host), and only posts from its own pages
  (Origin): a page of another site cannot drive it through the browser.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Collection, Coroutine
from typing import Any, Final
from urllib.parse import urlsplit

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse, Response
from fastapi.routing import APIRoute
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from virf.errors import EnvironmentProblem, InputError, VirfError, clip, json_of, printable

# A scene of the largest size VIRF reads (5,000 objects with their relations)
# is far below this.
MAX_BODY_BYTES: Final = 8 * 1024 * 1024
# Names a browser on this machine reaches a server by.  Anything else in a
# Host header is a DNS-rebinding page trying to reach the loopback server.
LOCAL_HOSTS: Final = ("127.0.0.1", "localhost", "::1")
JSON_TYPE: Final = "application/json"
BODY_NOT_JSON: Final = f"the request body must be JSON (Content-Type: {JSON_TYPE})"
# A body refused half-read: the connection ends, the rest is not read.
CLOSE: Final = {"Connection": "close"}


def problem(status: int, message: str, headers: dict[str, str] | None = None) -> JSONResponse:
    """The one error shape: ``BAD_INPUT`` for what a client can fix (4xx),
    ``ERROR`` for what the server cannot do (5xx); one line of plain text."""
    kind = "BAD_INPUT" if status < 500 else "ERROR"
    body = {"status": kind, "error": printable(message)}
    return JSONResponse(body, status_code=status, headers=headers)


def _size(limit: int) -> str:
    return f"{limit // 2**20} MiB" if limit >= 2**20 else f"{limit} bytes"


class BodyTooLarge(HTTPException):
    """More bytes arrived than the limit.  An ``HTTPException`` so that
    FastAPI, reading a route's body, passes it on to the app's handler
    instead of turning it into its generic 400.  The answer closes the
    connection: the rest of the body is not read."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body larger than {_size(limit)}", headers=dict(CLOSE))


class BodyLimit:
    """ASGI middleware: a request body of at most ``limit`` bytes, counted as
    they are received, so that neither a small Content-Length nor a chunked
    body lets more through; a Content-Length over the limit is refused
    before anything is read.

    Hand-written: FastAPI's own ``max_body_size`` counts the same way, but
    answers a request whose Content-Length is over the limit with
    Starlette's plain-text 413, whatever the app answers, not in the
    documented shape."""

    def __init__(self, app: ASGIApp, limit: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        too_large = BodyTooLarge(self.limit)
        declared = Headers(scope=scope).get("content-length", "").strip()
        if declared.isdigit() and int(declared) > self.limit:
            await problem(413, too_large.detail, dict(CLOSE))(scope, receive, send)
            return
        received = 0
        started = False

        async def counted() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit:
                    raise too_large
            return message

        async def sending(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted, sending)
        except BodyTooLarge:
            # Read outside a route, where no handler made it an answer.
            if started:
                raise
            await problem(413, too_large.detail, dict(CLOSE))(scope, receive, send)


class _StrictJsonRequest(Request):
    """A request whose JSON body was read by the CLI's reader."""

    parsed: Any = None

    async def read_json(self) -> None:
        kind = self.headers.get("content-type", "").split(";")[0].strip().lower()
        if kind != JSON_TYPE:
            raise InputError(BODY_NOT_JSON)
        self.parsed = json_of(await self.body(), "the request body")

    async def json(self) -> Any:
        return self.parsed


class StrictJsonRoute(APIRoute):
    """A route whose JSON body is read by :func:`virf.errors.json_of`, the
    reader of the CLI's files.

    Hand-written: FastAPI reads a body with ``json.loads``, which keeps the
    last of two equal keys and takes NaN.  A custom ``Request`` class is
    FastAPI's documented way to read a body differently; the body is read
    here, before FastAPI's own handler, because FastAPI would replace the
    reader's error line with its generic 'There was an error parsing the
    body'."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()
        if self.body_field is None:
            return handler

        async def read_strictly(request: Request) -> Response:
            strict = _StrictJsonRequest(request.scope, request.receive)
            await strict.read_json()
            return await handler(strict)

        return read_strictly


def _not_found(request: Request) -> str:
    """'nothing is served at PATH', with the app's paths nearest to it."""
    path = request.url.path
    root = str(request.scope.get("root_path", "")).rstrip("/")
    paths = sorted(
        root + str(p)
        for route in request.app.routes
        if isinstance(p := getattr(route, "path", None), str) and p
    )
    near = difflib.get_close_matches(path, paths, n=3, cutoff=0.6)
    hint = f"; closest: {', '.join(near)}" if near else ""
    return f"nothing is served at {clip(path)}{hint}"


def add_error_shape(app: FastAPI) -> None:
    """Answer FastAPI's and Starlette's own HTTP errors (404, 405, 413...)
    and VIRF's errors in the one shape: a ``VirfError`` is a 400, an
    ``EnvironmentProblem`` (Java missing) a 503.  Request validation and
    bugs are worded by each app."""

    @app.exception_handler(HTTPException)
    async def http_error(request: Request, exc: HTTPException) -> JSONResponse:
        headers = dict(exc.headers or {})
        if exc.status_code == 404 and exc.detail == "Not Found":
            message = _not_found(request)
        elif exc.status_code == 405:
            allowed = headers.get("Allow", "")
            message = f"{request.method} is not allowed on {clip(request.url.path)}; use {allowed}"
        else:
            message = str(exc.detail)
        return problem(exc.status_code, message, headers)

    @app.exception_handler(VirfError)
    async def virf_error(request: Request, exc: VirfError) -> JSONResponse:
        return problem(503 if isinstance(exc, EnvironmentProblem) else 400, str(exc))


def host_allowed(hosts: Collection[str], netloc: str) -> bool:
    """Whether ``netloc`` (a Host header, or an Origin's host and port)
    names one of ``hosts``; ``"*"`` among them allows any."""
    if "*" in hosts:
        return True
    name = urlsplit(f"//{netloc}").hostname
    return name is not None and name.lower() in {h.lower().strip("[]") for h in hosts}


def foreign(request: Request, hosts: Collection[str]) -> JSONResponse | None:
    """403 for a request a page of another site may have sent, else None: a
    Host that is none of ``hosts`` (DNS rebinding), or a request other than
    GET whose Origin is another site (a form or a script elsewhere)."""
    host = request.headers.get("host", "")
    if not host_allowed(hosts, host):
        names = ", ".join(h for h in hosts if h != "*")
        return problem(403, f"this server answers only to {names}, not to Host '{clip(host)}'")
    origin = request.headers.get("origin")
    if (
        request.method != "GET"
        and origin is not None
        and (origin == "null" or not host_allowed(hosts, urlsplit(origin).netloc))
    ):
        return problem(403, f"requests from {clip(origin)} are not accepted")
    return None
