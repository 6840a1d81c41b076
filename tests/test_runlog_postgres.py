"""The run log on a real PostgreSQL server: the same migrations, the same
records as on SQLite, one log shared by several writers, and from the
commands that take a log (``virf plan --log``, ``virf serve --run-log``)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest
from conftest import ROOT
from fastapi.testclient import TestClient
from runlog_support import MESSAGES, log_one

from virf.database import shown
from virf.errors import EnvironmentProblem
from virf.planner import MIGRATIONS, Migration, RunLog

# A service without a key answers to this machine's names only.
LOCAL = "http://127.0.0.1"

# A migration every dialect reads: what a later VIRF might add.
LATER = Migration(
    "0099_test_notes",
    """
    ALTER TABLE model_calls ADD COLUMN note TEXT;
    CREATE TABLE notes (id INTEGER PRIMARY KEY AUTOINCREMENT, body TEXT NOT NULL, score REAL);
    """,
)


@pytest.fixture
def pg(postgres_url: str) -> Iterator[str]:
    """A new, empty database on the test server."""
    name = f"virf_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres_url, autocommit=True) as conn:
        conn.execute(f"CREATE DATABASE {name}")
    yield postgres_url.rsplit("/", 1)[0] + "/" + name


@pytest.fixture(params=["sqlite", "postgresql"])
def target(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """The same behaviour, checked on both kinds of log."""
    if request.param == "sqlite":
        return str(tmp_path / "runs.db")
    url: str = request.getfixturevalue("pg")
    return url


def test_a_new_log_gets_every_migration_and_a_second_opening_none(target: str) -> None:
    with RunLog(target, run_id="a") as log:
        assert log.applied_migrations() == [m.id for m in MIGRATIONS]
        log_one(log)
    with RunLog(target, run_id="b") as log:
        assert log.applied_migrations() == [m.id for m in MIGRATIONS]
        log_one(log, "t2")
        assert [c.task_id for c in log.calls()] == ["t1", "t2"]
        assert log.run_ids() == ["a", "b"]


def test_a_later_migration_keeps_the_rows_and_an_older_virf_refuses_the_log(target: str) -> None:
    with RunLog(target, run_id="old") as log:
        log_one(log)
    with RunLog(target, run_id="new", migrations=(*MIGRATIONS, LATER)) as log:
        assert log.applied_migrations() == [*(m.id for m in MIGRATIONS), LATER.id]
        assert [c.run_id for c in log.calls()] == ["old"]
    with pytest.raises(EnvironmentProblem, match=f"newer VIRF \\(migration {LATER.id}\\)"):
        RunLog(target, run_id="older")
    edited = Migration(LATER.id, LATER.sql.replace("note TEXT", "remark TEXT"))
    with pytest.raises(EnvironmentProblem, match=f"migration {LATER.id} differs"):
        RunLog(target, run_id="edited", migrations=(*MIGRATIONS, edited))


def test_a_failed_migration_leaves_nothing_behind(target: str) -> None:
    RunLog(target, run_id="a").close()
    broken = Migration("0099_broken", "CREATE TABLE half (x TEXT); INSERT INTO nowhere VALUES (1);")
    with pytest.raises(EnvironmentProblem, match="cannot migrate run log"):
        RunLog(target, run_id="a", migrations=(*MIGRATIONS, broken))
    half = Migration("0099_half", "CREATE TABLE half (x TEXT);")
    with RunLog(target, run_id="a", migrations=(*MIGRATIONS, half)) as log:
        # 'half' went with the rest of the failed migration: it can be created again.
        assert log.applied_migrations()[-1] == half.id


def test_records_are_the_same_on_both(tmp_path: Path, pg: str) -> None:
    seen = []
    for where in (str(tmp_path / "runs.db"), pg):
        with RunLog(where, run_id="r") as log:
            first = log_one(log, reply=None)
            second = log_one(log, "t2")
            assert second > first
            seen.append([{**vars(c), "created_at": None} for c in log.calls()])
    assert seen[0] == seen[1]
    assert seen[1][0]["messages"] == MESSAGES and seen[1][0]["latency_ms"] == 1.5


def test_several_machines_share_one_log(pg: str) -> None:
    """Two service processes write to one database at once; each row keeps its run."""
    one, two = RunLog(pg, run_id="machine-1"), RunLog(pg, run_id="machine-2")
    try:
        for i in range(5):
            log_one(one, f"a{i}")
            log_one(two, f"b{i}")
        assert sorted(one.run_ids()) == ["machine-1", "machine-2"]
        assert [c.task_id for c in two.calls(run_id="machine-1")] == [f"a{i}" for i in range(5)]
    finally:
        one.close()
        two.close()


def test_a_log_that_cannot_be_reached_is_one_line_without_its_password() -> None:
    url = "postgresql://virf:secret@127.0.0.1:1/nowhere"
    with pytest.raises(EnvironmentProblem) as exc:
        RunLog(url)
    message = str(exc.value)
    assert message.startswith("cannot connect to postgresql://virf:***@127.0.0.1:1/nowhere")
    assert "secret" not in message and "\n" not in message
    assert shown(url) == "postgresql://virf:***@127.0.0.1:1/nowhere"


def _virf(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "virf.cli.main", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_virf_plan_logs_its_model_calls_to_postgresql(pg: str) -> None:
    result = _virf(
        "plan",
        "--scene",
        "examples/dialogue/scene.json",
        "--instruction",
        (ROOT / "examples/dialogue/instruction.txt").read_text().strip(),
        "--planner",
        "replay:examples/dialogue/replay.jsonl",
        "--task-id",
        "demo-fridge",
        "--log",
        pg,
        "--json",
    )
    assert result.returncode == 0, result.stderr
    with RunLog(pg) as log:
        calls = log.calls(task_id="demo-fridge")
    assert calls and all(c.apprentice.startswith("replay") for c in calls)
    assert [c.iteration for c in calls] == sorted(c.iteration for c in calls)


def test_virf_plan_with_an_unreachable_log_says_so_in_one_line() -> None:
    result = _virf(
        "plan",
        "--scene",
        "examples/dialogue/scene.json",
        "--instruction",
        "Put the apple in the fridge.",
        "--planner",
        "replay:examples/dialogue/replay.jsonl",
        "--log",
        "postgresql://virf:secret@127.0.0.1:1/nowhere",
    )
    assert result.returncode != 0
    assert result.stderr.startswith("error: cannot connect to postgresql://virf:***@127.0.0.1:1")
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


def test_service_runs_are_recorded_in_the_shared_log(pg: str) -> None:
    from virf.service.app import create_app

    app = create_app(planners=[f"replay:{ROOT / 'examples/dialogue/replay.jsonl'}"], run_log=pg)
    scene = json.loads((ROOT / "examples/dialogue/scene.json").read_text())
    with TestClient(app, base_url=LOCAL) as client:
        started = client.post(
            "/v1/plan",
            json={
                "scene": scene,
                "instruction": (ROOT / "examples/dialogue/instruction.txt").read_text().strip(),
                "task_id": "demo-fridge",
            },
        )
        assert started.status_code == 202, started.text
        run_id = started.json()["id"]
        for _ in range(300):
            state = client.get(f"/v1/runs/{run_id}").json()
            if state["state"] == "waiting":
                client.post(f"/v1/runs/{run_id}/answers", json={"answers": {}})
            if state["state"] in ("done", "failed"):
                break
            time.sleep(0.1)
        assert state["state"] == "done", state
    with RunLog(pg) as log:
        assert log.calls(task_id="demo-fridge")


def _wait(client: TestClient, run_id: str, states: tuple[str, ...]) -> dict:
    for _ in range(600):
        state: dict = client.get(f"/v1/runs/{run_id}").json()
        if state["state"] in states:
            return state
        time.sleep(0.05)
    raise AssertionError(f"run {run_id} never reached {states}: {state}")


def test_any_worker_shows_streams_and_answers_a_run(target: str, tmp_path: Path) -> None:
    """Two workers (two apps) with one run log: a run started on one is
    shown, answered and streamed on the other, which never ran it."""
    from virf.service.app import create_app

    folder = ROOT / "examples" / "unknown-material-microwave"
    plan = json.loads((folder / "plan.txt").read_text())
    replay = tmp_path / "replay.jsonl"
    replay.write_text(json.dumps({"task_id": "q", "iteration": 0, "text": "\n".join(plan)}) + "\n")
    # The paper's USC-Uncertainty example, on the paper's rules (the household
    # rules also find the answered bowl of liquid left heating at the plan's end).
    one = create_app(scenario="paper", planners=[f"replay:{replay}"], run_log=target)
    two = create_app(scenario="paper", planners=[f"replay:{replay}"], run_log=target)
    with TestClient(one, base_url=LOCAL) as first, TestClient(two, base_url=LOCAL) as second:
        started = first.post(
            "/v1/plan",
            json={
                "scene": json.loads((folder / "scene.json").read_text()),
                "instruction": "Heat the cup in the microwave.",
                "task_id": "q",
            },
        )
        assert started.status_code == 202, started.text
        run_id = started.json()["id"]
        waiting = _wait(second, run_id, ("waiting", "done", "failed"))
        assert waiting["state"] == "waiting", waiting
        keys = [q["key"] for q in waiting["questions"]]
        refused = second.post(f"/v1/runs/{run_id}/answers", json={"answers": {"nope": "x"}})
        assert refused.status_code == 400 and "asked no question 'nope'" in refused.text
        answers = dict(zip(keys, ["Glass", "yes", "yes", "yes"], strict=True))
        answered = second.post(f"/v1/runs/{run_id}/answers", json={"answers": answers})
        assert answered.status_code == 200, answered.text
        with second.stream("GET", f"/v1/runs/{run_id}/events") as stream:
            kinds = [
                line.split(": ", 1)[1] for line in stream.iter_lines() if line.startswith("event: ")
            ]
        assert kinds[-1] == "result" and "turn" in kinds, kinds
        there = second.get(f"/v1/runs/{run_id}").json()
        assert there == first.get(f"/v1/runs/{run_id}").json()
        assert there["state"] == "done" and there["result"]["outcome"] == "APPROVED", there
    with TestClient(create_app(run_log=target), base_url=LOCAL) as third:
        assert third.get("/v1/runs/nothing").status_code == 404


def test_virf_serve_with_two_workers_shares_its_runs(tmp_path: Path) -> None:
    """A real `virf serve --workers 2 --run-log`: whichever process a request
    reaches, a run is shown, answered and finished."""
    import httpx

    from virf.service.bench import Server

    folder = ROOT / "examples" / "unknown-material-microwave"
    plan = json.loads((folder / "plan.txt").read_text())
    replay = tmp_path / "replay.jsonl"
    replay.write_text(json.dumps({"task_id": "q", "iteration": 0, "text": "\n".join(plan)}) + "\n")
    # The paper's example on the paper's rules, as in the test above.
    server = Server(
        2,
        *("--scenario", "paper"),
        *("--run-log", str(tmp_path / "runs.db")),
        *("--planner", f"replay:{replay}"),
    )
    try:
        server.wait_ready()
        workers = set()
        for _ in range(200):  # both processes answer before the run starts
            workers.add(httpx.get(f"{server.url}/v1/health", timeout=10).json()["worker"])
            if len(workers) == 2:
                break
            time.sleep(0.05)
        assert len(workers) == 2, workers
        body = {
            "scene": json.loads((folder / "scene.json").read_text()),
            "instruction": "Heat the cup in the microwave.",
            "task_id": "q",
        }
        run = httpx.post(f"{server.url}/v1/plan", json=body, timeout=30).json()
        for _ in range(600):
            # A new connection each time: any worker may take it.
            state = httpx.get(f"{server.url}/v1/runs/{run['id']}", timeout=10)
            assert state.status_code == 200, state.text
            if state.json()["state"] == "waiting":
                break
            time.sleep(0.05)
        keys = [q["key"] for q in state.json()["questions"]]
        answers = dict(zip(keys, ["Glass", "yes", "yes", "yes"], strict=True))
        posted = httpx.post(
            f"{server.url}/v1/runs/{run['id']}/answers", json={"answers": answers}, timeout=10
        )
        assert posted.status_code == 200, posted.text
        for _ in range(600):
            state = httpx.get(f"{server.url}/v1/runs/{run['id']}", timeout=10)
            assert state.status_code == 200, state.text
            if state.json()["state"] in ("done", "failed"):
                break
            time.sleep(0.05)
        assert state.json()["result"]["outcome"] == "APPROVED", state.json()
    finally:
        server.close()
