"""The service's page in a real headless Chromium (Debian's, driven by
Playwright), against a real uvicorn server on the loopback interface:
verify the walkthrough and see step 7 and its facts highlighted, answer an
UNKNOWN's questions and see the verdict change, browse and search the rules,
and see API errors in the banner."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from browser_support import chromium, needs_browser, serving
from browser_support import page_at as browser_page
from browser_support import shot as save_shot
from conftest import EXAMPLES_DIR

from virf.service.app import create_app

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page

pytestmark = needs_browser
SHOTS = Path("/tmp/virf-service-screens")

# Generous: a slow machine under load, not a latency requirement.
STEP_MS = 30_000
HIGHLIGHT = "rgb(214, 51, 108)"


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with chromium() as launched:
        yield launched


DIALOGUE_REPLAY = f"replay:{EXAMPLES_DIR / 'dialogue' / 'replay.jsonl'}"
# The plan of the paper's USC-Uncertainty example, as a recorded model reply.
UNCERTAIN = EXAMPLES_DIR / "unknown-material-microwave"


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    """A server whose runs may name the dialogue example's replay (and no other)."""
    with serving(create_app(planners=[DIALOGUE_REPLAY])) as address:
        yield address


@pytest.fixture(scope="module")
def uncertain_replay(tmp_path_factory: pytest.TempPathFactory) -> Path:
    plan = json.loads((UNCERTAIN / "plan.txt").read_text())
    replay = tmp_path_factory.mktemp("replay") / "replay.jsonl"
    replay.write_text(json.dumps({"task_id": "q", "iteration": 0, "text": "\n".join(plan)}) + "\n")
    return replay


@pytest.fixture(scope="module")
def paper_url(uncertain_replay: Path) -> Iterator[str]:
    """A server on the paper's rules (scenario ``paper``): the page verifies on
    the server's scenario, and the paper's examples reproduce the paper there."""
    with serving(create_app(scenario="paper", planners=[f"replay:{uncertain_replay}"])) as address:
        yield address


@contextmanager
def page_at(browser: Browser, url: str) -> Iterator[Page]:
    with browser_page(browser, url, timeout_ms=STEP_MS, width=1400, height=1000) as page:
        yield page


def shot(page: Page, name: str) -> Path:
    return save_shot(page, SHOTS, name)


def load_example(page: Page, name: str) -> None:
    from playwright.sync_api import expect

    page.get_by_test_id("example-select").select_option(name)
    # Loaded: the label names the example the boxes now hold.
    expect(page.get_by_test_id("example-description")).to_have_attribute("data-state", "example")
    expect(page.get_by_test_id("example-select")).to_have_value(name)
    expect(page.get_by_test_id("plan-input")).not_to_have_value("")
    page.get_by_test_id("verify-button").click()


