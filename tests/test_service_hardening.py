"""The service under a red-team pass (issue 28): what it reads, how much, which
planners a client may name, who may reach it, and the shape of every error.

* One reader of request and file bytes: a body with a duplicate key or a NaN
  is refused as ``virf verify`` refuses a file with one, on every JSON route,
  never verified as whichever value came last.
* The body limit counts the bytes read, whatever the framing: a small
  Content-Length over a chunked body changes nothing.
* A client names only planners the server was started with; the path of a
  replay it names is never opened.
* A keyless service answers only to this machine's names (Host, Origin).
* Every 4xx is ``{"status": "BAD_INPUT", "error": one line}``, FastAPI's own
  404 and 405 included; an Authorization header without ``Bearer`` is no key.
"""

from __future__ import annotations

import contextlib
import json
import re
import select
import socket
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from browser_support import serving
from click.testing import Result
from conftest import EXAMPLES_DIR, inst, rel
from fastapi.testclient import TestClient

from virf.service.app import MAX_REQUEST_BYTES, create_app

LOCAL = "http://127.0.0.1"
DIALOGUE = EXAMPLES_DIR / "dialogue"
DIALOGUE_REPLAY = f"replay:{DIALOGUE / 'replay.jsonl'}"

# A fork inside a running toaster: UNSAFE at step 0, whatever the plan does.
DANGER: list[dict[str, str]] = [
    rel("Fork_1", "isInside", "Toaster_1"),
    rel("Toaster_1", "hasState", "on", "data_property"),
]
INSTANCES = [
    inst("Toaster", "Toaster_1"),
    inst("Fork", "Fork_1"),
    inst("Pot", "Pot_1"),
    inst("CounterTop", "CounterTop_1"),
]
SCENE_TWICE = (
    '{"instances": ' + json.dumps(INSTANCES) + ', "assertions": ' + json.dumps(DANGER) + ", "
    '"assertions": []}'
)


@pytest.fixture(scope="module")
def client() -> TestClient:
    return TestClient(create_app(), base_url=LOCAL)


def post_raw(client: TestClient, path: str, raw: str | bytes, **headers: str) -> Any:
    data = raw.encode() if isinstance(raw, str) else raw
    return client.post(path, content=data, headers={"content-type": "application/json", **headers})


def error_of(response: Any, status: int) -> str:
    """The one line of a documented error answer (and that it is one)."""
    assert response.status_code == status, response.text
    body = response.json()
    assert set(body) == {"status", "error"}, body
    assert body["status"] == ("BAD_INPUT" if status < 500 else "ERROR"), body
    assert isinstance(body["error"], str) and body["error"] and "\n" not in body["error"]
    return str(body["error"])


# ------------------------------------------------- 1. one reader, strict JSON
def test_a_scene_with_its_assertions_twice_is_refused_as_the_cli_refuses_it(
    client: TestClient, cli: Callable[..., Result], tmp_path: Path
) -> None:
    scene = tmp_path / "scene.json"
    scene.write_text(SCENE_TWICE, encoding="utf-8")
    plan = tmp_path / "plan.txt"
    plan.write_text("find Pot\n", encoding="utf-8")
    printed = cli("verify", scene, plan, "--json")
    assert printed.exit_code == 2
    said = json.loads(printed.stdout)["error"]
    assert said.endswith("duplicate key 'assertions' (the later value would hide the first)")

    got = post_raw(client, "/v1/verify", '{"scene": ' + SCENE_TWICE + ', "plan": "find Pot"}')
    error = error_of(got, 400)
    assert error == (
        "the request body is not valid JSON: duplicate key 'assertions' "
        "(the later value would hide the first)"
    )
    # The scene the first key describes is UNSAFE: the key was the difference.
    alone = {"instances": INSTANCES, "assertions": DANGER}
    report = client.post("/v1/verify", json={"scene": alone, "plan": "find Pot"}).json()
    assert report["status"] == "UNSAFE"


