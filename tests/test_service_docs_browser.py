"""``/docs`` in a real headless Chromium (Debian's, driven by Playwright)
against a real uvicorn server, with every request that is not to that server
refused: Swagger UI (``/docs``) and ReDoc (``/redoc``) still render the
service's operations, from the scripts and styles the service serves itself."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import pytest
from browser_support import chromium, needs_browser, serving

from virf.service.app import create_app

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page, Route

pytestmark = needs_browser
# Generous: a slow machine under load, not a latency requirement.
STEP_MS = 30_000


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    with serving(create_app()) as address:
        yield address


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with chromium() as launched:
        yield launched


@contextmanager
def offline(browser: Browser, url: str) -> Iterator[tuple[Page, list[str], list[str]]]:
    """A page on which every request that is not to ``url``'s server is
    aborted, with the list of those refused and of the page's script errors."""
    refused: list[str] = []
    errors: list[str] = []

    def only_the_server(route: Route) -> None:
        if route.request.url.startswith(url):
            route.continue_()
        else:
            refused.append(route.request.url)
            route.abort()

    context = browser.new_context()
    try:
        context.route("**/*", only_the_server)
        page = context.new_page()
        page.set_default_timeout(STEP_MS)
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        yield page, refused, errors
    finally:
        context.close()


def test_docs_show_the_operations_with_the_network_refused(browser: Browser, url: str) -> None:
    with offline(browser, url) as (page, refused, errors):
        page.goto(url + "docs")
        page.wait_for_selector(".opblock")
        paths = page.locator(".opblock-summary-path").all_inner_texts()
        title = page.locator(".info .title").inner_text()
    assert "VIRF Logic Tutor" in title
    shown = {p.replace("\u200b", "").strip() for p in paths}
    assert {"/v1/verify", "/v1/rules", "/v1/health", "/v1/plan"} <= shown, shown
    assert not errors, errors
    assert not refused, refused


def test_redoc_shows_the_operations_with_the_network_refused(browser: Browser, url: str) -> None:
    with offline(browser, url) as (page, refused, errors):
        page.goto(url + "redoc")
        page.get_by_text("/v1/verify", exact=True).first.wait_for()
        heading = page.locator("h1").first.inner_text()
    assert "VIRF Logic Tutor" in heading
    assert not errors, errors
    # ReDoc's bundle names one image of its own on a CDN, the Redocly logo
    # of its footer; the page is whole without it.
    assert all(u.startswith("https://cdn.redoc.ly/") for u in refused), refused