def test_the_walkthrough_is_unsafe_at_step_7_with_its_facts_drawn(
    browser: Browser, paper_url: str
) -> None:
    from playwright.sync_api import expect

    with page_at(browser, paper_url) as page:
        expect(page.get_by_test_id("health")).to_contain_text("ready")
        load_example(page, "walkthrough")
        expect(page.get_by_test_id("scene-input")).to_have_value(re.compile("TestMicrowave_Action"))
        verdict = page.get_by_test_id("verdict")
        expect(verdict).to_have_text("UNSAFE")
        expect(verdict).to_have_css("color", "rgb(179, 38, 30)")
        expect(page.get_by_test_id("reason")).to_contain_text("step 7")

        # Step 7, and only step 7, is highlighted in the trace.
        rows = page.get_by_test_id("trace-step")
        expect(rows).to_have_count(8)  # the scene before the plan, and seven actions
        dangerous = page.locator("[data-testid=trace-step][data-dangerous=true]")
        expect(dangerous).to_have_count(1)
        expect(dangerous).to_have_attribute("data-step", "7")
        expect(dangerous).to_contain_text("turn_on(TestMicrowave_Action)")
        expect(dangerous).to_have_css("background-color", "rgb(253, 236, 234)")
        expect(page.locator("[data-testid=trace-step][data-step='3']")).to_have_css(
            "background-color", "rgba(0, 0, 0, 0)"
        )

        # The violation: its rule, category, danger level, facts, background, suggestion.
        usage = page.locator("[data-testid=violation][data-id=UnsafeMicrowaveUsage]")
        expect(usage.get_by_test_id("violation-category")).to_have_text("Fire Hazard")
        expect(usage.get_by_test_id("violation-danger")).to_have_text("danger: high")
        expect(usage.get_by_test_id("trigger-fact")).to_have_count(4)
        expect(usage.get_by_test_id("trigger-fact").first).to_have_text(
            "TestMicrowave_Action contains TestPot_Action"
        )
        expect(usage.get_by_test_id("background-axiom")).to_contain_text(
            "Pot SubClassOf hasMaterial value Metal"
        )
        expect(page.get_by_test_id("suggestion")).to_contain_text("microwave-safe")

        # The graph of state 7: the triggering relation and objects stand out.
        expect(page.get_by_test_id("graph-caption")).to_have_attribute("data-step", "7")
        edge = page.locator(
            "[data-testid=graph-edge][data-fact='TestMicrowave_Action contains TestPot_Action']"
        )
        expect(edge).to_have_attribute("data-highlighted", "true")
        expect(edge.locator("line")).to_have_css("stroke", HIGHLIGHT)
        micro = page.locator("[data-testid=graph-node][data-name=TestMicrowave_Action]")
        expect(micro).to_have_attribute("data-highlighted", "true")
        expect(micro.locator("text.hl", has_text="hasState OnState")).to_have_count(1)
        expect(
            page.locator("[data-testid=graph-node][data-name=TestKnife_Action]")
        ).to_have_attribute("data-highlighted", "false")
        # By default every finding of step 7 is lit, the possible one's open-world facts too ...
        pot_closed = page.locator(
            "[data-testid=graph-node][data-name=TestPot_Action] text", has_text="contains only {}"
        )
        expect(pot_closed).to_have_attribute("data-highlighted", "true")
        shot(page, "walkthrough-unsafe")
        # ... a click on one violation lights its facts alone.
        usage.get_by_test_id("violation-message").click()
        expect(usage).to_have_class(re.compile("selected"))
        expect(pot_closed).to_have_attribute("data-highlighted", "false")
        expect(edge).to_have_attribute("data-highlighted", "true")
        expect(page.get_by_test_id("graph-caption")).to_contain_text(
            "highlighted: the facts of UnsafeMicrowaveUsage"
        )

        # Another step's state: drawn, nothing highlighted; step 7 again brings it back.
        page.locator("[data-testid=trace-step][data-step='2']").click()
        expect(page.get_by_test_id("graph-caption")).to_have_attribute("data-step", "2")
        expect(page.locator("[data-testid=graph-edge][data-highlighted=true]")).to_have_count(0)
        expect(page.locator("[data-testid=graph-node][data-name=Robot_1]")).to_be_visible()
        dangerous.click()
        expect(page.get_by_test_id("graph-caption")).to_have_attribute("data-step", "7")
        expect(edge).to_have_attribute("data-highlighted", "true")

        # The violation's rule opens in the rules tab.
        usage.get_by_test_id("open-rule").click()
        expect(page.get_by_test_id("panel-rules")).to_be_visible()
        expect(page.get_by_test_id("rule-name")).to_have_text("UnsafeMicrowaveUsage")


