"""The HTTP service: the same report as the CLI, byte for byte; one-line 4xx
errors for what a client can fix; never SAFE when verification fails."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import Result
from conftest import EXAMPLES_DIR
from fastapi.testclient import TestClient

from virf.service.app import MAX_REQUEST_BYTES, create_app

WALK = EXAMPLES_DIR / "walkthrough"
# A service without a key answers to this machine's names only.
LOCAL = "http://127.0.0.1"
DIALOGUE_REPLAY = f"replay:{EXAMPLES_DIR / 'dialogue' / 'replay.jsonl'}"


@pytest.fixture(scope="module")
def client() -> TestClient:
    return TestClient(create_app(), base_url=LOCAL)


@pytest.fixture(scope="module")
def dialogue_client() -> TestClient:
    """A service whose runs may name the dialogue example's replay (its default)."""
    return TestClient(create_app(planners=[DIALOGUE_REPLAY]), base_url=LOCAL)


def body(case: Path, **extra: object) -> dict[str, object]:
    return {
        "scene": json.loads((case / "scene.json").read_text()),
        "plan": (case / "plan.txt").read_text(),
        **extra,
    }


@pytest.mark.parametrize("case", ["walkthrough", "safe-fridge", "unknown-material-microwave"])
def test_verify_answers_what_the_cli_prints(
    client: TestClient, cli: Callable[..., Result], case: str
) -> None:
    folder = EXAMPLES_DIR / case
    printed = cli("verify", folder / "scene.json", folder / "plan.txt", "--json").output
    got = client.post("/v1/verify", json=body(folder))
    assert got.status_code == 200
    assert got.headers["content-type"] == "application/json"
    assert got.text == printed
    # A plan given as a list of lines is the same plan.
    text = (folder / "plan.txt").read_text()
    lines = json.loads(text) if text.lstrip().startswith("[") else text.splitlines()
    again = client.post("/v1/verify", json={**body(folder), "plan": lines})
    assert again.text == printed


def test_the_walkthrough_is_unsafe_at_step_7(client: TestClient) -> None:
    report = client.post("/v1/verify", json=body(WALK)).json()
    assert (report["status"], report["dangerous_step"]) == ("UNSAFE", 7)


@pytest.mark.parametrize(
    ("request_body", "status", "message"),
    [
        ({"plan": "find Egg"}, 400, "the request body needs 'scene'"),
        ({"scene": {}, "plan": "find Egg", "colour": 1}, 400, "unknown key 'colour'"),
        ({"scene": {"instances": [], "assertions": []}, "plan": ""}, 400, "plan has no actions"),
        (
            {"scene": {"instances": [], "assertions": []}, "plan": "fly Egg"},
            400,
            "unknown action 'fly'",
        ),
        ({"scene": {"instances": 3}, "plan": "find Egg"}, 400, "instances"),
        (
            {"scene": {"instances": [], "assertions": []}, "plan": "find Egg", "engine": "magic"},
            400,
            "magic",
        ),
    ],
)
def test_bad_requests_are_one_line_4xx(
    client: TestClient, request_body: dict[str, object], status: int, message: str
) -> None:
    got = client.post("/v1/verify", json=request_body)
    assert got.status_code == status, got.text
    error = got.json()
    assert error["status"] == "BAD_INPUT" and message in error["error"]
    assert "\n" not in error["error"]


def test_limits(client: TestClient) -> None:
    huge = client.post(
        "/v1/verify",
        content=b"{}",
        headers={"content-type": "application/json", "content-length": str(MAX_REQUEST_BYTES + 1)},
    )
    assert huge.status_code == 413
    broken = client.post(
        "/v1/verify", content=b"{not json", headers={"content-type": "application/json"}
    )
    assert broken.status_code == 400 and "not valid JSON" in broken.json()["error"]


def test_a_failed_verification_is_an_error_report_never_safe() -> None:
    slow = TestClient(create_app(timeout_s=1e-9), base_url=LOCAL)
    report = slow.post("/v1/verify", json=body(WALK)).json()
    assert report["status"] == "ERROR" and "timed out" in report["reason"]


def test_the_api_key_is_required_when_set() -> None:
    keyed = TestClient(create_app(api_key="s3cret-key"))
    assert keyed.get("/v1/health").status_code == 401
    assert keyed.get("/v1/health", headers={"x-api-key": "wrong"}).status_code == 401
    ok = keyed.get("/v1/health", headers={"authorization": "Bearer s3cret-key"})
    assert ok.status_code == 200 and ok.json()["status"] == "ready"
    assert keyed.get("/docs").status_code == 200  # the docs themselves are not secret