def test_a_body_with_the_plan_twice_is_refused(client: TestClient) -> None:
    scene = {"instances": INSTANCES, "assertions": [rel("Fork_1", "isOn", "CounterTop_1")]}
    dangerous = (
        "find Fork_1\npick Fork_1\nfind Toaster_1\nput Fork_1 in Toaster_1\nturn on Toaster_1"
    )
    verdicts = [
        client.post("/v1/verify", json={"scene": scene, "plan": plan}).json()["status"]
        for plan in (dangerous, "find Pot")
    ]
    assert verdicts == ["UNSAFE", "SAFE"]  # the key decides the verdict
    raw = (
        '{"scene": ' + json.dumps(scene) + ', "plan": ' + json.dumps(dangerous) + ", "
        '"plan": "find Pot"}'
    )
    assert "duplicate key 'plan'" in error_of(post_raw(client, "/v1/verify", raw), 400)


def test_nan_in_a_body_is_refused(client: TestClient) -> None:
    raw = '{"scene": {"instances": [], "assertions": []}, "plan": "find Pot", "engine": NaN}'
    assert error_of(post_raw(client, "/v1/verify", raw), 400) == (
        "the request body is not valid JSON: NaN is not a JSON number"
    )


def test_a_body_that_is_not_utf8_is_refused(client: TestClient) -> None:
    raw = b'{"scene": {}, "plan": "find P\xf6t"}'
    assert error_of(post_raw(client, "/v1/verify", raw), 400) == (
        "the request body is not UTF-8 text"
    )


JSON_ROUTES = [
    "/v1/verify",
    "/v1/state",
    "/v1/apply-answers",
    "/v1/learn",
    "/v1/plan",
    "/v1/runs/0123/answers",
]


@pytest.mark.parametrize("path", JSON_ROUTES)
def test_every_json_route_reads_bodies_strictly(client: TestClient, path: str) -> None:
    raw = '{"scene": {"instances": []}, "scene": {"instances": []}}'
    assert "duplicate key 'scene'" in error_of(post_raw(client, path, raw), 400)


def test_the_review_routes_read_bodies_strictly(tmp_path: Path) -> None:
    from virf.authoring.workspace import Workspace

    Workspace.init(tmp_path / "kb", "paper", starter=False).close()
    local = TestClient(create_app(workspace=tmp_path / "kb", reviewer="ana"), base_url=LOCAL)
    raw = '{"decision": "reject", "reason": "no", "decision": "accept"}'
    got = post_raw(local, "/review/api/candidates/1/decision", raw)
    assert "duplicate key 'decision'" in error_of(got, 400)


# ---------------------------------------------------- 3. bytes read, not declared
def test_a_small_content_length_does_not_lift_the_limit(client: TestClient) -> None:
    big = (
        b'{"scene": {"instances": [], "assertions": []}, "plan": "'
        + b"#" * (MAX_REQUEST_BYTES + 1)
        + b'"}'
    )
    got = post_raw(client, "/v1/verify", big, **{"content-length": "1"})
    assert "larger than 8 MiB" in error_of(got, 413)


def test_a_chunked_body_is_read_up_to_the_limit(client: TestClient) -> None:
    def chunks(raw: bytes) -> Iterator[bytes]:
        for start in range(0, len(raw), 1 << 20):
            yield raw[start : start + (1 << 20)]

    walk = EXAMPLES_DIR / "walkthrough"
    small = json.dumps(
        {"scene": json.loads((walk / "scene.json").read_text()), "plan": "find Pot"}
    ).encode()
    got = client.post(
        "/v1/verify", content=chunks(small), headers={"content-type": "application/json"}
    )
    assert got.status_code == 200 and got.json()["status"] in ("SAFE", "UNKNOWN"), got.text
    big = b'{"plan": "' + b"#" * (MAX_REQUEST_BYTES + 1) + b'"}'
    got = client.post(
        "/v1/verify", content=chunks(big), headers={"content-type": "application/json"}
    )
    assert "larger than 8 MiB" in error_of(got, 413)