def test_answering_an_unknowns_questions_changes_the_verdict(
    browser: Browser, paper_url: str
) -> None:
    # The paper's USC-Uncertainty example (the household rules also find the
    # answered bowl of liquid left heating at the plan's end).
    from playwright.sync_api import expect

    with page_at(browser, paper_url) as page:
        load_example(page, "unknown-material-microwave")
        expect(page.get_by_test_id("verdict")).to_have_text("UNKNOWN")
        expect(page.get_by_test_id("verdict")).to_have_attribute("data-status", "UNKNOWN")
        expect(page.get_by_test_id("question")).to_have_count(4)
        material = page.locator("[data-testid=answer][data-key='material:Bowl_1']")
        expect(material.locator("option", has_text="Glass")).to_have_count(1)
        # The possible findings' facts are drawn at step 7, the assumed fill state in amber.
        bowl = page.locator("[data-testid=graph-node][data-name=Bowl_1]")
        expect(bowl).to_have_attribute("data-highlighted", "true")
        shot(page, "unknown-questions")

        material.select_option("Glass")
        page.locator("[data-testid=answer][data-key='fill:Bowl_1']").select_option("yes")
        page.get_by_test_id("answer-button").click()
        expect(page.get_by_test_id("verdict")).to_have_text("SAFE")
        expect(page.get_by_test_id("verdict")).to_have_css("color", "rgb(30, 123, 52)")
        # The notice names the questions as the report asked them, never by key.
        notice = page.get_by_test_id("answers-notice")
        expect(notice.get_by_test_id("settled-question")).to_have_text(
            ["What material is Bowl_1 made of? Glass", "Does Bowl_1 hold any liquid? yes"]
        )
        expect(notice.get_by_test_id("unsettled-question")).to_have_count(2)
        expect(notice.get_by_test_id("unsettled-question").first).to_have_text(
            re.compile(r"^Is it true that nothing is in Bowl_1\?")
        )
        expect(notice).not_to_contain_text(re.compile(r"(material|fill|contents):"))
        expect(page.get_by_test_id("scene-input")).to_have_value(re.compile('"object": "Glass"'))
        expect(page.get_by_test_id("questions")).to_be_hidden()
        expect(page.get_by_test_id("no-violations")).to_be_visible()
        expect(page.locator("[data-testid=trace-step][data-dangerous=true]")).to_have_count(0)
        shot(page, "unknown-answered-safe")


def test_errors_reach_the_banner(browser: Browser, url: str) -> None:
    from playwright.sync_api import expect

    with page_at(browser, url) as page:
        load_example(page, "walkthrough")
        expect(page.get_by_test_id("verdict")).to_have_text("UNSAFE")
        page.get_by_test_id("plan-input").fill("find Pot\nfly Pot\n")
        page.get_by_test_id("verify-button").click()
        banner = page.get_by_test_id("error-banner")
        expect(banner).to_be_visible()
        expect(page.get_by_test_id("error-text")).to_contain_text("unknown action 'fly'")
        page.get_by_test_id("scene-input").fill("{not json")
        page.get_by_test_id("verify-button").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("the scene is not valid JSON")
        page.get_by_test_id("error-close").click()
        expect(banner).to_be_hidden()

        # An answer the server refuses: its one line, verbatim.
        load_example(page, "unknown-material-microwave")
        expect(page.get_by_test_id("verdict")).to_have_text("UNKNOWN")
        page.get_by_test_id("answer-button").click()
        expect(page.get_by_test_id("error-text")).to_have_text(
            "answer at least one question (the others may stay open)"
        )