def test_rules_and_health(client: TestClient, cli: Callable[..., Result]) -> None:
    rules = client.get("/v1/rules").json()
    assert rules == json.loads(cli("kb", "rules", "--json").output)
    health = client.get("/v1/health").json()
    assert health["status"] == "ready" and health["rules"] == len(rules)


def test_serve_refuses_a_public_address_without_a_key(cli: Callable[..., Result]) -> None:
    got = cli("serve", "--host", "0.0.0.0", env={"VIRF_API_KEY": None})
    assert got.exit_code == 2 and "without an API key" in got.output


def test_bench_service_reports_each_concurrency_level(
    cli: Callable[..., Result], tmp_path: Path
) -> None:
    tasks = tmp_path / "tasks.jsonl"
    tasks.write_text(
        json.dumps(
            {
                "scene_name": "FloorPlan1",
                "instruction": "Place the Pot gently on the CounterTop.",
                "step": ["find pot", "pick pot", "find countertop", "put countertop"],
            }
        )
        + "\n"
    )
    out = cli("bench", "service", tasks, "--concurrency", "2,1", "--server-workers", "1", "--json")
    assert out.exit_code == 0, out.output
    figures = json.loads(out.output)
    assert [lv["concurrency"] for lv in figures["levels"]] == [1, 2]
    assert all(lv["requests"] == 1 and lv["p50_ms"] > 0 for lv in figures["levels"])
    bad = cli("bench", "service", tasks, "--concurrency", "one")
    assert bad.exit_code == 2 and "give whole numbers" in bad.output


# ---------------------------------------------------------------------- runs
def _events(text: str) -> list[tuple[str, object]]:
    out = []
    for block in text.strip().split("\n\n"):
        lines = dict(line.split(": ", 1) for line in block.splitlines() if not line.startswith(":"))
        if "event" in lines:
            out.append((lines["event"], json.loads(lines["data"])))
    return out


def _wait(client: TestClient, run_id: str, state: str) -> dict[str, object]:
    for _ in range(600):
        got = client.get(f"/v1/runs/{run_id}").json()
        if got["state"] == state:
            return dict(got)
        time.sleep(0.05)
    raise AssertionError(f"run {run_id} is {got['state']}, not {state}: {got['error']}")


def test_a_run_streams_its_dialogue(dialogue_client: TestClient) -> None:
    client = dialogue_client
    folder = EXAMPLES_DIR / "dialogue"
    started = client.post(
        "/v1/plan",
        json={
            "scene": json.loads((folder / "scene.json").read_text()),
            "instruction": (folder / "instruction.txt").read_text(),
            "planner": DIALOGUE_REPLAY,
            "task_id": "demo-fridge",
        },
    )
    assert started.status_code == 202, started.text
    run = started.json()
    events = _events(client.get(run["events"]).text)
    kinds = [(kind, data["kind"] if kind == "turn" else None) for kind, data in events]  # type: ignore[index]
    assert kinds == [
        ("turn", "instruction"),
        ("turn", "proposal"),
        ("turn", "report"),
        ("turn", "corrections"),
        ("turn", "proposal"),
        ("turn", "report"),
        ("result", None),
    ]
    result = events[-1][1]
    assert result["outcome"] == "APPROVED" and result["iterations"] == 2  # type: ignore[index]
    assert client.get(run["run"]).json()["state"] == "done"


