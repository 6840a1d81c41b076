"""The service and open-world scenes: ``strict_vocabulary`` on /v1/verify,
the open-world objects /v1/apply-answers names, and POST /v1/learn, which
keeps answers as candidate classes in the service's workspace; after a
reviewer accepts one on /review/, the next verification uses it."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from click.testing import Result
from fastapi.testclient import TestClient
from learn_support import ELECTRIC, HAIR_DRYER, HAIR_DRYER_PLAN

from virf.authoring.workspace import Workspace
from virf.service.app import create_app

BODY: dict[str, Any] = {"scene": HAIR_DRYER, "plan": HAIR_DRYER_PLAN}


@pytest.fixture(scope="module")
def client() -> TestClient:
    return TestClient(create_app(), base_url="http://127.0.0.1")  # no key: this machine only


def problem(response: Any, status: int) -> str:
    assert response.status_code == status, response.text
    data = response.json()
    assert set(data) == {"status", "error"} and "\n" not in data["error"]
    return str(data["error"])


def test_strict_vocabulary_refuses_what_the_open_world_reads(
    client: TestClient, cli: Callable[..., Result], tmp_path: Path
) -> None:
    assert client.post("/v1/verify", json=BODY).json()["status"] == "UNKNOWN"
    refused = problem(client.post("/v1/verify", json={**BODY, "strict_vocabulary": True}), 400)
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(HAIR_DRYER))
    plan = tmp_path / "plan.txt"
    plan.write_text("\n".join(HAIR_DRYER_PLAN))
    printed = cli("verify", scene, plan, "--strict-vocabulary", "--json")
    assert printed.exit_code == 2 and json.loads(printed.stdout)["error"] == refused
    assert refused.startswith("unknown class 'HairDryer'")
    assert "strict_vocabulary: Input should be a valid boolean" in problem(
        client.post("/v1/verify", json={**BODY, "strict_vocabulary": "yes"}), 400
    )


def test_apply_answers_names_the_open_world_objects(client: TestClient) -> None:
    got = client.post("/v1/apply-answers", json={**BODY, "answers": {ELECTRIC: "yes"}}).json()
    assert got["applied"] == [ELECTRIC] and got["open_world"] == {"HairDryer_1": "HairDryer"}


def test_learning_needs_a_workspace(client: TestClient) -> None:
    body = {**BODY, "answers": {ELECTRIC: "yes"}, "who": "alice"}
    assert "keeps no knowledge workspace" in problem(client.post("/v1/learn", json=body), 409)
    assert client.get("/v1/health").json()["learn"] is None


def test_learn_accept_and_the_next_verdict_uses_it(tmp_path: Path) -> None:
    kb = tmp_path / "kb"
    Workspace.init(kb, starter=False).close()
    local = TestClient(create_app(kb=kb, workspace=kb, reviewer="bob"), base_url="http://127.0.0.1")
    assert local.get("/v1/health").json()["learn"] == "/v1/learn"
    body = {**BODY, "answers": {ELECTRIC: "yes"}, "who": "alice"}
    for bad, words in (
        ({"who": " "}, "'who' must name who answered"),
        ({"answers": {ELECTRIC + "s": "yes"}}, f"closest asked: {ELECTRIC}"),
        ({"answers": {ELECTRIC: "maybe"}}, "'maybe' is not yes or no"),
        ({"whom": "alice"}, "unknown key 'whom'"),
    ):
        assert words in problem(local.post("/v1/learn", json={**body, **bad}), 400)
    assert local.get("/review/api/candidates").json() == []  # nothing half-stored

    got = local.post("/v1/learn", json=body)
    assert got.status_code == 200, got.text
    learned = got.json()
    assert (learned["status"], learned["applies_here"], learned["skipped"]) == ("UNSAFE", True, [])
    [candidate] = learned["candidates"]
    assert (candidate["class_name"], candidate["passed"], candidate["problems"]) == (
        "HairDryer",
        True,
        [],
    )
    assert candidate["axioms"][1] == "HairDryer SubClassOf hasProperty value ElectricallyPowered"
    assert candidate["changes"][0]["after"] == "UNSAFE (LiveDeviceBesideWaterDanger)"

    # Pending: the verdict has not changed.
    assert local.post("/v1/verify", json=BODY).json()["status"] == "UNKNOWN"
    view = local.get(f"/review/api/candidates/{candidate['id']}").json()
    assert view["summary"]["origin"] == "answer" and view["learned"]["who"] == "alice"
    decided = local.post(
        f"/review/api/candidates/{candidate['id']}/decision", json={"decision": "accept"}
    )
    assert decided.status_code == 200, decided.text
    after = local.post("/v1/verify", json=BODY).json()
    assert (after["status"], after["dangerous_step"], after["questions"]) == ("UNSAFE", 2, [])
