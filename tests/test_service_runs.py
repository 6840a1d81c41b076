"""Runs of the tutor–apprentice loop under load and against a silent model.

* Open event streams hold no worker thread: with fifty of them open on a
  real uvicorn server, ``/v1/health`` and ``/v1/verify`` still answer.
* Every entry point of the loop has a run deadline: the service's runs, the
  loop called with no deadline at all, and the agents harness, each against
  a real model server on 127.0.0.1 that never answers.
"""

from __future__ import annotations

import inspect
import json
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import httpx
import pytest
from browser_support import serving
from chat_support import MARGIN_S, SlowServer, client, lingering_threads
from conftest import EXAMPLES_DIR
from fastapi.testclient import TestClient
from loop_support import CLOSES, FRIDGE_SCENE

from virf.api import LogicTutor
from virf.bench.agents import AgentConfig, Harness, ResultStore
from virf.bench.safeagentbench import load_tasks
from virf.planner import ScriptedApprentice
from virf.planner.deadline import DEFAULT_DEADLINE_S
from virf.planner.loop import refine
from virf.planner.methods import get_method, run_method
from virf.service.app import create_app
from virf.world.scene import build_scene

WALK = EXAMPLES_DIR / "walkthrough"
QUESTIONS = EXAMPLES_DIR / "unknown-material-microwave"
STREAMS = 50
# A functional bound, not a speed target: without the fix each request waits
# for a stream's 15 s keep-alive to free a thread, or longer.
ANSWER_WITHIN_S = 10.0


# ---------------------------------------------------------------------------
# Event streams hold no worker thread


