"""The review server's JSON API, against an in-memory stand-in for the
workspace (fast: no Java, no store).  The browser test drives the real
workspace; these pin the HTTP contract: status codes, one-line errors,
which workspace call each request makes, and the local-only guards."""

from __future__ import annotations

import re
import threading
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from review_support import DRAFT, FakeWorkspace, sample_workspace

from virf.authoring.models import (
    Decision,
    DecisionView,
)
from virf.authoring.review import STATIC_DIR, ReviewWorkspace, create_app
from virf.errors import InputError


@pytest.fixture
def ws() -> FakeWorkspace:
    return sample_workspace()


@pytest.fixture
def client(ws: FakeWorkspace) -> TestClient:
    fake: ReviewWorkspace = ws  # the fake must satisfy the protocol the app takes
    return TestClient(create_app(fake, "ana"), base_url="http://127.0.0.1")


def one_line_error(response: Any, status: int) -> str:
    assert response.status_code == status, response.text
    body = response.json()
    # The service's documented error shape (the review page is its /review/ section).
    assert set(body) == {"status", "error"}, body
    assert body["status"] == ("BAD_INPUT" if status < 500 else "ERROR"), body
    detail = body["error"]
    assert isinstance(detail, str) and detail and "\n" not in detail
    return detail


# -- the page ------------------------------------------------------------------


