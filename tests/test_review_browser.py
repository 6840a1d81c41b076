"""The review page in a real headless Chromium (Debian's, driven by Playwright).

One test walks the page over the in-memory workspace of the API tests (the
page's own behaviour: evidence flags, stale checks, refusals, the banner);
the other drives the real workspace end to end, from a person's proposal to
the rule listed by ``virf kb rules --kb DIR``."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from browser_support import chromium, needs_browser
from browser_support import page_at as browser_page
from browser_support import serving as serve_app
from browser_support import shot as save_shot

from virf.authoring.review import ReviewWorkspace, create_app

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page

pytestmark = needs_browser
SHOTS = Path("/tmp/virf-review-screens")

STEP_MS = 60_000


@contextmanager
def serving(workspace: ReviewWorkspace, reviewer: str) -> Iterator[str]:
    """The review server on a free loopback port, in a thread; yields its address."""
    with serve_app(create_app(workspace, reviewer)) as url:
        yield url


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with chromium() as launched:
        yield launched


@contextmanager
def page_at(browser: Browser, url: str) -> Iterator[Page]:
    with browser_page(browser, url, timeout_ms=STEP_MS) as page:
        yield page


def shot(page: Page, name: str) -> Path:
    return save_shot(page, SHOTS, name)


def test_the_page_over_a_stand_in_workspace(browser: Browser) -> None:
    from playwright.sync_api import expect
    from review_support import sample_workspace

    ws = sample_workspace()
    with serving(ws, "ana") as url, page_at(browser, url) as page:
        queue = page.get_by_test_id("queue")
        # Pending only by default; the first is opened.
        expect(queue.locator(".queue-item")).to_have_count(2)
        expect(page.get_by_test_id("rule-name")).to_have_text("PaperTowelOnBurnerDanger")
        expect(page.get_by_test_id("rule-safety-warning")).to_contain_text("Keep paper")

        # "all" shows the rejected one too, after the pending ones.
        page.get_by_test_id("filter-all").check()
        expect(queue.locator(".queue-item")).to_have_count(3)
        assert queue.locator(".queue-item").last.get_attribute("data-status") == "rejected"

        # Keyboard: down from the first opens the second, whose second passage is gone.
        page.get_by_test_id("queue-item-1").focus()
        page.keyboard.press("ArrowDown")
        expect(page.get_by_test_id("rule-name")).to_have_text("CurtainNearBurnerDanger")
        missing = page.get_by_test_id("evidence-missing")
        expect(missing).to_contain_text("gone#1")
        expect(missing).to_have_css("color", "rgb(179, 38, 30)")
        expect(page.get_by_test_id("evidence-item")).to_contain_text("Keep anything")
        assert ("opened", 2, "ana") in ws.calls

        # An edit that fails its check: the result shows, and accepting it is off.
        axiom = page.get_by_test_id("axiom")
        axiom.fill("Broken and (supports some Curtain)")
        expect(page.get_by_test_id("check-summary")).to_have_class("check-summary stale")
        page.get_by_test_id("check").click()
        expect(page.get_by_test_id("check-summary")).to_contain_text("A check failed")
        expect(page.locator("[data-testid=check-item][data-ok=false]")).to_contain_text(
            "unsatisfiable"
        )
        expect(page.get_by_test_id("related")).to_contain_text("FlammableOnLitBurnerDanger")
        expect(page.get_by_test_id("terms").locator("tbody tr")).to_have_count(2)
        expect(page.get_by_test_id("terms")).to_contain_text("FlammableObject / domain")
        expect(page.get_by_test_id("accept-edited")).to_be_disabled()

        # The effect preview lists the changed verdicts.
        page.get_by_test_id("preview").click()
        expect(page.get_by_test_id("preview-change")).to_contain_text("SAFE → UNSAFE")
        assert ws.calls[-1] == ("preview", 2, "Broken and (supports some Curtain)")

        # Rejecting without a reason is refused on the page, with the API untouched.
        page.get_by_test_id("reject").click()
        expect(page.get_by_test_id("error-banner")).to_be_visible()
        expect(page.get_by_test_id("error-text")).to_contain_text("needs a reason")
        assert not any(call[0] == "decide" for call in ws.calls)

        page.get_by_test_id("reason").fill("curtains are covered by the general rule")
        page.get_by_test_id("reject").click()
        expect(page.get_by_test_id("decision-text")).to_contain_text("Rejected by ana")
        expect(page.get_by_test_id("error-banner")).to_be_hidden()
        expect(page.get_by_test_id("queue-item-2")).to_have_attribute("data-status", "rejected")
        expect(page.get_by_test_id("decide")).to_be_hidden()
        shot(page, "stand-in-after-reject")

        # An API error reaches the banner: the server's one line, verbatim.
        page.get_by_test_id("queue-item-1").click()
        expect(page.get_by_test_id("rule-name")).to_have_text("PaperTowelOnBurnerDanger")
        axiom.fill("NoJava and Thing")
        page.get_by_test_id("check").click()
        expect(page.get_by_test_id("error-text")).to_have_text(
            "Java is not installed; install a Java 11+ runtime"
        )


PASSAGE = "nfpa-cooking-safety:around-the-stove-flammables-clothing-and-children:1"
DRAFTED = "StoveBurner and (hasState some OnState) and (supports some Towl)"
EDITED = "StoveBurner and (hasState some OnState) and (supports some Towel)"


def test_review_over_the_real_workspace(browser: Browser, tmp_path: Path) -> None:
    """A person's proposal, opened, edited, checked and accepted on the page,
    ends up among the rules ``virf kb rules --kb DIR`` lists."""
    import json

    from playwright.sync_api import expect
    from typer.testing import CliRunner

    from virf.authoring.workspace import Workspace
    from virf.cli.main import app

    root = tmp_path / "kb"
    ws = Workspace.init(root, "paper")
    proposal = tmp_path / "proposal.json"
    rule = {
        "equivalentClass": "TowelOnLitBurnerDanger",
        # A misspelt class, for the reviewer to fix.
        "definition": DRAFTED,
        "category": "Fire Hazard",
        "dangerLevel": "high",
        "description": "A towel lying on a burner that is on can catch fire.",
        "safetyWarning": "Do not leave a towel on a lit burner.",
        "triggerReason": "A towel is on a burner that is switched on.",
        "suggestion": "Move the towel off the burner before switching it on.",
        "evidence": [PASSAGE],
    }
    proposal.write_text(json.dumps({"propertyChains": [rule]}), encoding="utf-8")
    [cid] = ws.propose(proposal, "ana", check=False)

    with serving(ws, "bo") as url, page_at(browser, url) as page:
        item = page.get_by_test_id(f"queue-item-{cid}")
        expect(item).to_have_attribute("data-status", "pending")
        item.click()
        expect(page.get_by_test_id("rule-name")).to_have_text("TowelOnLitBurnerDanger")
        expect(page.get_by_test_id("evidence-item")).to_contain_text("potholders")
        expect(page.get_by_test_id("evidence-item")).to_contain_text("NFPA")

        axiom = page.get_by_test_id("axiom")
        expect(axiom).to_have_value(DRAFTED)
        axiom.fill(EDITED)
        page.get_by_test_id("check").click()
        # The page may still show the check of the draft (Towl passes too, as a
        # new class): wait for the edited axiom's terms, not only for "pass".
        terms = page.get_by_test_id("terms")
        expect(terms).to_contain_text("Towel", timeout=STEP_MS)
        expect(terms).not_to_contain_text("Towl")
        expect(page.get_by_test_id("check-summary")).to_have_class("check-summary pass")
        shot(page, "real-after-check")

        page.get_by_test_id("accept-edited").click()
        expect(page.get_by_test_id("decision-text")).to_contain_text("Accepted", timeout=STEP_MS)
        expect(page.get_by_test_id("decision-text")).to_contain_text("by bo")
        expect(page.get_by_test_id("candidate-status")).to_have_text("accepted")
        row = page.locator("[data-testid=rule-row][data-name=TowelOnLitBurnerDanger]")
        expect(row).to_contain_text(EDITED)
        expect(row).to_contain_text(PASSAGE)
        expect(row.locator("td").nth(7)).to_have_text("bo")
        # The queue (pending only) no longer holds it.
        expect(page.get_by_test_id(f"queue-item-{cid}")).to_have_count(0)
        shot(page, "real-after-accept")

    listed = CliRunner().invoke(app, ["kb", "rules", "--kb", str(root)])
    assert listed.exit_code == 0, listed.output
    assert "TowelOnLitBurnerDanger" in listed.output
    listed_rule = listed.output.split("TowelOnLitBurnerDanger", 1)[1]
    assert "supports some Towel)" in listed_rule.splitlines()[1], listed.output
    # ... and verification with the workspace uses it: with only the new rule
    # checked, a towel on a burner that gets switched on is UNSAFE.
    from virf.api import LogicTutor

    tutor = LogicTutor(kb=root, explain=False).restricted(["TowelOnLitBurnerDanger"])
    scene = {
        "instances": [
            {"class_name": "StoveBurner", "instance_name": "StoveBurner_1"},
            {"class_name": "StoveKnob", "instance_name": "StoveKnob_1"},
            {"class_name": "Towel", "instance_name": "Towel_1"},
        ],
        "assertions": [
            {"subject": "StoveKnob_1", "property": "controls", "object": "StoveBurner_1"},
            {"subject": "StoveKnob_1", "property": "hasState", "object": "OffState"},
            {"subject": "StoveBurner_1", "property": "hasState", "object": "OffState"},
            {"subject": "Towel_1", "property": "isOn", "object": "StoveBurner_1"},
        ],
    }
    report = tutor.verify(scene, ["find StoveKnob", "turn_on StoveKnob"])
    assert report.status == "UNSAFE", report.reason
    assert [v.id for v in report.violations] == ["TowelOnLitBurnerDanger"]


def test_only_web_addresses_become_links(browser: Browser) -> None:
    """A document's url that is not http(s) (``javascript:`` would run in
    the page when clicked, were it not for the CSP) is shown as text."""
    from playwright.sync_api import expect
    from review_support import FakeWorkspace, found

    ws = FakeWorkspace()
    hostile = ("javascript:alert(document.domain)", "data:text/html,hi", "//evil.example/x")
    evidence = tuple(
        found(f"nfpa-cooking-safety#{n}").model_copy(update={"url": url})
        for n, url in enumerate((*hostile, "https://www.nfpa.org/cooking"), start=1)
    )
    ws.add("PaperTowelOnBurnerDanger", evidence=evidence)
    with serving(ws, "ana") as url, page_at(browser, url) as page:
        items = page.get_by_test_id("evidence-item")
        expect(items).to_have_count(4)
        for n in range(3):
            expect(items.nth(n)).to_contain_text("Cooking safety")
            expect(items.nth(n).locator("a")).to_have_count(0)
        link = items.nth(3).locator("a")
        expect(link).to_have_attribute("href", "https://www.nfpa.org/cooking")
        expect(link).to_have_text("Cooking safety")