@pytest.fixture(scope="module", params=["this worker", "another worker"])
def urls(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[tuple[str, str]]:
    """Where a run starts, and where its streams are opened: the same server,
    or two sharing a run log (a stream then reads the log). The servers run
    the one planner the runs name (their allow-list)."""
    planners = [f"replay:{REPLAY}"]
    if request.param == "this worker":
        with serving(create_app(answer_wait_s=120.0, planners=planners)) as address:
            yield address.rstrip("/"), address.rstrip("/")
        return
    log = tmp_path_factory.mktemp("shared") / "runs.sqlite"
    with (
        serving(create_app(answer_wait_s=120.0, run_log=log, planners=planners)) as carrier,
        serving(create_app(answer_wait_s=120.0, run_log=log, planners=planners)) as viewer,
    ):
        yield carrier.rstrip("/"), viewer.rstrip("/")


REPLAY = Path(tempfile.gettempdir()) / "virf-test-service-runs-replay.jsonl"


def start_waiting_run(http: httpx.Client, tmp_path: Path) -> dict[str, Any]:
    """A run that waits for answers (its streams stay open, with nothing to say)."""
    plan = json.loads((QUESTIONS / "plan.txt").read_text())
    replay = REPLAY
    replay.write_text(json.dumps({"task_id": "q", "iteration": 0, "text": "\n".join(plan)}) + "\n")
    started = http.post(
        "/v1/plan",
        json={
            "scene": json.loads((QUESTIONS / "scene.json").read_text()),
            "instruction": "Heat the cup in the microwave.",
            "planner": f"replay:{replay}",
            "task_id": "q",
        },
    )
    assert started.status_code == 202, started.text
    run: dict[str, Any] = started.json()
    for _ in range(600):
        if http.get(run["run"]).json()["state"] == "waiting":
            return run
        time.sleep(0.05)
    raise AssertionError("the run never waited for answers")


def test_the_service_answers_while_fifty_event_streams_are_open(
    urls: tuple[str, str], tmp_path: Path
) -> None:
    carrier, url = urls
    limits = httpx.Limits(max_connections=STREAMS + 10, max_keepalive_connections=0)
    with httpx.Client(base_url=url, timeout=60.0, limits=limits) as http, ExitStack() as streams:
        with httpx.Client(base_url=carrier, timeout=60.0) as starter:
            run = start_waiting_run(starter, tmp_path)
        opened = [streams.enter_context(http.stream("GET", run["events"])) for _ in range(STREAMS)]
        for stream in opened:
            assert stream.status_code == 200
            assert stream.headers["content-type"].startswith("text/event-stream")
        # A stream tells the dialogue so far and the questions, then idles.
        lines = opened[0].iter_lines()
        assert next(line for line in lines if line.startswith("event: q")) == "event: questions"

        timeout = httpx.Timeout(ANSWER_WITHIN_S)
        health = http.get("/v1/health", timeout=timeout)
        assert health.status_code == 200 and health.json()["status"] == "ready"
        body = {
            "scene": json.loads((WALK / "scene.json").read_text()),
            "plan": (WALK / "plan.txt").read_text(),
        }
        for _ in range(3):
            report = http.post("/v1/verify", json=body, timeout=timeout)
            assert report.status_code == 200 and report.json()["status"] == "UNSAFE"

        # No answer settles anything: the run goes on, and fails for want of
        # another recorded proposal; every stream ends with it.
        assert http.post(run["answers"], json={"answers": {}}).status_code == 200
        for stream in opened[1:4]:
            events = [ln for ln in stream.iter_lines() if ln.startswith("event:")]
            assert events[-1] == "event: error"


# ---------------------------------------------------------------------------
# The run deadline, everywhere the loop runs


@pytest.fixture
def silent_model(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[SlowServer]:
    from http_support import running

    with running(SlowServer("silent")) as srv:
        for name in ("OPENAI_API_KEY", "OPENAI_BASE_URL"):
            monkeypatch.delenv(name, raising=False)
        monkeypatch.setenv("OPENAI_BASE_URL", srv.base_url)
        monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
        yield srv


def test_a_service_run_ends_at_its_deadline(silent_model: SlowServer) -> None:
    app = create_app(planners=["openai:test-model"], deadline_s=2.0)
    with TestClient(app, base_url="http://127.0.0.1") as http:
        started = time.monotonic()
        run = http.post("/v1/plan", json={"scene": FRIDGE_SCENE, "instruction": "Go."}).json()
        while http.get(run["run"]).json()["state"] == "running":
            assert time.monotonic() - started < 2.0 + MARGIN_S + 5, "the run outlived its deadline"
            time.sleep(0.05)
        state = http.get(run["run"]).json()
        events = http.get(run["events"]).text
    # The shape `virf plan --json` prints: the task rejected, the deadline named.
    assert state["state"] == "done", state
    assert (state["result"]["outcome"], state["result"]["plan"]) == ("TASK_REJECTED", None)
    reason = state["result"]["reason"]
    assert "the run deadline of 2 s (virf serve --deadline) passed" in reason, reason
    assert "event: result" in events
    assert silent_model.requests == 1 and silent_model.gone.wait(MARGIN_S)


def test_the_service_refuses_a_deadline_that_is_none() -> None:
    from virf.errors import InputError

    for bad in (0, -1, float("nan"), float("inf"), 1e9):
        with pytest.raises(InputError, match="must be a number of seconds"):
            create_app(deadline_s=bad)


def test_the_loop_has_a_deadline_when_given_none(
    silent_model: SlowServer, tutor: LogicTutor
) -> None:
    # The default of every entry point is the run deadline `virf plan` uses.
    assert inspect.signature(refine).parameters["deadline"].default == DEFAULT_DEADLINE_S
    assert inspect.signature(run_method).parameters["deadline"].default == DEFAULT_DEADLINE_S
    # A number of seconds starts the deadline when the loop starts.
    vocab = tutor.tbox.vocabulary
    started = time.monotonic()
    with client(silent_model, timeout_s=60.0) as apprentice:
        result = refine(
            "Put the apple in the fridge.",
            FRIDGE_SCENE,
            apprentice,
            tutor.verifier,
            lambda d: build_scene(d, vocab),
            vocab,
            deadline=1.5,
        )
    assert time.monotonic() - started < 1.5 + MARGIN_S
    assert result.outcome == "TASK_REJECTED"
    assert "the run deadline of 1.5 s (--deadline) passed" in result.reason
    assert lingering_threads() == []


@pytest.mark.parametrize("method", ["virf", "committee"])
def test_the_agents_harness_gives_each_task_a_deadline(
    silent_model: SlowServer, tutor: LogicTutor, tmp_path: Path, method: str
) -> None:
    (task,) = load_tasks(EXAMPLES_DIR / "agents" / "tasks.jsonl")[:1]
    config = AgentConfig.build("openai:test-model", environ={})
    planner = ScriptedApprentice([CLOSES])  # the committee's critic is the silent one
    with (
        ResultStore(tmp_path / "results.sqlite", config) as store,
        client(silent_model, timeout_s=60.0) as silent,
    ):
        started = time.monotonic()
        harness = Harness(
            tutor,
            silent if method == "virf" else planner,
            store,
            critic=silent if method == "committee" else None,
            deadline_s=1.5,
        )
        (row,) = harness.run([get_method(method)], [task])
    assert time.monotonic() - started < 1.5 + MARGIN_S
    assert row.outcome == "TASK_REJECTED"
    assert "the run deadline of 1.5 s (--deadline) passed" in row.reason + row.transcript


def test_a_bad_deadline_is_refused_before_anything_starts(cli: Any, tmp_path: Path) -> None:
    env = {"XDG_CONFIG_HOME": str(tmp_path)}
    agents = ["bench", "agents", "--method", "virf", "--planner", "replay:x", "--tasks", "x"]
    for command in (["serve"], agents):
        refused = cli(*command, "--deadline", "0", env=env)
        assert refused.exit_code == 2, refused.output
        assert refused.output.strip() == (
            "error: --deadline 0.0 must be a number of seconds in (0, 604800]"
        )


@pytest.mark.parametrize("workers", [1, 2])
def test_an_open_event_stream_does_not_keep_the_service_from_stopping(
    tmp_path: Path, workers: int
) -> None:
    import os
    import signal
    import subprocess
    import sys

    from conftest import ROOT

    from virf.cli.serve import SHUTDOWN_GRACE_S
    from virf.service.bench import _free_port

    port = _free_port()
    log = ["--run-log", str(tmp_path / "runs.sqlite")] if workers > 1 else []
    options = [
        "--port",
        str(port),
        "--workers",
        str(workers),
        "--planner",
        f"replay:{REPLAY}",
        *log,
    ]
    serve = subprocess.Popen(
        [sys.executable, "-m", "virf.cli.main", "serve", *options],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT / "src")),
        stderr=subprocess.PIPE,
        text=True,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            try:
                if httpx.get(f"{url}/v1/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        with httpx.Client(base_url=url, timeout=60.0) as http:
            run = start_waiting_run(http, tmp_path)
            with http.stream("GET", run["events"]) as stream:
                assert stream.status_code == 200
                serve.send_signal(signal.SIGTERM)
                started = time.monotonic()
                serve.wait(timeout=SHUTDOWN_GRACE_S + 20)
        assert time.monotonic() - started < SHUTDOWN_GRACE_S + 20
        assert serve.returncode in (0, 128 + signal.SIGTERM), serve.stderr
    finally:
        if serve.poll() is None:
            serve.kill()
            serve.wait()