def test_the_page_and_its_assets_are_served_locally(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200
    assert page.headers["content-type"].startswith("text/html")
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assert 'id="queue"' in page.text
    # Relative, so the page works at / (virf kb review) and at /review/ (virf serve).
    for asset in ("static/review.js", "static/review.css"):
        assert f'"{asset}"' in page.text
        assert client.get(f"/{asset}").status_code == 200


def test_the_page_loads_nothing_from_the_internet() -> None:
    # The review page must work offline: no CDN script, font or style.
    for path in STATIC_DIR.iterdir():
        text = path.read_text(encoding="utf-8")
        loads = re.findall(r"(?:src|href)\s*=\s*[\"'](https?:)?//", text) + re.findall(
            r"@import|url\(\s*[\"']?https?:", text
        )
        assert not loads, f"{path.name} loads from outside: {loads}"


# -- the queue and a candidate ------------------------------------------------


def test_queue_defaults_to_pending_and_filters(client: TestClient) -> None:
    pending = client.get("/api/candidates").json()
    assert [(c["id"], c["status"]) for c in pending] == [(1, "pending"), (2, "pending")]
    everything = client.get("/api/candidates?status=all").json()
    assert [c["status"] for c in everything] == ["pending", "pending", "rejected"]
    assert [c["id"] for c in client.get("/api/candidates?status=rejected").json()] == [3]


def test_an_unknown_status_filter_names_the_choices(client: TestClient) -> None:
    detail = one_line_error(client.get("/api/candidates?status=pendign"), 400)
    assert "pendign" in detail and "pending, accepted, rejected, all" in detail


def test_opening_a_pending_candidate_records_the_reviewer(
    client: TestClient, ws: FakeWorkspace
) -> None:
    view = client.get("/api/candidates/2").json()
    assert view["rule"]["name"] == "CurtainNearBurnerDanger"
    assert [e["found"] for e in view["evidence"]] == [True, False]
    assert ("opened", 2, "ana") in ws.calls
    # A decided candidate is only looked at: no review time starts.
    client.get("/api/candidates/3")
    assert ("opened", 3, "ana") not in ws.calls


def test_an_unknown_candidate_is_404_in_the_workspace_words(client: TestClient) -> None:
    assert one_line_error(client.get("/api/candidates/42"), 404) == (
        "no candidate 42; the workspace has 1-3"
    )
    one_line_error(client.post("/api/candidates/42/check", json={"axiom": DRAFT}), 404)
    one_line_error(client.post("/api/candidates/42/decision", json={"decision": "accept"}), 404)


def test_a_candidate_id_must_be_a_number(client: TestClient) -> None:
    detail = one_line_error(client.get("/api/candidates/abc"), 400)
    assert "'abc'" in detail
    # Too large for the store's integers: still just an unknown candidate.
    one_line_error(client.get(f"/api/candidates/{2**70}"), 404)


def test_an_unknown_endpoint_is_a_json_404(client: TestClient) -> None:
    assert "/api/candidatez" in one_line_error(client.get("/api/candidatez"), 404)


# -- checks and previews ------------------------------------------------------


def test_check_runs_the_edited_axiom(client: TestClient, ws: FakeWorkspace) -> None:
    edited = DRAFT.replace("PaperTowel", "Napkin")
    body = client.post("/api/candidates/1/check", json={"axiom": edited})
    assert body.status_code == 200
    got = body.json()
    assert got["axiom"] == edited and got["passed"] is True
    assert got["terms"][0]["alternatives"] == [["Towel", 0.86], ["Paper", 0.71]]
    assert ws.calls[-1] == ("recheck", 1, edited)


@pytest.mark.parametrize(
    ("body", "words"),
    [
        ({"axiom": DRAFT, "axoim": "x"}, "unknown key 'axoim'"),
        ({}, "the request body needs 'axiom'"),
        ({"axiom": "x" * 4_001}, "'axiom' is longer than 4000 characters"),
        ({"axiom": 3}, "'axiom' must be Manchester-syntax text"),
        ({"axiom": ""}, "'axiom' must not be empty"),
        ([DRAFT], "must be a JSON object"),
    ],
)
def test_a_bad_check_body_is_one_line(client: TestClient, body: object, words: str) -> None:
    detail = one_line_error(client.post("/api/candidates/1/check", json=body), 400)
    assert words in detail


def test_a_body_that_is_not_json_is_refused(client: TestClient) -> None:
    bad = client.post(
        "/api/candidates/1/check",
        content=b"{axiom: nope",
        headers={"Content-Type": "application/json"},
    )
    assert one_line_error(bad, 400).startswith("the request body is not valid JSON: ")
    # A form post (what another site's page could send) is not JSON.
    form = client.post("/api/candidates/1/check", data={"axiom": DRAFT})
    assert "must be JSON" in one_line_error(form, 400)


def test_a_missing_java_is_503(client: TestClient) -> None:
    detail = one_line_error(
        client.post("/api/candidates/1/check", json={"axiom": "NoJava and Thing"}), 503
    )
    assert detail.startswith("Java is not installed")


def test_preview_passes_the_edited_axiom_or_none(client: TestClient, ws: FakeWorkspace) -> None:
    got = client.post("/api/candidates/1/preview", json={"axiom": None}).json()
    assert got["changes"][0]["after"] == "UNSAFE"
    client.post("/api/candidates/1/preview", json={"axiom": "Edited"})
    previews = [call for call in ws.calls if call[0] == "preview"]
    assert previews == [("preview", 1, None), ("preview", 1, "Edited")]


# -- decisions ----------------------------------------------------------------


def test_accept_records_the_reviewer_and_lists_the_rule(
    client: TestClient, ws: FakeWorkspace
) -> None:
    got = client.post("/api/candidates/1/decision", json={"decision": "accept"})
    assert got.status_code == 200, got.text
    assert got.json()["reviewer"] == "ana" and got.json()["decision"] == "accept"
    assert ws.calls[-1] == ("decide", 1, "accept", "ana", None, None)
    assert [r["name"] for r in client.get("/api/rules").json()] == ["PaperTowelOnBurnerDanger"]
    assert [c["id"] for c in client.get("/api/candidates").json()] == [2]


def test_accept_edited_sends_the_axiom(client: TestClient, ws: FakeWorkspace) -> None:
    edited = DRAFT.replace("PaperTowel", "Napkin")
    got = client.post(
        "/api/candidates/1/decision", json={"decision": "accept", "reason": None, "axiom": edited}
    )
    assert got.json()["edit"] == "minor"
    assert ws.calls[-1] == ("decide", 1, "accept", "ana", None, edited)


def test_a_decided_candidate_is_a_conflict(client: TestClient, ws: FakeWorkspace) -> None:
    detail = one_line_error(
        client.post("/api/candidates/3/decision", json={"decision": "accept"}), 409
    )
    assert "already rejected" in detail
    assert not any(call[0] == "decide" for call in ws.calls)


def test_deciding_in_a_race_is_a_conflict(client: TestClient, ws: FakeWorkspace) -> None:
    # Another reviewer decides between this server's look-up and its call.
    real = ws.decide

    def late(cid: int, decision: Decision, **kw: Any) -> DecisionView:
        ws.items[cid].status = "accepted"
        return real(cid, decision, **kw)

    ws.decide = late  # type: ignore[method-assign]
    one_line_error(client.post("/api/candidates/1/decision", json={"decision": "accept"}), 409)


def test_reject_needs_a_reason(client: TestClient, ws: FakeWorkspace) -> None:
    for reason in (None, "", "   "):
        detail = one_line_error(
            client.post(
                "/api/candidates/1/decision", json={"decision": "reject", "reason": reason}
            ),
            400,
        )
        assert "reason" in detail
    ok = client.post(
        "/api/candidates/1/decision", json={"decision": "reject", "reason": " not a hazard "}
    )
    assert ok.status_code == 200 and ok.json()["reason"] == "not a hazard"


def test_a_failing_check_refuses_the_accept_in_the_workspace_words(client: TestClient) -> None:
    detail = one_line_error(
        client.post(
            "/api/candidates/1/decision", json={"decision": "accept", "axiom": "Broken and Thing"}
        ),
        400,
    )
    assert detail == "cannot accept candidate 1: the concept is unsatisfiable"


def test_an_unknown_decision_names_the_choices(client: TestClient) -> None:
    detail = one_line_error(
        client.post("/api/candidates/1/decision", json={"decision": "maybe"}), 400
    )
    assert detail == "'decision' must be 'accept' or 'reject', not \"maybe\""


# -- local only ---------------------------------------------------------------


def test_a_foreign_host_is_refused(client: TestClient) -> None:
    # DNS rebinding: a page on evil.example resolved to 127.0.0.1.
    got = client.get("/api/candidates", headers={"Host": "evil.example:8765"})
    assert "127.0.0.1" in one_line_error(got, 403)
    assert client.get("/api/candidates", headers={"Host": "localhost:8765"}).status_code == 200


def test_a_post_from_another_site_is_refused(client: TestClient, ws: FakeWorkspace) -> None:
    got = client.post(
        "/api/candidates/1/decision",
        json={"decision": "accept"},
        headers={"Origin": "https://evil.example"},
    )
    assert "evil.example" in one_line_error(got, 403)
    assert not any(call[0] == "decide" for call in ws.calls)
    same = client.post(
        "/api/candidates/1/check",
        json={"axiom": DRAFT},
        headers={"Origin": "http://127.0.0.1:8765"},
    )
    assert same.status_code == 200


def test_an_empty_reviewer_name_is_refused(ws: FakeWorkspace) -> None:
    with pytest.raises(InputError, match="reviewer"):
        create_app(ws, "  ")


# -- the command ----------------------------------------------------------------


def test_review_needs_a_workspace(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from virf.cli.main import app

    got = CliRunner().invoke(app, ["kb", "review", "--workspace", str(tmp_path / "none")])
    assert got.exit_code == 2
    assert "virf kb init" in got.output
    assert "Traceback" not in got.output


def test_review_serves_until_ctrl_c(tmp_path: Path) -> None:
    """The real command in its own process: it prints its address, answers,
    and stops cleanly (exit 0, no traceback) on SIGINT, with Java started
    (which, run with -Xrs, leaves Ctrl-C to the server)."""
    import json
    import signal
    import subprocess
    import sys
    import urllib.request

    from virf.authoring.workspace import Workspace

    Workspace.init(tmp_path / "kb", "paper", starter=False).close()
    cmd = [sys.executable, "-m", "virf.cli.main", "kb", "review", "-w", str(tmp_path / "kb")]
    proc = subprocess.Popen(
        [*cmd, "--port", "0", "--reviewer", "ana"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # A server that never prints its address must not hang the suite.
    watchdog = threading.Timer(60, proc.kill)
    watchdog.start()
    try:
        assert proc.stdout is not None
        # A warning (no Java) may come first; the address is on its own line.
        line = proc.stdout.readline()
        if line.startswith("warning:"):
            line = proc.stdout.readline()
        found = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
        assert found, f"no address in {line!r}; stderr: {proc.stderr.read() if proc.stderr else ''}"
        assert "ana" in line
        with urllib.request.urlopen(f"{found.group(0)}api/candidates?status=all") as answer:
            assert json.load(answer) == []
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "stopped" in out
    assert "Traceback" not in err


def test_an_empty_real_workspace(tmp_path: Path) -> None:
    # The real store, without Java: an empty queue, and ids it has not got,
    # including one too large for SQLite's integers, are plain 404s.
    from virf.authoring.workspace import Workspace

    ws = Workspace.init(tmp_path / "kb", "paper", starter=False)
    try:
        client = TestClient(create_app(ws, "ana"), base_url="http://127.0.0.1")
        assert client.get("/api/candidates?status=all").json() == []
        assert client.get("/api/rules").json() == []
        assert "no candidate 1" in one_line_error(client.get("/api/candidates/1"), 404)
        one_line_error(client.get(f"/api/candidates/{2**70}"), 404)
        one_line_error(client.post("/api/candidates/1/check", json={"axiom": DRAFT}), 404)
    finally:
        ws.close()
