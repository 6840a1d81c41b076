"""The service's API docs work without the internet: ``/docs`` (Swagger UI)
and ``/redoc`` load their scripts, styles and icon from the service itself
(test_service_docs_browser.py renders ``/docs`` with the network refused)."""

from __future__ import annotations

import re
from html.parser import HTMLParser

import pytest
from fastapi.testclient import TestClient

from virf.service.app import DOCS_ASSETS, create_app

LOCAL = "http://127.0.0.1"


@pytest.fixture(scope="module")
def client() -> TestClient:
    return TestClient(create_app(), base_url=LOCAL)


class _Links(HTMLParser):
    """Every URL a page loads by itself: src and href attributes."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.urls += [v for k, v in attrs if k in ("src", "href") and v]


def _links(html: str) -> list[str]:
    parser = _Links()
    parser.feed(html)
    return parser.urls


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_the_docs_pages_load_only_what_the_service_serves(client: TestClient, page: str) -> None:
    answer = client.get(page)
    assert answer.status_code == 200
    urls = _links(answer.text)
    assert urls, answer.text
    # No scheme, no host: each is a path on this service.
    assert all(u.startswith("/") and not u.startswith("//") for u in urls), urls
    assert not re.search(r"https?://", answer.text), answer.text
    for url in urls:
        served = client.get(url)
        assert served.status_code == 200, url
        assert served.content, url
        assert url.startswith(DOCS_ASSETS + "/"), url


def test_swagger_ui_asks_no_outside_validator(client: TestClient) -> None:
    # Swagger UI's default would send the API description to a public validator.
    assert '"validatorUrl": null' in client.get("/docs").text


def test_the_styles_load_nothing_from_outside(client: TestClient) -> None:
    css = client.get(f"{DOCS_ASSETS}/swagger-ui.css")
    assert css.headers["content-type"].startswith("text/css")
    assert not re.search(r"url\(\s*['\"]?(https?:)?//", css.text)
    assert "@import" not in css.text