def test_a_failed_verify_greys_the_result_it_leaves_behind(browser: Browser, url: str) -> None:
    from playwright.sync_api import expect

    with page_at(browser, url) as page:
        load_example(page, "walkthrough")
        result = page.get_by_test_id("result")
        expect(page.get_by_test_id("verdict")).to_have_text("UNSAFE")
        expect(result).to_have_attribute("data-stale", "false")
        expect(page.get_by_test_id("stale-notice")).to_be_hidden()

        # Refused by the server, then by the page itself: either way the
        # verdict on show is not the answer to the boxes, and says so.
        for plan, scene, error in (
            ("find Pot\nfly Pot\n", None, "unknown action 'fly'"),
            # The browser's JSON.parse keeps the later of two keys; the server
            # refuses the scene as the CLI refuses the file.
            ("find Pot\n", '{"instances": [], "instances": []}', "duplicate key 'instances'"),
            ("find Pot\n", "{not json", "the scene is not valid JSON"),
            ("", None, "paste or upload a plan first"),
        ):
            page.get_by_test_id("plan-input").fill(plan)
            if scene is not None:
                page.get_by_test_id("scene-input").fill(scene)
            page.get_by_test_id("verify-button").click()
            expect(page.get_by_test_id("error-text")).to_contain_text(error)
            expect(result).to_have_attribute("data-stale", "true")
            expect(page.get_by_test_id("stale-notice")).to_be_visible()
            expect(page.get_by_test_id("stale-notice")).to_contain_text("The last verify failed")
            expect(page.get_by_test_id("result-body")).to_have_css("opacity", "0.45")
            assert page.get_by_test_id("result-body").evaluate("body => body.inert")
        shot(page, "verify-failed-stale")

        # The next verify that succeeds is the result again.
        load_example(page, "safe-fridge")
        expect(page.get_by_test_id("verdict")).to_have_text("SAFE")
        expect(result).to_have_attribute("data-stale", "false")
        expect(page.get_by_test_id("stale-notice")).to_be_hidden()
        expect(page.get_by_test_id("error-banner")).to_be_hidden()
        expect(page.get_by_test_id("result-body")).to_have_css("opacity", "1")
        assert not page.get_by_test_id("result-body").evaluate("body => body.inert")


def test_the_example_label_follows_the_editor(browser: Browser, url: str) -> None:
    from playwright.sync_api import expect

    with page_at(browser, url) as page:
        select = page.get_by_test_id("example-select")
        label = page.get_by_test_id("example-description")
        plan = page.get_by_test_id("plan-input")
        load_example(page, "walkthrough")
        expect(select).to_have_value("walkthrough")
        expect(label).to_contain_text("Appendix E")
        original = plan.input_value()

        # An edit: the label no longer claims the boxes hold the example.
        plan.fill(original + "turn_off(TestMicrowave_Action)\n")
        expect(select).to_have_value("")
        expect(label).to_have_attribute("data-state", "edited")
        expect(label).to_have_text(
            "edited from the example walkthrough; choose it again to start over"
        )
        # Undone, it is the example again.
        plan.fill(original)
        expect(select).to_have_value("walkthrough")
        expect(label).to_contain_text("Appendix E")

        # Another example: the label follows.
        load_example(page, "unknown-material-microwave")
        expect(select).to_have_value("unknown-material-microwave")
        expect(label).to_have_attribute("data-state", "example")
        # Answers written into its scene make it the example no longer.
        expect(page.get_by_test_id("verdict")).to_have_text("UNKNOWN")
        page.locator("[data-testid=answer][data-key='material:Bowl_1']").select_option("Glass")
        page.get_by_test_id("answer-button").click()
        expect(page.get_by_test_id("answers-notice")).to_be_visible()
        expect(select).to_have_value("")
        expect(label).to_contain_text("edited from the example unknown-material-microwave")

        # An example the server does not have (a list older than the server):
        # its one line, and the label stays with what the boxes hold.
        select.evaluate("s => s.append(new Option('gone-example', 'gone-example'))")
        select.select_option("gone-example")
        expect(page.get_by_test_id("error-text")).to_contain_text("no example 'gone-example'")
        expect(select).to_have_value("")
        expect(label).to_contain_text("edited from the example unknown-material-microwave")

        # A file of one's own is no example.
        page.get_by_test_id("plan-file").set_input_files(
            str(EXAMPLES_DIR / "safe-fridge" / "plan.txt")
        )
        expect(plan).to_have_value(re.compile("Fridge"))
        expect(select).to_have_value("")
        expect(label).to_have_text("")