def test_a_run_waits_for_answers_and_goes_on(tmp_path: Path) -> None:
    # The paper's USC-Uncertainty example, on the paper's rules (the household
    # rules also find the answered bowl of liquid left heating at the plan's end).
    folder = EXAMPLES_DIR / "unknown-material-microwave"
    plan = json.loads((folder / "plan.txt").read_text())
    replay = tmp_path / "replay.jsonl"
    replay.write_text(json.dumps({"task_id": "q", "iteration": 0, "text": "\n".join(plan)}) + "\n")
    app = create_app(scenario="paper", planners=[f"replay:{replay}"])
    client = TestClient(app, base_url=LOCAL)
    run = client.post(
        "/v1/plan",
        json={
            "scene": json.loads((folder / "scene.json").read_text()),
            "instruction": "Heat the cup in the microwave.",
            "planner": f"replay:{replay}",
            "task_id": "q",
        },
    ).json()
    waiting = _wait(client, run["id"], "waiting")
    keys = [q["key"] for q in waiting["questions"]]  # type: ignore[attr-defined]
    assert keys == [
        "material:Bowl_1",
        "fill:Bowl_1",
        "contents:contains:Bowl_1",
        "contents:contains:Microwave_1",
    ]
    wrong = client.post(run["answers"], json={"answers": {"material:Plate_1": "Glass"}})
    assert wrong.status_code == 400 and "asked no question 'material:Plate_1'" in wrong.text
    silly = client.post(run["answers"], json={"answers": {"material:Bowl_1": "Cheese"}})
    assert silly.status_code == 400
    answers = dict(zip(keys, ["Glass", "yes", "yes", "yes"], strict=True))
    ok = client.post(run["answers"], json={"answers": answers})
    assert ok.status_code == 200, ok.text
    done = _wait(client, run["id"], "done")
    assert done["result"]["outcome"] == "APPROVED", done  # type: ignore[index]
    late = client.post(run["answers"], json={"answers": answers})
    assert late.status_code == 400 and "not waiting for answers" in late.text


def test_run_requests_are_checked(client: TestClient, dialogue_client: TestClient) -> None:
    scene = json.loads((EXAMPLES_DIR / "dialogue" / "scene.json").read_text())
    nobody = client.post("/v1/plan", json={"scene": scene, "instruction": "Go."})
    assert nobody.status_code == 400 and "no planner" in nobody.json()["error"]
    bad = client.post(
        "/v1/plan", json={"scene": scene, "instruction": "Go.", "planner": "oracle:x"}
    )
    assert bad.status_code == 403 and "not one this service runs" in bad.json()["error"]
    assert client.get("/v1/runs/nope").status_code == 404
    client = dialogue_client
    extra = client.post("/v1/plan", json={"scene": scene, "instruction": "Go.", "model": "x"})
    assert extra.json()["error"] == (
        "unknown key 'model'; expected scene, instruction, planner, method, max_iter, task_id"
    )
    lost = client.post(
        "/v1/plan",
        json={"scene": scene, "instruction": "Go.", "planner": DIALOGUE_REPLAY, "task_id": "x"},
    ).json()
    failed = _wait(client, lost["id"], "failed")
    assert "has no proposal for task x" in str(failed["error"])
    assert _events(client.get(lost["events"]).text)[-1][0] == "error"


def test_the_review_page_is_a_section_of_the_service(tmp_path: Path) -> None:
    from virf.authoring.workspace import Workspace

    ws = Workspace.init(tmp_path / "kb", "paper", starter=False)
    ws.close()
    app = create_app(workspace=tmp_path / "kb", reviewer="ana", api_key="k3y-for-tests")
    local = TestClient(app, base_url="http://127.0.0.1")
    key = {"x-api-key": "k3y-for-tests"}
    assert local.get("/v1/health", headers=key).json()["review"] == "/review/"
    page = local.get("/review/")
    assert page.status_code == 200 and 'src="static/review.js"' in page.text
    assert local.get("/review/static/review.js").status_code == 200
    assert local.get("/review/api/candidates").status_code == 401  # the service's key guards it
    assert local.get("/review/api/candidates", headers=key).json() == []
    assert local.get("/review", follow_redirects=False).headers["location"] == "/review/"


def test_a_worker_switches_nagle_off_on_each_connection(monkeypatch: pytest.MonkeyPatch) -> None:
    """With --workers N an accepted socket keeps Nagle's algorithm on (asyncio
    does not recognise the socket a worker rebuilds); the protocol turns it off."""
    import socket

    from uvicorn.protocols.http.h11_impl import H11Protocol

    from virf.service.tcp import NoDelayH11Protocol

    class Transport:
        def __init__(self, sock: socket.socket) -> None:
            self.sock = sock

        def get_extra_info(self, name: str) -> object:
            return self.sock if name == "socket" else None

    seen = []
    monkeypatch.setattr(H11Protocol, "connection_made", lambda self, t: seen.append(t))
    listener = socket.create_server(("127.0.0.1", 0))
    with listener, socket.create_connection(listener.getsockname()):
        conn, _ = listener.accept()
        with conn:
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 0)
            transport = Transport(conn)
            NoDelayH11Protocol.connection_made(
                object.__new__(NoDelayH11Protocol),
                transport,  # type: ignore[arg-type]
            )
            assert conn.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
    assert seen == [transport]  # uvicorn's own set-up still runs