def test_a_real_server_stops_reading_a_chunked_body_at_the_limit() -> None:
    """The red team's request, on a socket: Content-Length 1 and a chunked
    body far above the limit (uvicorn frames it by Transfer-Encoding).  The
    server answers 413 once the limit is passed and closes the connection."""
    with (
        serving(create_app()) as url,
        socket.create_connection(("127.0.0.1", int(url.rstrip("/").rsplit(":", 1)[1]))) as sock,
    ):
        sock.settimeout(30)
        sock.sendall(
            b"POST /v1/verify HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            b"Content-Type: application/json\r\nContent-Length: 1\r\n"
            b"Transfer-Encoding: chunked\r\n\r\n"
        )
        chunk = b"#" * (1 << 16)
        sent = 0
        with contextlib.suppress(OSError):  # the server may close while we send
            while sent < 12 * MAX_REQUEST_BYTES:
                if select.select([sock], [], [], 0)[0]:
                    break  # it answered
                sock.sendall(b"%x\r\n%s\r\n" % (len(chunk), chunk))
                sent += len(chunk)
        answer = b""
        with contextlib.suppress(OSError):
            while more := sock.recv(65536):
                answer += more
    assert sent < 2 * MAX_REQUEST_BYTES, f"sent {sent} bytes before an answer"
    head, _, body = answer.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 413"), answer[:300]
    assert b"connection: close" in head.lower()
    assert json.loads(body) == {"status": "BAD_INPUT", "error": "request body larger than 8 MiB"}