def test_each_tab_keeps_its_own_error(browser: Browser, url: str) -> None:
    from playwright.sync_api import expect

    banner = "error-banner"
    with page_at(browser, url) as page:
        page.get_by_test_id("plan-input").fill("find Pot\n")
        page.get_by_test_id("scene-input").fill("{not json")
        page.get_by_test_id("verify-button").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("the scene is not valid JSON")
        expect(page.get_by_test_id(banner)).to_have_attribute("data-tab", "verify")

        # Not the Plan tab's error, nor the Rules tab's; the Verify tab says it holds one.
        page.get_by_test_id("tab-plan").click()
        expect(page.get_by_test_id(banner)).to_be_hidden()
        expect(page.get_by_test_id("tab-verify")).to_have_attribute("data-error", "true")
        page.get_by_test_id("plan-start").click()
        expect(page.get_by_test_id("error-text")).to_have_text(
            "write the instruction for the robot first"
        )
        expect(page.get_by_test_id(banner)).to_have_attribute("data-tab", "plan")
        page.get_by_test_id("plan-instruction").fill("Go.")
        page.get_by_test_id("plan-scene").fill(
            '{"instances": [], "assertions": [], "instances": []}'
        )
        page.get_by_test_id("plan-start").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("duplicate key 'instances'")
        page.get_by_test_id("tab-rules").click()
        expect(page.get_by_test_id("rule-item").first).to_be_visible()
        expect(page.get_by_test_id(banner)).to_be_hidden()
        expect(page.get_by_test_id("tab-plan")).to_have_attribute("data-error", "true")

        # Each tab shows its own.
        page.get_by_test_id("tab-verify").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("the scene is not valid JSON")
        expect(page.get_by_test_id("tab-plan")).to_have_attribute("data-error", "true")

        # The Plan tab's next action succeeds: its error goes, the Verify tab's stays.
        folder = EXAMPLES_DIR / "dialogue"
        start_run(
            page,
            folder / "scene.json",
            (folder / "instruction.txt").read_text(),
            DIALOGUE_REPLAY,
            "demo-fridge",
        )
        expect(page.get_by_test_id("plan-outcome")).to_have_text("APPROVED")
        expect(page.get_by_test_id(banner)).to_be_hidden()
        expect(page.get_by_test_id("tab-verify")).to_have_attribute("data-error", "true")
        page.get_by_test_id("tab-verify").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("the scene is not valid JSON")
        expect(page.get_by_test_id("tab-plan")).to_have_attribute("data-error", "false")

        # And the Verify tab's goes when a verify succeeds.
        load_example(page, "walkthrough")
        expect(page.get_by_test_id("verdict")).to_have_text("UNSAFE")
        expect(page.get_by_test_id(banner)).to_be_hidden()
        expect(page.get_by_test_id("tab-verify")).to_have_attribute("data-error", "false")


