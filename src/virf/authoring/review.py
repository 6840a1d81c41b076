"""The review page: a small local web server over a knowledge workspace.

A knowledge engineer opens ``virf kb review`` in a browser, walks the queue of
drafted candidates, edits and re-checks an axiom, previews its effect and
accepts or rejects it.  Every fact shown comes from the workspace's review
API (:class:`virf.authoring.workspace.Workspace`) as the view models of
:mod:`virf.authoring.models`; this module only maps HTTP onto that API and
serves the static page (vanilla JS, no build step, nothing from the
internet).

Handlers are plain functions, so FastAPI runs them in its thread pool: a
check starts Java for seconds and must not stall the page's other requests.
"""

from __future__ import annotations

import contextlib
import errno
import socket
import sys
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Annotated, Final, Protocol

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import Field

from virf.authoring.models import (
    AcceptedRule,
    CandidateSummary,
    CandidateView,
    CheckReport,
    Decision,
    DecisionView,
    Preview,
    Status,
)
from virf.errors import EnvironmentProblem, InputError, Record, Says, clip
from virf.ontology.manchester import MAX_AXIOM_CHARS
from virf.web import (
    LOCAL_HOSTS,
    BodyLimit,
    StrictJsonRoute,
    add_error_shape,
    foreign,
    problem,
)

STATIC_DIR: Final = Path(__file__).resolve().parent / "static"
STATUS_FILTERS: Final = ("pending", "accepted", "rejected", "all")
# Far above any reason a person writes; far below what would make the store choke.
MAX_REASON_CHARS: Final = 4_000
# Far above any body the page sends (an axiom, a reason).
MAX_BODY_BYTES: Final = 1024 * 1024


class ReviewWorkspace(Protocol):
    """What the review page needs of a workspace: the review API of
    :class:`virf.authoring.workspace.Workspace`, which satisfies it."""

    def candidates(self, status: Status | None = None) -> list[CandidateSummary]: ...

    def summary(self, cid: int) -> CandidateSummary: ...

    def candidate(self, cid: int) -> CandidateView: ...

    def opened(self, cid: int, reviewer: str) -> None: ...

    def recheck(self, cid: int, axiom: str) -> CheckReport: ...

    def preview(
        self,
        cid: int,
        axiom: str | None = None,
        tasks: Path | None = None,
        examples: Path | None = None,
    ) -> Preview: ...

    def decide(
        self,
        cid: int,
        decision: Decision,
        *,
        reviewer: str,
        reason: str | None = None,
        axiom: str | None = None,
    ) -> DecisionView: ...

    def rules(self) -> list[AcceptedRule]: ...


# -- request bodies ----------------------------------------------------------
# Record: strict, closed JSON objects whose problems read as one line.

Axiom = Annotated[
    str,
    Field(min_length=1, max_length=MAX_AXIOM_CHARS),
    Says(
        "'axiom' must be Manchester-syntax text",
        string_too_short="'axiom' must not be empty",
        string_too_long="'axiom' is longer than {max_length} characters",
    ),
]


class Body(Record):
    when_missing = "{where} needs '{key}'"


class CheckBody(Body):
    axiom: Axiom


class PreviewBody(Body):
    axiom: Axiom | None = None


class DecisionBody(Body):
    decision: Annotated[Decision, Says("'decision' must be 'accept' or 'reject', not {value}")]
    reason: Annotated[str | None, Field(max_length=MAX_REASON_CHARS)] = None
    axiom: Axiom | None = None


# The body model of each POST, by the last segment of its path, so a
# validation failure can be worded by ``Record.parse`` as everywhere else.
_BODIES: Final[dict[str, type[Body]]] = {
    "check": CheckBody,
    "preview": PreviewBody,
    "decision": DecisionBody,
}


