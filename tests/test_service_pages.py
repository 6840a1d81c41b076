"""The service's web page and the endpoints it needs, over FastAPI's TestClient:
the page and its assets, the bundled examples, the state at a step and
answers to questions, each with its one-line 4xx errors."""

from __future__ import annotations

import importlib.resources
import json
import re
from pathlib import Path
from typing import Any

import pytest
from conftest import EXAMPLES_DIR, load_expected
from fastapi import FastAPI
from fastapi.testclient import TestClient

import virf
from virf.bundled import bundled_examples
from virf.ontology.tbox import DEFAULT_SCENARIO
from virf.service.app import Tutors, create_app
from virf.service.pages import STATIC_DIR, add_pages

WALK = EXAMPLES_DIR / "walkthrough"
UNKNOWN = EXAMPLES_DIR / "unknown-material-microwave"


@pytest.fixture(scope="module")
def client() -> TestClient:
    return TestClient(create_app(), base_url="http://127.0.0.1")  # no key: this machine only


def case(folder: Path) -> dict[str, Any]:
    return {
        "scene": json.loads((folder / "scene.json").read_text()),
        "plan": (folder / "plan.txt").read_text(),
    }


def reproduced(folder: Path) -> dict[str, Any]:
    """The example's request on the scenario it reproduces (the paper's
    examples name ``"scenario": "paper"``), through the requests' own option."""
    scenario = load_expected(folder).get("scenario")
    return case(folder) if scenario is None else {**case(folder), "scenario": scenario}


def problem(response: Any, status: int) -> str:
    assert response.status_code == status, response.text
    error = response.json()
    assert error["status"] == "BAD_INPUT", error
    assert "\n" not in error["error"]
    message: str = error["error"]
    return message


# ----------------------------------------------------------------- the page
def test_the_page_and_its_assets_are_served(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    for testid in ("verify-button", "example-select", "trace", "graph", "rule-search"):
        assert f'data-testid="{testid}"' in page.text
    for asset in re.findall(r'(?:src|href)="(/assets/[^"]+)"', page.text):
        got = client.get(asset)
        assert got.status_code == 200, asset
        assert got.text == (STATIC_DIR / asset.removeprefix("/assets/")).read_text()
    assert client.get("/assets/nothing.js").status_code == 404


def test_the_page_loads_nothing_from_the_internet() -> None:
    for path in STATIC_DIR.iterdir():
        text = path.read_text(encoding="utf-8")
        # The SVG namespace is a name, not a download.
        outside = re.findall(
            r"(?:https?:)?//[\w.-]+\.\w+", text.replace("http://www.w3.org/2000/svg", "")
        )
        assert not outside, (path.name, outside)


def test_the_api_key_guards_the_new_endpoints_but_not_the_page() -> None:
    keyed = TestClient(create_app(api_key="s3cret-key"))
    assert keyed.get("/").status_code == 200
    assert keyed.get("/assets/page.js").status_code == 200
    assert keyed.get("/v1/examples").status_code == 401
    assert keyed.post("/v1/state", json={**case(WALK), "step": 0}).status_code == 401
    answers = {**case(UNKNOWN), "answers": {"material:Bowl_1": "Glass"}}
    assert keyed.post("/v1/apply-answers", json=answers).status_code == 401
    ok = keyed.get("/v1/examples", headers={"x-api-key": "s3cret-key"})
    assert ok.status_code == 200 and ok.json()


# ----------------------------------------------------------------- examples
def test_the_examples_are_listed_with_their_descriptions(client: TestClient) -> None:
    listed = client.get("/v1/examples").json()
    names = [e["name"] for e in listed]
    assert "walkthrough" in names and "unknown-material-microwave" in names
    assert names == sorted(names)
    # Only folders with a scene and a plan: the replay and corpus folders are not examples.
    assert "agents" not in names and "knowledge-acquisition" not in names
    walk = next(e for e in listed if e["name"] == "walkthrough")
    assert walk["description"] == json.loads((WALK / "scene.json").read_text())["description"]


def test_an_example_is_its_files(client: TestClient) -> None:
    got = client.get("/v1/examples/walkthrough").json()
    assert got["scene"] == json.loads((WALK / "scene.json").read_text())
    assert got["plan"] == (WALK / "plan.txt").read_text()
    # ... and verifying it is verifying the files.
    report = client.post("/v1/verify", json={"scene": got["scene"], "plan": got["plan"]}).json()
    assert (report["status"], report["dangerous_step"]) == ("UNSAFE", 7)


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("walkthru", "no example 'walkthru'; choose from walkthrough"),
        ("agents", "no example 'agents'"),
        ("Walkthrough", "no example 'Walkthrough'; choose from walkthrough"),
    ],
)
def test_an_unknown_example_is_a_one_line_404(client: TestClient, name: str, message: str) -> None:
    assert message in problem(client.get(f"/v1/examples/{name}"), 404)