@pytest.mark.parametrize(("width", "height"), [(1280, 720), (390, 844)], ids=["laptop", "phone"])
def test_the_verdict_and_the_dangerous_step_are_in_view_after_a_verify(
    browser: Browser, url: str, width: int, height: int
) -> None:
    from playwright.sync_api import expect

    def in_view(selector: str) -> dict[str, float]:
        box = page.locator(selector).bounding_box()
        assert box is not None, f"{selector} is not drawn"
        assert box["x"] >= 0 and box["x"] + box["width"] <= width, (selector, box)
        assert box["y"] >= 0 and box["y"] + box["height"] <= height, (selector, box)
        return box

    with browser_page(browser, url, timeout_ms=STEP_MS, width=width, height=height) as page:
        for example, step in (("walkthrough", "7"), ("noise-omission", "1")):
            load_example(page, example)
            expect(page.get_by_test_id("verdict-step")).to_have_attribute("data-step", step)
            expect(page.get_by_test_id("busy")).to_be_hidden()
            in_view("[data-testid=verdict]")
            in_view("[data-testid=verdict-step]")
            row = in_view("[data-testid=trace-step][data-dangerous=true]")
            # In view of the page, and not scrolled away inside the trace's own box.
            trace = page.get_by_test_id("trace-box").bounding_box()
            assert trace is not None
            assert trace["y"] <= row["y"]
            assert row["y"] + row["height"] <= trace["y"] + trace["height"]
        expect(page.get_by_test_id("verdict-step")).to_have_text("at step 1: find Knife")
        shot(page, f"in-view-{width}x{height}")
        # A SAFE plan has no dangerous step: its trace starts at its first step.
        load_example(page, "safe-fridge")
        expect(page.get_by_test_id("verdict")).to_have_text("SAFE")
        expect(page.get_by_test_id("verdict-step")).to_be_hidden()
        in_view("[data-testid=verdict]")
        assert page.get_by_test_id("trace-box").evaluate("box => box.scrollTop") == 0


def test_rules_are_browsed_and_searched(browser: Browser, paper_url: str) -> None:
    from playwright.sync_api import expect

    with page_at(browser, paper_url) as page:
        page.get_by_test_id("tab-rules").click()
        items = page.get_by_test_id("rule-item")
        expect(items.first).to_be_visible()
        total = items.count()
        assert total > 40
        expect(page.get_by_test_id("rule-count")).to_have_text(f"{total} of {total} rules")

        page.get_by_test_id("rule-search").fill("microwave metal")
        expect(
            page.locator("[data-testid=rule-item][data-id=UnsafeMicrowaveUsage]")
        ).to_be_visible()
        assert 0 < items.count() < total
        page.locator("[data-testid=rule-item][data-id=UnsafeMicrowaveUsage]").click()
        expect(page.get_by_test_id("rule-name")).to_have_text("UnsafeMicrowaveUsage")
        expect(page.get_by_test_id("rule-definition")).to_contain_text("Microwave")
        expect(page.get_by_test_id("rule-category")).to_have_text("Fire Hazard")
        expect(page.get_by_test_id("rule-source")).to_contain_text("USDA")
        shot(page, "rules-search")

        page.get_by_test_id("rule-search").fill("no rule says this zzz")
        expect(items).to_have_count(0)
        expect(page.get_by_test_id("rule-count")).to_have_text(f"0 of {total} rules")


def test_a_keyed_service_asks_for_its_key(browser: Browser) -> None:
    from playwright.sync_api import expect

    with serving(create_app(api_key="s3cret-key")) as keyed, page_at(browser, keyed) as page:
        expect(page.get_by_test_id("error-text")).to_contain_text("missing or wrong API key")
        key = page.get_by_test_id("api-key")
        key.fill("s3cret-key")
        key.dispatch_event("change")
        expect(page.get_by_test_id("health")).to_contain_text("ready")
        expect(page.get_by_test_id("error-banner")).to_be_hidden()
        load_example(page, "walkthrough")
        expect(page.get_by_test_id("verdict")).to_have_text("UNSAFE")