class HttpProblem(Exception):
    """An error answered with ``status`` and ``{"status": "BAD_INPUT", "error": message}``."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


def create_app(
    workspace: ReviewWorkspace,
    reviewer: str,
    *,
    allowed_hosts: Sequence[str] = LOCAL_HOSTS,
    preview_tasks: Path | None = None,
    examples: Path | None = None,
) -> FastAPI:
    """The review server for ``workspace``; decisions are recorded as ``reviewer``'s.
    The effect preview runs over ``examples`` and the tasks of ``preview_tasks``.

    ``allowed_hosts`` are the host names the page may be reached by (the Host
    and Origin headers are checked against them); ``("*",)`` allows any, for a
    server bound to a public address on purpose."""
    if not reviewer.strip():
        raise InputError("the reviewer's name must not be empty; give one with --reviewer")
    ws = workspace
    app = FastAPI(
        title="VIRF knowledge review",
        docs_url=None,  # the docs pages load their scripts from a CDN
        redoc_url=None,
        openapi_url=None,
    )
    # Bodies are read as the CLI reads files, and counted as they arrive (virf.web).
    app.router.route_class = StrictJsonRoute
    app.add_middleware(BodyLimit, limit=MAX_BODY_BYTES)
    hosts = tuple(allowed_hosts)

    @app.middleware("http")
    async def local_only(
        request: Request, call_next: Callable[[Request], Awaitable[Response]]
    ) -> Response:
        # The server acts on a person's behalf with no login: only pages it
        # served itself may drive it.  A foreign Host is DNS rebinding; a
        # foreign Origin on a POST is another site's form or script.
        refused = foreign(request, hosts)
        if refused is not None:
            return refused
        response = await call_next(request)
        # Everything the page uses is served from here; nothing else may load.
        response.headers["Content-Security-Policy"] = (
            "default-src 'self'; img-src 'self' data:; frame-ancestors 'none'; base-uri 'none'"
        )
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Cache-Control"] = "no-store"
        return response

    add_error_shape(app)  # Starlette's own errors, VirfError (400) and EnvironmentProblem (503)

    @app.exception_handler(HttpProblem)
    def on_problem(request: Request, exc: HttpProblem) -> JSONResponse:
        return problem(exc.status, exc.message)

    @app.exception_handler(RequestValidationError)
    def on_invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return problem(400, _request_problem(request, exc))

    @app.exception_handler(Exception)
    def on_bug(request: Request, exc: Exception) -> JSONResponse:
        # uvicorn logs the traceback on the server's terminal, where the
        # person who started it can report it; the page gets one line.
        return problem(500, f"internal error: {type(exc).__name__}: {exc}")

    def known(cid: int) -> CandidateSummary:
        """The candidate's queue entry; 404 with the workspace's own words if there is none."""
        try:
            return ws.summary(cid)
        except InputError as exc:
            raise HttpProblem(404, str(exc)) from None

    def refuse_if_decided(summary: CandidateSummary) -> None:
        if summary.status != "pending":
            raise HttpProblem(409, f"candidate {summary.id} was already {summary.status}")

    @app.get("/", include_in_schema=False)
    def page() -> FileResponse:
        return FileResponse(STATIC_DIR / "review.html", media_type="text/html")

    @app.get("/api/candidates")
    def list_candidates(status: str = "pending") -> list[CandidateSummary]:
        if status not in STATUS_FILTERS:
            raise HttpProblem(
                400, f"unknown status '{clip(status)}'; choose from {', '.join(STATUS_FILTERS)}"
            )
        chosen: Status | None = None if status == "all" else status  # type: ignore[assignment]
        return ws.candidates(chosen)

    @app.get("/api/candidates/{cid}")
    def show_candidate(cid: int) -> CandidateView:
        summary = known(cid)
        view = ws.candidate(cid)
        # Time per decision counts from the first look at a pending candidate;
        # browsing decided ones is not review work.
        if summary.status == "pending":
            ws.opened(cid, reviewer)
        return view

    @app.post("/api/candidates/{cid}/check")
    def check(cid: int, body: CheckBody) -> CheckReport:
        refuse_if_decided(known(cid))
        return ws.recheck(cid, body.axiom)

    @app.post("/api/candidates/{cid}/preview")
    def preview(cid: int, body: PreviewBody) -> Preview:
        refuse_if_decided(known(cid))
        return ws.preview(cid, body.axiom, tasks=preview_tasks, examples=examples)

    @app.post("/api/candidates/{cid}/decision")
    def decide(cid: int, body: DecisionBody) -> DecisionView:
        refuse_if_decided(known(cid))
        reason = body.reason.strip() if body.reason else None
        if body.decision == "reject" and not reason:
            raise HttpProblem(400, "a rejection needs a reason")
        try:
            return ws.decide(cid, body.decision, reviewer=reviewer, reason=reason, axiom=body.axiom)
        except InputError:
            # Another reviewer may have decided it meanwhile: that is a
            # conflict, not a bad request.
            refuse_if_decided(known(cid))
            raise

    @app.get("/api/rules")
    def rules() -> list[AcceptedRule]:
        return ws.rules()

    @app.api_route("/api/{rest:path}", methods=["GET", "POST"], include_in_schema=False)
    def unknown_api(rest: str) -> None:
        raise HttpProblem(404, f"no API endpoint /api/{clip(rest)}")

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app


def _request_problem(request: Request, exc: RequestValidationError) -> str:
    """One line for a request FastAPI could not read: a bad path or query
    value, or a body that is not the endpoint's JSON object."""
    errors = exc.errors()
    first = errors[0] if errors else {}
    loc = tuple(first.get("loc", ()))
    if loc[:1] == ("path",) and loc[1:] == ("cid",):
        return f"a candidate id is a whole number, not '{clip(str(first.get('input')))}'"
    if loc[:1] != ("body",):
        where = ".".join(str(p) for p in loc[1:]) or "the request"
        return f"{where}: {first.get('msg', 'invalid value')}"
    if first.get("type") == "json_invalid":
        return "the request body is not valid JSON"
    model = _BODIES.get(request.url.path.rstrip("/").rsplit("/", 1)[-1])
    body = getattr(exc, "body", None)
    if model is not None:
        try:
            model.parse(body, "the request body")
        except InputError as problem:
            return str(problem)
    return f"the request body is not valid: {first.get('msg', 'invalid value')}"