def test_without_an_examples_folder_the_list_is_empty(tmp_path: Path) -> None:
    app = FastAPI()
    add_pages(app, Tutors(DEFAULT_SCENARIO, "fast", None, 120.0), examples=tmp_path / "none")
    bare = TestClient(app)
    assert bare.get("/v1/examples").json() == []
    assert "this server has none" in problem(bare.get("/v1/examples/walkthrough"), 404)


def test_the_examples_folder_is_the_checkouts_or_the_installed_copy(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    assert bundled_examples() == EXAMPLES_DIR
    # An installed package: site-packages/virf has no checkout around it...
    package = tmp_path / "lib" / "site-packages" / "virf"
    package.mkdir(parents=True)
    (tmp_path / "lib" / "examples").mkdir()  # a stray folder without a project around it
    monkeypatch.setattr(virf, "__file__", str(package / "__init__.py"))
    monkeypatch.setattr(importlib.resources, "files", lambda _: package)
    assert bundled_examples() is None
    # ... and its examples are the copy the wheel put inside the package.
    (package / "examples").mkdir()
    assert bundled_examples() == package / "examples"


# ----------------------------------------------------------------- /v1/state
def test_the_state_at_the_dangerous_step_holds_its_triggering_facts(client: TestClient) -> None:
    report = client.post("/v1/verify", json=reproduced(WALK)).json()
    state = client.post("/v1/state", json={**reproduced(WALK), "step": 7}).json()
    assert (state["step"], state["states"], state["action"]) == (7, 8, None)
    triples = {(f["subject"], f["predicate"], f["object"]) for f in state["facts"]}
    [lead] = [v for v in report["violations"] if v["id"] == "UnsafeMicrowaveUsage"]
    for fact in lead["triggering_facts"]:
        assert (fact["subject"], fact["predicate"], fact["object"]) in triples
    kinds = {f["kind"] for f in state["facts"]}
    assert kinds <= {"type", "object", "data", "closure"} and "closure" in kinds
    assumed = [f for f in state["facts"] if f["provenance"] == "assumed"]
    assert {"subject": "TestPot_Action", "predicate": "hasState", "object": "UnknownFillState",
            "kind": "object", "provenance": "assumed"} in assumed  # fmt: skip


def test_a_state_before_an_action_carries_the_action(client: TestClient) -> None:
    state = client.post("/v1/state", json={**case(WALK), "step": 6}).json()
    report = client.post("/v1/verify", json=case(WALK)).json()
    assert state["action"] == report["plan"][6] == "turn_on(TestMicrowave_Action)"
    facts = {(f["subject"], f["predicate"], f["object"]) for f in state["facts"]}
    assert ("Step7_turn_on", "hasTarget", "TestMicrowave_Action") in facts
    assert ("TestMicrowave_Action", "hasState", "OnState") not in facts
    initial = client.post("/v1/state", json={**case(WALK), "step": 0}).json()
    assert ("TestCountertop_Action", "supports", "TestPot_Action") in {
        (f["subject"], f["predicate"], f["object"]) for f in initial["facts"]
    }


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"step": 8}, "step 8: the simulation has states 0 to 7"),
        ({"step": -1}, "step -1: the simulation has states 0 to 7"),
        ({"step": "7"}, "step: Input should be a valid integer"),
        ({"step": None}, "step"),
        ({"plan": "\n# nothing\n"}, "plan has no actions"),
        ({"plan": "fly Pot"}, "unknown action 'fly'"),
        ({"scene": {"instances": 3}}, "instances"),
        ({"colour": "red"}, "unknown key 'colour'; expected scene, plan, step, scenario, engine"),
        ({"engine": "magic"}, "magic"),
    ],
)
def test_bad_state_requests_are_one_line_400s(
    client: TestClient, change: dict[str, Any], message: str
) -> None:
    body = {**case(WALK), "step": 7, **change}
    assert message in problem(client.post("/v1/state", json=body), 400)


