"""The HTTP service: ``POST /v1/verify``, ``GET /v1/rules``, ``GET /v1/health``.

The tutor is loaded once per process and kept warm; a request costs one
verification.  ``/v1/verify`` answers with exactly the JSON ``virf verify
--json`` prints for the same scene and plan, byte for byte.  Errors a client
can fix are 4xx with one line, ``{"status": "BAD_INPUT", "error": "..."}``,
the shape of the CLI's JSON errors; what the service cannot do is 5xx.  A
verification that fails (a timeout, a reasoner failure) is an ERROR report,
never SAFE.

Handlers are plain functions, run in FastAPI's thread pool; a verifier is not
safe to share between threads, so each tutor verifies one request at a time
(the work is CPU-bound: more threads would not make it faster, more
processes do, ``--workers``).
"""

from __future__ import annotations

import hmac
import os
import threading
from collections.abc import Awaitable, Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, RedirectResponse, Response, StreamingResponse
from fastapi_offline import FastAPIOffline
from pydantic import BaseModel, ConfigDict

from virf.api import LogicTutor
from virf.database import shown
from virf.errors import InputError
from virf.ontology.tbox import DEFAULT_SCENARIO
from virf.planner.deadline import DEFAULT_DEADLINE_S
from virf.service.runs import AnswersRequest, PlannerRefused, PlanRequest, Runs
from virf.web import (
    LOCAL_HOSTS,
    MAX_BODY_BYTES,
    BodyLimit,
    StrictJsonRoute,
    add_error_shape,
    foreign,
    problem,
)
from virf.world.plan import PlanStep, parse_plan, parse_plan_text
from virf.world.scene import Scene

# A scene of MAX_INSTANCES objects with their relations is far below this.
MAX_REQUEST_BYTES: Final = MAX_BODY_BYTES
API_KEY_HEADER: Final = "x-api-key"
# Where the API docs' scripts and styles are served (not under /v1/: the
# docs pages need no API key, as /openapi.json needs none).
DOCS_ASSETS: Final = "/docs-assets"


class VerifyRequest(BaseModel):
    """``POST /v1/verify``: a scene (the scene-file JSON) and a plan (a list
    of action lines, or the text of a plan file)."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    scene: dict[str, Any]
    plan: list[str] | str
    scenario: str | None = None
    engine: str | None = None
    # As `virf verify --strict-vocabulary`: a class the knowledge base lacks
    # is refused instead of read as an open-world object.
    strict_vocabulary: bool = False


class HttpNotFound(Exception):
    """An id in the path names nothing: 404."""


def _keys_of(request: Request) -> str:
    """The keys the body of this request's endpoint takes."""
    path = request.url.path
    model: type[BaseModel] = VerifyRequest
    if path == "/v1/learn":
        from virf.service.learning import LearnRequest

        model = LearnRequest
    elif path == "/v1/plan":
        model = PlanRequest
    elif path.startswith("/v1/runs/"):
        model = AnswersRequest
    return ", ".join(model.model_fields)


def key_sent(headers: Mapping[str, str]) -> str | None:
    """The API key a request carries: ``X-API-Key: KEY`` or ``Authorization:
    Bearer KEY`` (the scheme in any case, RFC 9110); an Authorization header
    of another scheme, or none, carries no key."""
    key = headers.get(API_KEY_HEADER)
    if key is not None:
        return key
    scheme, _, token = headers.get("authorization", "").strip().partition(" ")
    return (token.strip() or None) if scheme.lower() == "bearer" else None


class Tutors:
    """One warm tutor per (scenario, engine), each verifying one request at a
    time.  With a knowledge workspace (``kb``), a tutor is made again when the
    workspace's modules change (a reviewer accepted a rule or a learned
    class), so the next request verifies with what was accepted."""

    def __init__(self, scenario: str, engine: str, kb: Path | None, timeout_s: float) -> None:
        self.scenario, self.engine, self.kb, self.timeout_s = scenario, engine, kb, timeout_s
        self._tutors: dict[tuple[str, str], tuple[LogicTutor, threading.Lock, object]] = {}
        self._lock = threading.Lock()

    def prepare(
        self,
        scene: dict[str, Any],
        plan: list[str] | str,
        scenario: str | None,
        engine: str | None,
        *,
        strict_vocabulary: bool = False,
    ) -> tuple[LogicTutor, threading.Lock, Scene, tuple[PlanStep, ...]]:
        """A request's tutor, scene and plan, read as ``virf verify`` reads them
        (a plan is a list of lines or a plan file's text)."""
        steps = parse_plan_text(plan) if isinstance(plan, str) else parse_plan(plan)
        if not steps:
            raise InputError("plan has no actions (only blank lines or comments)")
        tutor, lock = self.get(scenario, engine)
        return tutor, lock, tutor.scene(scene, strict_vocabulary=strict_vocabulary), tuple(steps)

    def _stamp(self) -> object:
        """What identifies the workspace's modules as they are now."""
        if self.kb is None:
            return None
        from virf.ontology.workspace import open_layout

        try:
            return tuple(
                (p.name, p.stat().st_mtime_ns, p.stat().st_size)
                for p in open_layout(self.kb).modules()
            )
        except OSError:
            return None  # loading the tutor says what is wrong

    def get(self, scenario: str | None, engine: str | None) -> tuple[LogicTutor, threading.Lock]:
        key = (scenario or self.scenario, engine or self.engine)
        stamp = self._stamp()
        with self._lock:
            found = self._tutors.get(key)
            if found is None or found[2] != stamp:
                tutor = LogicTutor(key[0], key[1], timeout_s=self.timeout_s, kb=self.kb)
                found = self._tutors[key] = (tutor, threading.Lock(), stamp)
            return found[0], found[1]