# -- serving -------------------------------------------------------------------


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on ``host``:``port`` (0: any free port), or one line
    saying why not.  Bound here, not by uvicorn, so the address printed is the
    real one and a busy port is a clear error instead of a log record."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror:
        raise InputError(f"cannot resolve host '{clip(host)}'; use 127.0.0.1") from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(128)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise InputError(
                f"port {port} on {host} is in use; choose another with --port"
            ) from None
        if exc.errno in (errno.EACCES, errno.EPERM):
            raise InputError(
                f"not allowed to listen on {host}:{port}; choose a port above 1023"
            ) from None
        raise InputError(f"cannot listen on {host}:{port}: {exc.strerror}") from None
    return sock


def url_of(sock: socket.socket) -> str:
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/"


def serve(
    workspace: ReviewWorkspace,
    host: str = "127.0.0.1",
    port: int = 8765,
    reviewer: str = "reviewer",
    *,
    announce: Callable[[str], None] | None = None,
    preview_tasks: Path | None = None,
    examples: Path | None = None,
) -> None:
    """Serve the review page until Ctrl-C (or SIGTERM), then return.

    ``announce`` receives the one line with the address (default: print it)."""
    import uvicorn

    from virf.ontology.jvm import ensure_jvm

    wildcard = host in ("0.0.0.0", "::", "")
    allowed: Sequence[str] = ("*",) if wildcard else (*LOCAL_HOSTS, host)
    say = announce or print
    app = create_app(
        workspace, reviewer, allowed_hosts=allowed, preview_tasks=preview_tasks, examples=examples
    )
    sock = bind(host, port)
    try:
        # Started before serving: the first check does not wait for the JVM,
        # and a JVM that cannot start is a warning now, not a failed check
        # later.  (The JVM runs with -Xrs, so Ctrl-C and SIGTERM stay
        # uvicorn's, which shuts the server down gracefully.)
        ensure_jvm()
    except EnvironmentProblem as exc:
        say(f"warning: {exc}; the page works, but checks and decisions will fail")
    url = url_of(sock)
    say(f"Review page for {reviewer}: {url}  (Ctrl-C stops)")
    sys.stdout.flush()
    config = uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off")
    server = uvicorn.Server(config)
    try:
        server.run(sockets=[sock])
    except KeyboardInterrupt:
        # uvicorn has shut down by now and re-raises the signal it caught:
        # stopping the server is what Ctrl-C asks for, not an error.
        pass
    finally:
        with contextlib.suppress(OSError):
            sock.close()