def test_a_state_request_needs_its_step(client: TestClient) -> None:
    assert "needs 'step'" in problem(client.post("/v1/state", json=case(WALK)), 400)


# ----------------------------------------------------------------- /v1/apply-answers
def test_answers_update_the_scene_and_change_the_verdict(client: TestClient) -> None:
    # The paper's USC-Uncertainty example on the paper's rules (the household
    # rules also find the answered bowl of liquid left heating at the plan's end).
    paper = reproduced(UNKNOWN)
    assert paper["scenario"] == "paper"
    before = client.post("/v1/verify", json=paper).json()
    assert before["status"] == "UNKNOWN"
    got = client.post(
        "/v1/apply-answers",
        json={**paper, "answers": {"material:Bowl_1": "glass", "fill:Bowl_1": "yes"}},
    ).json()
    assert got["applied"] == ["material:Bowl_1", "fill:Bowl_1"]
    assert set(got["unsettled"]) == {"contents:contains:Bowl_1", "contents:contains:Microwave_1"}
    said = {(a["subject"], a["property"], a["object"]) for a in got["scene"]["assertions"]}
    assert ("Bowl_1", "hasMaterial", "Glass") in said
    assert ("Bowl_1", "hasMaterial", "UnknownMaterial") not in said
    after = client.post("/v1/verify", json={**paper, "scene": got["scene"]}).json()
    assert after["status"] == "SAFE", after["reason"]

    metal = client.post(
        "/v1/apply-answers", json={**paper, "answers": {"material:Bowl_1": "Metal"}}
    ).json()
    again = client.post("/v1/verify", json={**paper, "scene": metal["scene"]}).json()
    assert again["status"] == "UNSAFE"


def test_an_answer_that_leaves_a_question_open_settles_nothing(client: TestClient) -> None:
    got = client.post(
        "/v1/apply-answers", json={**case(UNKNOWN), "answers": {"material:Bowl_1": "don't know"}}
    ).json()
    assert got["applied"] == [] and "material:Bowl_1" in got["unsettled"]
    assert got["scene"] == case(UNKNOWN)["scene"]


@pytest.mark.parametrize(
    ("answers", "message"),
    [
        ({"material:Bowl_1": "Glas"}, "unknown material 'Glas'; choose from Glass"),
        ({"fill:Bowl_1": "maybe"}, "'maybe' is not yes or no"),
        ({"material:Bowl1": "Glass"}, "no question 'material:Bowl1' for this scene and plan"),
        ({"material:Bowl_1": 3}, "answers.material:Bowl_1"),
        ([], "answers"),
    ],
)
def test_bad_answers_are_one_line_400s(client: TestClient, answers: Any, message: str) -> None:
    body = {**case(UNKNOWN), "answers": answers}
    assert message in problem(client.post("/v1/apply-answers", json=body), 400)


def test_a_plan_without_questions_accepts_no_answers(client: TestClient) -> None:
    safe = EXAMPLES_DIR / "safe-fridge"
    body = {**case(safe), "answers": {"fill:Bowl_1": "yes"}}
    assert "none is open" in problem(client.post("/v1/apply-answers", json=body), 400)