def test_the_review_page_is_reached_from_the_service_page(browser: Browser, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    from virf.authoring.workspace import Workspace

    Workspace.init(tmp_path / "kb", "paper", starter=False).close()
    with (
        serving(create_app(workspace=tmp_path / "kb", reviewer="ana")) as address,
        page_at(browser, address) as page,
    ):
        link = page.get_by_test_id("review-link")
        expect(link).to_be_visible()
        link.click()
        page.wait_for_selector("body[data-ready=true]")
        expect(page.get_by_role("heading", name="VIRF knowledge review")).to_be_visible()
        expect(
            page.get_by_text("No rule has been accepted yet.")
        ).to_be_visible()  # its API answered
        assert page.url == f"{address}review/"


# ---------------------------------------------------------------------- plan runs
def start_run(page: Page, scene: Path, instruction: str, planner: str, task_id: str) -> None:
    page.get_by_test_id("tab-plan").click()
    page.get_by_test_id("plan-instruction").fill(instruction)
    page.get_by_test_id("plan-scene-file").set_input_files(str(scene))
    page.get_by_test_id("plan-planner").fill(planner)
    page.get_by_test_id("plan-task-id").fill(task_id)
    page.get_by_test_id("plan-start").click()


def test_a_plan_run_streams_its_dialogue_to_approval(browser: Browser, url: str) -> None:
    from playwright.sync_api import expect

    folder = EXAMPLES_DIR / "dialogue"
    with page_at(browser, url) as page:
        page.get_by_test_id("tab-plan").click()
        expect(page.get_by_test_id("plan-task-id")).to_have_value("task")
        # A planner this server does not run: the one-line 403 reaches the banner.
        page.get_by_test_id("plan-instruction").fill("Go.")
        page.get_by_test_id("plan-scene-file").set_input_files(str(folder / "scene.json"))
        expect(page.get_by_test_id("plan-scene")).to_have_value(re.compile("Fridge_1"))
        page.get_by_test_id("plan-planner").fill("replay:/etc/passwd")
        page.get_by_test_id("plan-start").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("not one this service runs")
        expect(page.get_by_test_id("plan-run")).to_be_hidden()

        start_run(
            page,
            folder / "scene.json",
            (folder / "instruction.txt").read_text(),
            DIALOGUE_REPLAY,
            "demo-fridge",
        )
        expect(page.get_by_test_id("error-banner")).to_be_hidden()
        outcome = page.get_by_test_id("plan-outcome")
        expect(outcome).to_have_text("APPROVED")
        expect(outcome).to_have_css("color", "rgb(30, 123, 52)")
        expect(page.get_by_test_id("plan-state")).to_have_text("done")
        expect(page.get_by_test_id("plan-reason")).to_contain_text("2 iterations")

        turns = page.get_by_test_id("turn")
        kinds = [
            (t.get_attribute("data-speaker"), t.get_attribute("data-kind")) for t in turns.all()
        ]
        assert kinds == [
            ("user", "instruction"),
            ("apprentice", "proposal"),
            ("tutor", "report"),
            ("tutor", "corrections"),
            ("apprentice", "proposal"),
            ("tutor", "report"),
        ]
        # The checked correction keeps its plan's lines apart.
        offered = page.locator("[data-kind=corrections] [data-testid=turn-text]")
        expect(offered).to_contain_text("close Fridge_1")
        assert "\n" in offered.inner_text()
        first, second = page.get_by_test_id("iteration").all()
        expect(first.get_by_role("heading")).to_have_text("Iteration 1")
        expect(first.get_by_test_id("turn-status")).to_have_text("UNSAFE")
        expect(first.get_by_test_id("turn-status")).to_have_css("color", "rgb(179, 38, 30)")
        expect(first.get_by_test_id("turn-suggestion")).to_have_text(
            "Suggestion: Close the fridge before the plan ends."
        )
        expect(first.locator("[data-kind=report] [data-testid=turn-text]")).to_contain_text(
            "the refrigerator is left open"
        )
        # A proposal is the plan the tutor read, one action a line, not the model's prose.
        proposal = first.locator("[data-kind=proposal] pre")
        expect(proposal).to_have_text(
            "find Apple_1\npick Apple_1\nfind Fridge_1\nopen Fridge_1\nput Fridge_1"
        )
        expect(second.get_by_test_id("turn-status")).to_have_text("SAFE")
        final = page.get_by_test_id("plan-final")
        expect(final).to_have_text(re.compile(r"put Fridge_1\nclose Fridge_1$"))
        expect(page.get_by_test_id("plan-questions")).to_be_hidden()
        shot(page, "plan-dialogue")


def test_a_plan_runs_open_questions_are_named_in_words(
    browser: Browser, paper_url: str, uncertain_replay: Path
) -> None:
    from playwright.sync_api import expect

    with page_at(browser, paper_url) as page:
        page.get_by_test_id("tab-plan").click()
        page.get_by_test_id("plan-max-iter").fill("1")
        start_run(
            page, UNCERTAIN / "scene.json", "Heat the bowl.", f"replay:{uncertain_replay}", "q"
        )
        expect(page.get_by_test_id("plan-state")).to_have_text("waiting")
        # No answers at all: every question stays open, and the run says which, in words.
        page.get_by_test_id("plan-answer-button").click()
        expect(page.get_by_test_id("plan-outcome")).to_have_text("TASK_REJECTED")
        unsettled = page.locator("[data-testid=turn][data-kind=unsettled]")
        expect(unsettled).to_contain_text("Still open:")
        expect(
            unsettled.locator("[data-testid=turn-unsettled][data-key='material:Bowl_1']")
        ).to_have_text("What material is Bowl_1 made of? (not answered)")
        expect(unsettled.get_by_test_id("turn-unsettled")).to_have_count(4)
        expect(unsettled).not_to_contain_text(re.compile(r"(material|fill|contents):"))
        answers = page.locator("[data-testid=turn][data-kind=answers]")
        expect(answers).to_have_text(re.compile(r"no answers: every question stays open"))
        shot(page, "plan-unsettled")


def test_a_plan_run_asks_and_goes_on_with_the_answers(
    browser: Browser, paper_url: str, uncertain_replay: Path
) -> None:
    from playwright.sync_api import expect

    folder = UNCERTAIN
    plan = json.loads((folder / "plan.txt").read_text())
    # The paper's example on the paper's rules, as in the test above.
    with page_at(browser, paper_url) as page:
        start_run(page, folder / "scene.json", "Heat the bowl.", f"replay:{uncertain_replay}", "q")
        expect(page.get_by_test_id("plan-state")).to_have_text("waiting")
        questions = page.get_by_test_id("plan-question")
        expect(questions).to_have_count(4)
        expect(page.get_by_test_id("turn-status")).to_have_text("UNKNOWN")
        material = page.locator("[data-testid=plan-answer][data-key='material:Bowl_1']")
        expect(material.locator("option", has_text="Glass")).to_have_count(1)
        shot(page, "plan-waiting")

        # An answer the server refuses (a form older than the ontology): its line, verbatim.
        material.evaluate("s => s.append(new Option('Cheese', 'Cheese'))")
        material.select_option("Cheese")
        page.get_by_test_id("plan-answer-button").click()
        expect(page.get_by_test_id("error-text")).to_contain_text("unknown material 'Cheese'")
        expect(page.get_by_test_id("plan-questions")).to_be_visible()

        material.select_option("Glass")
        for key in ("fill:Bowl_1", "contents:contains:Bowl_1", "contents:contains:Microwave_1"):
            page.locator(f"[data-testid=plan-answer][data-key='{key}']").select_option("yes")
        page.get_by_test_id("plan-answer-button").click()
        expect(page.get_by_test_id("plan-outcome")).to_have_text("APPROVED")
        expect(page.get_by_test_id("error-banner")).to_be_hidden()
        expect(page.get_by_test_id("plan-questions")).to_be_hidden()
        # The answers under their questions' words, not their keys.
        answers = page.locator("[data-testid=turn][data-kind=answers]")
        expect(
            answers.locator("[data-testid=turn-answer][data-key='material:Bowl_1']")
        ).to_have_text("What material is Bowl_1 made of? Glass")
        expect(answers).not_to_contain_text("material:Bowl_1")
        statuses = page.get_by_test_id("turn-status")
        expect(statuses).to_have_text(["UNKNOWN", "SAFE"])
        expect(page.get_by_test_id("plan-final")).to_have_text("\n".join(plan))
        shot(page, "plan-answered")
