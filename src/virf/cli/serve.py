"""``virf serve``: the Logic Tutor as an HTTP service."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Any

import typer

from virf.cli.app import EngineOpt, KbOpt, ScenarioOpt, default_reviewer
from virf.errors import InputError

# On SIGTERM or Ctrl-C, requests under way get this long to finish; then what
# is still open (an event stream of a run waiting for answers) is cut off,
# so an open stream cannot keep the service from stopping.
SHUTDOWN_GRACE_S = 10


def serve(
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=0, max=65535, help="TCP port (0: any free one).")] = 8000,
    workers: Annotated[
        int, typer.Option(min=1, max=64, help="Processes, each with its own warm tutor.")
    ] = 1,
    scenario: ScenarioOpt = None,
    engine: EngineOpt = "fast",
    kb: KbOpt = None,
    planner: Annotated[
        list[str] | None,
        typer.Option(
            help="A planner POST /v1/plan runs may name (openai:MODEL, local:NAME, "
            "replay:FILE), written as runs name it; repeat it for several. The first is "
            "the planner of runs that name none. A run naming any other is refused (403).",
        ),
    ] = None,
    run_log: Annotated[
        str | None,
        typer.Option(
            help="Run log of the runs (their state and model calls): a SQLite file, or a "
            "postgresql:// URL that several service machines share."
        ),
    ] = None,
    deadline: Annotated[
        float | None,
        typer.Option(
            help="Seconds each /v1/plan run may take, waits for answers not counted "
            "(default 600, or deadline_s in the config file); a run past it is rejected."
        ),
    ] = None,
    workspace: Annotated[
        Path | None,
        typer.Option(
            "--workspace",
            "-w",
            help="A knowledge workspace whose review page becomes the /review/ section.",
        ),
    ] = None,
    reviewer: Annotated[
        str | None, typer.Option(help="Name recorded with review decisions (default: login name).")
    ] = None,
    api_key: Annotated[
        str | None,
        typer.Option(
            envvar="VIRF_API_KEY",
            help="Key clients send in the X-API-Key header (default $VIRF_API_KEY). Without "
            "one the service listens on this machine only.",
        ),
    ] = None,
) -> None:
    """Serve the tutor over HTTP: /v1/verify, /v1/plan runs, /v1/rules, /v1/health, the page at / (OpenAPI docs at /docs)."""
    import uvicorn

    from virf.service.tcp import NoDelayH11Protocol
    from virf.web import LOCAL_HOSTS

    if api_key is None and host not in LOCAL_HOSTS:
        raise InputError(
            f"--host {host} without an API key would let anyone verify through this machine; "
            "set --api-key or VIRF_API_KEY, or keep --host 127.0.0.1"
        )
    from virf.planner.config import run_deadline

    deadline_s = run_deadline(deadline)  # a bad value fails now, not at the first run
    if api_key is None:
        typer.echo("no API key: listening on this machine only", err=True)
    if workers > 1 and run_log is None:
        typer.echo(
            "no --run-log: each worker keeps its own runs, so a run's URLs must reach the "
            "worker that started it; give --run-log to share runs between workers",
            err=True,
        )
    planners = [p.strip() for p in planner or ()]
    empty = [p for p in planners if not p]
    if empty:
        raise InputError("--planner must not be empty; e.g. --planner openai:gpt-4o-mini")
    from virf.ontology.tbox import resolve_scenario

    scenario = resolve_scenario(scenario, kb)
    if run_log is not None:
        from virf.planner.runlog import RunLog

        RunLog(run_log).close()  # a log that cannot be opened fails now, not at the first run
    # Each worker process builds its own app (and tutor) from these settings.
    settings = (
        scenario,
        engine,
        str(kb) if kb else None,
        api_key,
        planners,
        run_log,
        str(workspace) if workspace else None,
        reviewer or default_reviewer(),
        deadline_s,
    )
    os.environ["VIRF_SERVE_SETTINGS"] = repr(settings)
    if workers == 1:
        from virf.service.app import create_app

        app = create_app(
            scenario=scenario,
            engine=engine,
            kb=kb,
            api_key=api_key,
            planners=planners,
            run_log=run_log,
            deadline_s=deadline_s,
            workspace=workspace,
            reviewer=reviewer or default_reviewer(),
        )
        config = uvicorn.Config(
            app,
            host=host,
            port=port,
            log_level="warning",
            http=NoDelayH11Protocol,
            timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
        )
        _run_announcing(config)
    else:
        _announce(host, port)
        uvicorn.run(
            "virf.service.app:app_from_environment",
            factory=True,
            host=host,
            port=port,
            workers=workers,
            log_level="warning",
            http=NoDelayH11Protocol,
            timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
        )


def _announce(host: str, port: int) -> None:
    """One line on stderr: where the service is (uvicorn's own is silenced
    with its other info lines)."""
    shown = f"[{host}]" if ":" in host else host
    typer.echo(f"virf serve: http://{shown}:{port}/ (the page; API docs at /docs)", err=True)


def _run_announcing(config: Any) -> None:
    """Run one server that says where it listens once it does (the real
    port when --port 0 asked for any free one)."""
    import uvicorn

    class Announcing(uvicorn.Server):
        async def startup(self, sockets: list[Any] | None = None) -> None:
            await super().startup(sockets)
            for server in self.servers:
                for sock in server.sockets:
                    _announce(*sock.getsockname()[:2])
                    return

    Announcing(config).run()