def create_app(
    *,
    scenario: str = DEFAULT_SCENARIO,
    engine: str = "fast",
    kb: Path | None = None,
    api_key: str | None = None,
    timeout_s: float = 120.0,
    planners: Sequence[str] = (),
    run_log: str | Path | None = None,
    answer_wait_s: float = 600.0,
    deadline_s: float = DEFAULT_DEADLINE_S,
    workspace: Path | None = None,
    reviewer: str = "reviewer",
) -> FastAPI:
    """The service; the default tutor loads here, so a bad option fails at start.
    ``planners`` are the apprentices a run may name (``virf serve --planner``,
    as written there); the first is the one of runs that name none.
    ``run_log`` records their model calls.  With a knowledge ``workspace``,
    ``deadline_s`` bounds each run (``virf serve --deadline``).
    its review page is a section of the app at ``/review/`` (decisions
    recorded as ``reviewer``'s).  Without an ``api_key`` the service answers
    only requests that name this machine (Host, Origin)."""
    tutors = Tutors(scenario, engine, kb, timeout_s)
    runs = Runs(
        tutors,
        planners=planners,
        run_log=run_log,
        answer_wait_s=answer_wait_s,
        deadline_s=deadline_s,
    )
    default, _ = tutors.get(None, None)
    # /docs and /redoc with their scripts and styles served by the service
    # itself (fastapi-offline ships them): FastAPI's own pages load them
    # from a CDN, and a robot's network often reaches none.  No validator
    # either: Swagger UI would send the API description to a public one.
    app = FastAPIOffline(
        title="VIRF Logic Tutor",
        summary="Verify robot task plans against an OWL 2 DL safety ontology.",
        version="1",
        static_url=DOCS_ASSETS,
        swagger_ui_parameters={"validatorUrl": None},
    )
    # Every JSON body is read as the CLI reads a file (virf.web).
    app.router.route_class = StrictJsonRoute
    # Added first, so the guard below runs before it: a request without its
    # key is refused before its body is counted.
    app.add_middleware(BodyLimit, limit=MAX_REQUEST_BYTES)

    @app.middleware("http")
    async def guard(
        request: Request, call_next: Callable[[Request], Awaitable[Response]]
    ) -> Response:
        if api_key is None:
            # No key: as the review page, it answers to this machine only.
            refused = foreign(request, LOCAL_HOSTS)
            if refused is not None:
                return refused
        elif request.url.path.startswith(("/v1/", "/review/api/")):
            given = key_sent(request.headers)
            if given is None or not hmac.compare_digest(given.encode(), api_key.encode()):
                return problem(
                    401,
                    f"missing or wrong API key: send it in the {API_KEY_HEADER} header "
                    "or as 'Authorization: Bearer KEY'",
                )
        return await call_next(request)

    add_error_shape(app)

    @app.exception_handler(RequestValidationError)
    async def bad_body(request: Request, exc: RequestValidationError) -> JSONResponse:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"] if p != "body") or "the request body"
        if first["type"] == "json_invalid":
            return problem(400, "the request body is not valid JSON")
        if first["type"] == "missing":
            return problem(400, f"the request body needs '{where}'")
        if first["type"] == "extra_forbidden":
            return problem(400, f"unknown key '{where}'; expected {_keys_of(request)}")
        return problem(400, f"{where}: {first['msg']}")

    @app.exception_handler(HttpNotFound)
    async def not_found(request: Request, exc: HttpNotFound) -> JSONResponse:
        return problem(404, str(exc))

    @app.exception_handler(PlannerRefused)
    async def planner_refused(request: Request, exc: PlannerRefused) -> JSONResponse:
        return problem(403, str(exc))

    @app.exception_handler(Exception)
    async def internal(request: Request, exc: Exception) -> JSONResponse:
        return problem(500, f"internal error: {type(exc).__name__}")

    @app.post("/v1/verify")
    def verify(body: VerifyRequest) -> Response:
        """Verify a plan in a scene: the report ``virf verify --json`` prints."""
        tutor, lock, scene, steps = tutors.prepare(
            body.scene,
            body.plan,
            body.scenario,
            body.engine,
            strict_vocabulary=body.strict_vocabulary,
        )
        with lock:
            report = tutor.verifier.verify(scene, steps)
        return Response(report.to_json() + "\n", media_type="application/json")

    @app.get("/v1/rules")
    def rules() -> list[dict[str, object]]:
        """The Unsafe State Concepts of the default scenario (``virf kb rules --json``)."""
        return default.tbox.vocabulary.rule_listing()

    @app.get("/v1/health")
    def health() -> dict[str, Any]:
        """Ready: the knowledge base is loaded (from its checked artifact, or compiled)."""
        tbox = default.tbox
        return {
            "status": "ready",
            "scenario": tbox.scenario,
            "engine": default.engine.name,
            "rules": len(tbox.vocabulary.uscs),
            "knowledge": tbox.source,
            "kb": str(kb) if kb is not None else None,
            "review": "/review/" if workspace is not None else None,
            # Answers about open-world objects can be sent to be learned.
            "learn": "/v1/learn" if workspace is not None else None,
            "worker": os.getpid(),  # which process answered (several with --workers)
            "run_log": shown(run_log) if run_log is not None else None,
            # The planners a run may name; the first is the default.
            "planners": list(runs.planners),
        }

    def known_run(run_id: str) -> Any:
        try:
            return runs.get(run_id)
        except KeyError:
            raise HttpNotFound(f"no run '{run_id[:40]}'") from None

    @app.post("/v1/plan", status_code=202)
    def plan(body: PlanRequest) -> dict[str, Any]:
        """Start a tutor–apprentice run (as ``virf plan``); follow it with the run's URLs."""
        run = runs.start(body)
        return {
            "id": run.id,
            "state": run.state,
            "run": f"/v1/runs/{run.id}",
            "events": f"/v1/runs/{run.id}/events",
            "answers": f"/v1/runs/{run.id}/answers",
        }

    @app.get("/v1/runs/{run_id}")
    def run_state(run_id: str) -> dict[str, Any]:
        """A run: its state (running, waiting for answers, done, failed), turns, questions, result."""
        state: dict[str, Any] = known_run(run_id).public()
        return state

    @app.get("/v1/runs/{run_id}/events")
    def run_events(run_id: str) -> StreamingResponse:
        """The run as server-sent events: turn, questions, result or error."""
        return StreamingResponse(runs.events(known_run(run_id)), media_type="text/event-stream")

    @app.post("/v1/runs/{run_id}/answers")
    def run_answers(run_id: str, body: AnswersRequest) -> dict[str, Any]:
        """Answer the questions the run is waiting on; it goes on with them."""
        run = known_run(run_id)
        runs.answer(run, body.answers)
        return {"id": run.id, "accepted": sorted(body.answers)}

    from virf.service.learning import add_learning  # these import this module
    from virf.service.pages import add_pages

    if workspace is not None:
        from virf.authoring.review import create_app as review_app
        from virf.authoring.workspace import Workspace

        ws = Workspace.open(workspace)
        # The review page's own guards stay: it answers on this machine only.
        app.mount("/review", review_app(ws, reviewer))

        @app.get("/review", include_in_schema=False)
        def review_root() -> RedirectResponse:
            return RedirectResponse("/review/")

        add_learning(app, tutors, ws)
    else:
        add_learning(app, tutors, None)

    add_pages(app, tutors)
    return app


def app_from_environment() -> FastAPI:
    """The app of one ``virf serve --workers N`` process, from the settings the
    command left in the environment (uvicorn starts workers by import path)."""
    import ast

    scenario, engine, kb, api_key, planners, run_log, workspace, reviewer, deadline_s = (
        ast.literal_eval(os.environ["VIRF_SERVE_SETTINGS"])
    )
    return create_app(
        scenario=scenario,
        engine=engine,
        kb=Path(kb) if kb else None,
        api_key=api_key,
        planners=planners,
        run_log=run_log,
        deadline_s=deadline_s,
        workspace=Path(workspace) if workspace else None,
        reviewer=reviewer,
    )
