"""The learn loop in a real headless Chromium (Debian's, driven by
Playwright) against a real uvicorn server: verify a scene with an object the
knowledge base does not know, read the question in plain words, answer it,
remember the answer, accept the learned class on the review page, verify the
same scene again and see the new verdict, without a question."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from browser_support import chromium, needs_browser, page_at, serving, shot
from learn_support import HAIR_DRYER, HAIR_DRYER_PLAN

from virf.authoring.workspace import Workspace
from virf.service.app import create_app

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page

pytestmark = needs_browser
SHOTS = Path("/tmp/virf-learn-screens")
STEP_MS = 30_000
# Learning checks the class with HermiT and previews its effect; accepting
# checks it again and the next verification compiles the knowledge base.
SLOW_MS = 180_000


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with chromium() as launched:
        yield launched


def verify_scene(page: Page) -> None:
    page.get_by_test_id("scene-input").fill(json.dumps(HAIR_DRYER, indent=2))
    page.get_by_test_id("plan-input").fill("\n".join(HAIR_DRYER_PLAN))
    page.get_by_test_id("verify-button").click()


def test_answer_remember_accept_and_the_next_verdict(browser: Browser, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    kb = tmp_path / "kb"
    Workspace.init(kb, starter=False).close()
    with (
        serving(create_app(kb=kb, workspace=kb, reviewer="bob")) as address,
        page_at(browser, address, timeout_ms=STEP_MS, width=1400, height=1000) as page,
    ):
        verify_scene(page)
        verdict = page.get_by_test_id("verdict")
        expect(verdict).to_have_text("UNKNOWN", timeout=STEP_MS)
        # The open-world object, and its question, in plain words.
        expect(page.get_by_test_id("note")).to_contain_text(
            "HairDryer_1: 'HairDryer' is not a class of the knowledge base"
        )
        question = page.get_by_test_id("question")
        expect(question).to_have_count(1)
        expect(question).to_contain_text("Is HairDryer_1 an electrical appliance?")
        expect(page.get_by_test_id("learn-box")).to_be_hidden()
        shot(page, SHOTS, "open-world-question")

        page.get_by_test_id("answer").select_option("yes")
        page.get_by_test_id("answer-button").click()
        expect(verdict).to_have_text("UNSAFE", timeout=STEP_MS)
        box = page.get_by_test_id("learn-box")
        expect(box).to_be_visible()
        expect(page.get_by_test_id("learn-text")).to_contain_text("HairDryer_1 (a 'HairDryer')")

        # Remembering needs a name: it is kept with the answers.
        page.get_by_test_id("learn-button").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("say who you are")
        page.get_by_test_id("learn-who").fill("alice")
        page.get_by_test_id("learn-button").click()
        result = page.get_by_test_id("learn-result")
        expect(result).to_contain_text("Sent for review:", timeout=SLOW_MS)
        learned = page.get_by_test_id("learned-candidate")
        expect(learned).to_contain_text("#1 HairDryer")
        expect(learned).to_contain_text(
            "HairDryer SubClassOf hasProperty value ElectricallyPowered"
        )
        expect(learned).to_contain_text("its checks pass")
        expect(page.get_by_test_id("learn-button")).to_be_disabled()
        shot(page, SHOTS, "remembered")

        # The reviewer accepts it on the review page.
        page.get_by_test_id("learn-review-link").click()
        page.wait_for_selector("body[data-ready=true]")
        item = page.get_by_test_id("queue-item-1")
        expect(page.get_by_test_id("rule-name")).to_have_text("HairDryer", timeout=STEP_MS)
        expect(item.get_by_test_id("learned-badge")).to_have_text("learned from an answer")
        expect(page.get_by_test_id("rule-name")).to_have_text("HairDryer")
        expect(page.locator("#rule-heading")).to_have_text("Learned class")
        expect(page.get_by_test_id("learned-learned-from")).to_contain_text("answers by alice")
        answer = page.get_by_test_id("learned-answer")
        expect(answer).to_contain_text("Is HairDryer_1 an electrical appliance?")
        expect(answer.get_by_test_id("learned-answer-value")).to_have_text("yes")
        expect(page.get_by_test_id("check-summary")).to_contain_text("All checks pass")
        expect(
            page.get_by_test_id("preview-change").filter(has_text="(learned from)")
        ).to_contain_text(
            "UNKNOWN (LiveDeviceBesideWaterDanger) → UNSAFE (LiveDeviceBesideWaterDanger)"
        )
        expect(page.get_by_test_id("preview-kb-test")).to_contain_text("virf kb test")
        shot(page, SHOTS, "review-learned")
        page.get_by_test_id("accept").click()
        expect(page.get_by_test_id("notice")).to_have_text(
            "Candidate #1 accepted.", timeout=SLOW_MS
        )
        expect(page.locator("[data-testid=rule-row][data-name=HairDryer]")).to_be_visible()

        # The same scene, as it was before the answer: UNSAFE, nothing asked.
        page.goto(address)
        page.wait_for_selector("body[data-ready=true]")
        verify_scene(page)
        expect(verdict).to_have_text("UNSAFE", timeout=SLOW_MS)
        expect(page.get_by_test_id("question")).to_have_count(0)
        expect(page.get_by_test_id("notes")).to_be_hidden()
        dangerous = page.locator("[data-testid=trace-step][data-dangerous=true]")
        expect(dangerous).to_have_attribute("data-step", "2")
        expect(page.get_by_test_id("background-axiom").filter(has_text="HairDryer")).to_have_count(
            2
        )
        expect(
            page.get_by_test_id("background-axiom").filter(
                has_text=re.compile("LEARNED-HairDryer-property-ElectricallyPowered")
            )
        ).to_contain_text("answers by alice")
        shot(page, SHOTS, "next-verdict")