# ------------------------------------------------------------ 5. planners, hosts
@pytest.fixture
def no_apprentice(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail any attempt to make an apprentice: the path must not be touched."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError(f"make_apprentice was called with {args}")

    monkeypatch.setattr("virf.service.runs.make_apprentice", refuse)


def plan_body(planner: str) -> dict[str, object]:
    scene = json.loads((DIALOGUE / "scene.json").read_text())
    return {"scene": scene, "instruction": "Go.", "planner": planner, "task_id": "x"}


def test_a_client_cannot_name_a_path_for_the_server_to_open(
    client: TestClient, tmp_path: Path, no_apprentice: None
) -> None:
    secret = tmp_path / "secret.json"
    secret.write_text(json.dumps({"password_hash": "x"}))
    answers = []
    for path in (secret, tmp_path, tmp_path / "missing.jsonl", Path("/etc/passwd")):
        got = client.post("/v1/plan", json=plan_body(f"replay:{path}"))
        answers.append(re.sub(r"'[^']*'", "'...'", error_of(got, 403), count=1))
    assert len(set(answers)) == 1, answers  # nothing tells the paths apart
    assert "password_hash" not in answers[0]
    assert "--planner" in answers[0]


def test_only_the_planners_the_server_runs_may_be_named(tmp_path: Path) -> None:
    other = tmp_path / "other.jsonl"
    app = create_app(planners=[DIALOGUE_REPLAY, "openai:gpt-4o-mini"])
    local = TestClient(app, base_url=LOCAL)
    refused = error_of(local.post("/v1/plan", json=plan_body(f"replay:{other}")), 403)
    assert DIALOGUE_REPLAY in refused and "openai:gpt-4o-mini" in refused
    assert error_of(local.post("/v1/plan", json=plan_body("openai:gpt-5")), 403)
    named = local.post("/v1/plan", json=plan_body(DIALOGUE_REPLAY))
    assert named.status_code == 202, named.text
    # The first is the default of a run that names none.
    body = plan_body(DIALOGUE_REPLAY)
    del body["planner"]
    assert local.post("/v1/plan", json=body).status_code == 202
    assert local.get("/v1/health").json()["planners"] == [DIALOGUE_REPLAY, "openai:gpt-4o-mini"]


def test_serve_takes_several_planners(
    monkeypatch: pytest.MonkeyPatch, cli: Callable[..., Result]
) -> None:
    seen: dict[str, Any] = {}

    def fake_create_app(**options: Any) -> object:
        seen.update(options)
        return object()

    monkeypatch.setattr("virf.service.app.create_app", fake_create_app)
    monkeypatch.setattr("uvicorn.run", lambda *a, **k: None)  # several workers
    monkeypatch.setattr("uvicorn.Server.run", lambda *a, **k: None)  # one
    got = cli("serve", "--planner", DIALOGUE_REPLAY, "--planner", "openai:gpt-4o-mini")
    assert got.exit_code == 0, got.output
    assert seen["planners"] == [DIALOGUE_REPLAY, "openai:gpt-4o-mini"]


def test_a_keyless_service_answers_only_to_this_machines_names(client: TestClient) -> None:
    foreign = client.get("/v1/health", headers={"host": "evil.example:8000"})
    assert "127.0.0.1" in error_of(foreign, 403)
    for host in ("127.0.0.1:8000", "localhost", "[::1]:8000"):
        assert client.get("/v1/health", headers={"host": host}).status_code == 200, host
    post = client.post(
        "/v1/verify",
        json={"scene": {"instances": []}, "plan": "find Pot"},
        headers={"origin": "https://evil.example"},
    )
    assert "evil.example" in error_of(post, 403)


def test_a_service_with_a_key_answers_any_host_that_has_the_key() -> None:
    keyed = TestClient(create_app(api_key="s3cret-key"), base_url="http://virf.example")
    got = keyed.get("/v1/health", headers={"x-api-key": "s3cret-key"})
    assert got.status_code == 200


# ----------------------------------------------------------- 10. one error shape
def test_an_unknown_path_is_a_documented_404_naming_the_closest(client: TestClient) -> None:
    error = error_of(client.post("/v1/verfy", json={}), 404)
    assert "/v1/verfy" in error and "/v1/verify" in error


def test_a_wrong_method_is_a_documented_405_naming_the_allowed_one(client: TestClient) -> None:
    error = error_of(client.get("/v1/verify"), 405)
    assert "GET" in error and "POST" in error


def test_a_missing_asset_is_a_documented_404(client: TestClient) -> None:
    error_of(client.get("/assets/nope.js"), 404)


def test_the_review_section_answers_in_the_documented_shape(tmp_path: Path) -> None:
    from virf.authoring.workspace import Workspace

    Workspace.init(tmp_path / "kb", "paper", starter=False).close()
    local = TestClient(create_app(workspace=tmp_path / "kb", reviewer="ana"), base_url=LOCAL)
    assert "candidate" in error_of(local.get("/review/api/candidates/999"), 404)
    assert "'abc'" in error_of(local.get("/review/api/candidates/abc"), 400)
    assert "127.0.0.1" in error_of(
        local.get("/review/api/candidates", headers={"host": "evil.example"}), 403
    )


def test_a_key_without_bearer_is_no_key() -> None:
    keyed = TestClient(create_app(api_key="s3cret-key"), base_url=LOCAL)
    for header in ("s3cret-key", "Basic s3cret-key", "Bearer", "Bearer wrong"):
        got = keyed.get("/v1/health", headers={"authorization": header})
        assert "API key" in error_of(got, 401), header
    ok = keyed.get("/v1/health", headers={"authorization": "Bearer s3cret-key"})
    assert ok.status_code == 200
    ok = keyed.get("/v1/health", headers={"authorization": "bearer s3cret-key"})
    assert ok.status_code == 200  # the scheme is case-insensitive (RFC 9110)


def test_a_body_that_is_not_json_by_its_type_is_refused_in_one_line(client: TestClient) -> None:
    got = client.post("/v1/verify", content=b"{}", headers={"content-type": "text/plain"})
    assert "Content-Type: application/json" in error_of(got, 400)


def test_serve_says_where_it_listens() -> None:
    """`virf serve --port 0` picks a free port; the one line it prints names
    it, and the service answers there (uvicorn's own lines are silenced)."""
    import os
    import signal
    import subprocess
    import sys

    import httpx
    from conftest import ROOT

    serve = subprocess.Popen(
        [sys.executable, "-m", "virf.cli.main", "serve", "--port", "0"],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT / "src")),
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert serve.stderr is not None
        lines = []
        while True:
            line = serve.stderr.readline()
            assert line, f"virf serve ended before saying where: {lines}"
            lines.append(line)
            found = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
            if found:
                break
        port = int(found.group(1))
        assert port > 0
        assert httpx.get(f"http://127.0.0.1:{port}/v1/health", timeout=30).status_code == 200
    finally:
        serve.send_signal(signal.SIGTERM)
        serve.wait(timeout=60)
