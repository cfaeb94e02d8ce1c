"""The API docs work offline: /docs (Swagger UI) and /redoc (ReDoc) load from this service only.

The bundles come from the installed ``fastapi-offline`` package (quilting.service.apidocs).
The browser tests open the pages of a real ``quilting serve`` in Debian's Chromium with every
request to another host aborted, and check that the pages render the API (the POST /synthesize
operation) and that they never tried another host. The HTTP tests check that every URL the two
pages name is this service's and answers with the right type, and that the pages' policy
(Content-Security-Policy) allows this origin alone.
"""

from __future__ import annotations

import base64
import hashlib
import re
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from html.parser import HTMLParser
from importlib import resources
from typing import TYPE_CHECKING
from urllib.parse import urljoin, urlsplit

import httpx
import pytest
from browser import Console, launch_browser, new_context, watch
from service_helpers import ROOT, Server

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page, Request, Route

#: Generous: a 2-core machine runs the service and Chromium at once; the bundles are 2.6 MB.
UI_MS = 30_000

#: What a docs page's references must answer, by how the URL ends.
MEDIA_TYPES = {
    ".js": "text/javascript",
    ".css": "text/css",
    ".png": "image/png",
    ".json": "application/json",
}

#: Records every Content-Security-Policy violation of the page (a load the policy stopped).
CSP_RECORDER_JS = """
window.__cspViolations = [];
document.addEventListener('securitypolicyviolation', (e) => {
  window.__cspViolations.push(`${e.violatedDirective} ${e.blockedURI}`);
});
"""


# --- the pages' references, read from their HTML --------------------------------------------


class References(HTMLParser):
    """Every URL a page names (src, href, spec-url) and its inline scripts and styles."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []
        self.inline: dict[str, list[str]] = {"script": [], "style": []}
        self._open: str | None = None
        self._text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        for name in ("src", "href", "spec-url"):
            if values.get(name):
                self.urls.append(str(values[name]))
        if tag in self.inline and "src" not in values:
            self._open, self._text = tag, []

    def handle_data(self, data: str) -> None:
        if self._open is not None:
            self._text.append(data)

    def handle_endtag(self, tag: str) -> None:
        if tag == self._open:
            self.inline[tag].append("".join(self._text))
            self._open = None


def references(html: str) -> References:
    found = References()
    found.feed(html)
    # Swagger UI's configuration names the OpenAPI document inside its inline script.
    for script in found.inline["script"]:
        found.urls += re.findall(r"\burl:\s*'([^']+)'", script)
    return found


def policy(response: httpx.Response) -> dict[str, list[str]]:
    """The page's Content-Security-Policy as directive -> sources."""
    header = response.headers.get("content-security-policy")
    assert header, f"{response.url} has no Content-Security-Policy"
    directives: dict[str, list[str]] = {}
    for part in header.split(";"):
        name, *sources = part.split()
        directives[name] = sources
    return directives


def sha256_source(text: str) -> str:
    return "'sha256-" + base64.b64encode(hashlib.sha256(text.encode()).digest()).decode() + "'"


# --- HTTP -----------------------------------------------------------------------------------


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_every_reference_of_the_page_is_ours_and_answers(server: Server, path: str) -> None:
    page = httpx.get(server.url + path, timeout=30)
    assert page.status_code == 200, page.text[:300]
    assert page.headers["content-type"].startswith("text/html")
    found = references(page.text)
    urls = sorted(set(found.urls))
    # The HTML names its bundle(s), stylesheet (Swagger UI), favicon and the OpenAPI document.
    assert "/openapi.json" in urls, urls
    assert any(u.endswith(".js") for u in urls), urls
    origin = urlsplit(server.url)
    for url in urls:
        absolute = urlsplit(urljoin(server.url + path, url))
        assert (absolute.scheme, absolute.netloc) == (origin.scheme, origin.netloc), (
            f"{path} loads {url} from another origin"
        )
        response = httpx.get(absolute.geturl(), timeout=30)
        assert response.status_code == 200, (url, response.status_code)
        suffix = "." + absolute.path.rpartition(".")[2]
        media = response.headers["content-type"].split(";")[0]
        assert media == MEDIA_TYPES[suffix], (url, media)
        assert response.content, url
        if media == "text/javascript":
            assert response.headers.get("x-content-type-options") == "nosniff", url


@pytest.mark.parametrize(
    ("path", "styles_inline"), [("/docs", False), ("/redoc", True)], ids=["docs", "redoc"]
)
def test_the_page_policy_allows_this_origin_alone(
    server: Server, path: str, styles_inline: bool
) -> None:
    page = httpx.get(server.url + path, timeout=30)
    directives = policy(page)
    assert directives["default-src"] == ["'self'"]
    for name in ("img-src", "font-src", "connect-src", "script-src", "style-src"):
        for source in directives[name]:
            # Only this origin, inline data (data:, blob:) and hashes: no host, no scheme-wide
            # http(s):, no wildcard.
            assert source in ("'self'", "data:", "blob:", "'unsafe-inline'") or re.fullmatch(
                r"'sha256-[A-Za-z0-9+/=]+'", source
            ), f"{path}: {name} allows {source}"
    assert "'unsafe-inline'" not in directives["script-src"]
    assert "'unsafe-eval'" not in directives["script-src"]
    found = references(page.text)
    # Each inline script runs because its hash is listed, and only those hashes are.
    scripts = {sha256_source(text) for text in found.inline["script"]}
    assert set(directives["script-src"]) - {"'self'"} == scripts
    assert scripts or path == "/redoc"  # Swagger UI's page configures it in an inline script
    if styles_inline:
        assert directives["style-src"] == ["'self'", "'unsafe-inline'"]
    else:
        assert set(directives["style-src"]) - {"'self'"} == {
            sha256_source(text) for text in found.inline["style"]
        }
    assert directives["object-src"] == ["'none'"]
    assert directives["frame-ancestors"] == ["'none'"]


def test_the_bundles_are_the_installed_packages_files(server: Server) -> None:
    static = resources.files("fastapi_offline") / "static"
    for name in ("swagger-ui-bundle.js", "swagger-ui.css", "favicon.png"):
        response = httpx.get(f"{server.url}/docs/static/{name}", timeout=30)
        assert response.status_code == 200, name
        assert response.content == (static / name).read_bytes(), name
    redoc = httpx.get(server.url + "/docs/static/redoc.standalone.js", timeout=30)
    original = (static / "redoc.standalone.js").read_bytes()
    # The one change: no logo from Redocly's CDN.
    assert b"cdn.redoc.ly" not in redoc.content
    assert len(redoc.content) < len(original)
    assert redoc.content.replace(b'src:"data:,"', b"") == original.replace(
        b'src:"https://cdn.redoc.ly/redoc/logo-mini.svg"', b""
    )


def test_a_bundle_revalidates_with_its_etag(server: Server) -> None:
    url = server.url + "/docs/static/swagger-ui.css"
    first = httpx.get(url, timeout=30)
    etag = first.headers["etag"]
    assert first.headers["cache-control"] == "no-cache"
    again = httpx.get(url, headers={"If-None-Match": etag}, timeout=30)
    assert again.status_code == 304
    assert again.content == b""
    other = httpx.get(url, headers={"If-None-Match": '"something-else"'}, timeout=30)
    assert other.status_code == 200 and other.content == first.content


@pytest.mark.parametrize(
    "name", ["core.py", "..%2F__init__.py", "swagger-ui.css.map", "%2E%2E", "LICENSE"]
)
def test_only_the_bundles_are_served(server: Server, name: str) -> None:
    response = httpx.get(f"{server.url}/docs/static/{name}", timeout=30)
    assert response.status_code == 404, (name, response.status_code)
    assert response.headers["content-type"].startswith("application/problem+json")
    assert response.json()["code"] == "not_found"


@pytest.mark.parametrize("path", ["/docs", "/redoc", "/docs/static/swagger-ui.css"])
def test_without_the_bundles_the_docs_answer_503_not_a_blank_page(
    monkeypatch: pytest.MonkeyPatch, path: str
) -> None:
    from fastapi.testclient import TestClient

    from quilting.service import apidocs
    from quilting.service.app import create_app

    monkeypatch.setattr(apidocs, "ASSET_PACKAGE", "no_such_package_for_quilting_docs")
    apidocs._asset.cache_clear()
    try:
        # No lifespan (no `with`): no workers are started for this.
        response = TestClient(create_app()).get(path)
    finally:
        apidocs._asset.cache_clear()
    assert response.status_code == 503
    assert response.headers["content-type"] == "application/problem+json"
    assert response.json()["code"] == "docs_unavailable"
    assert "fastapi-offline" in response.json()["detail"]
    assert response.headers["x-content-type-options"] == "nosniff"


def test_the_server_extra_brings_the_bundles() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    server_extra = project["optional-dependencies"]["server"]
    assert any(re.match(r"fastapi-offline\b", dep) for dep in server_extra), server_extra


# --- the pages in a browser, network off --------------------------------------------------


@dataclass
class Offline:
    """A page whose requests to any host but the service's are aborted, and what it tried."""

    page: Page
    console: Console
    origin: str
    elsewhere: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    requested: list[str] = field(default_factory=list)

    def route(self, route: Route) -> None:
        url = route.request.url
        parts = urlsplit(url)
        if parts.scheme in ("http", "https", "ws", "wss") and (
            f"{parts.scheme}://{parts.netloc}" != self.origin
        ):
            self.elsewhere.append(url)
            route.abort("internetdisconnected")
        else:
            route.continue_()

    def on_request(self, request: Request) -> None:
        self.requested.append(request.url)

    def on_failed(self, request: Request) -> None:
        self.failed.append(f"{request.url}: {request.failure}")

    def open(self, path: str) -> None:
        self.page.goto(self.origin + path, wait_until="load", timeout=UI_MS)

    def settle(self) -> None:
        """Wait until nothing is loading any more (late loads are part of the check)."""
        self.page.wait_for_load_state("networkidle", timeout=UI_MS)

    def assert_loaded_only_here(self, needed: str) -> None:
        """Once the page has settled: it loaded a URL ending in ``needed`` (what shows it
        worked), and nothing from elsewhere."""
        self.settle()
        assert any(u.endswith(needed) for u in self.requested), self.requested
        self.assert_nothing_elsewhere()

    def assert_nothing_elsewhere(self) -> None:
        violations = self.page.evaluate("() => window.__cspViolations")
        assert self.elsewhere == [], f"requests to other hosts: {self.elsewhere}"
        assert self.failed == [], f"failed requests: {self.failed}"
        assert violations == [], f"loads the page's policy stopped: {violations}"
        self.console.assert_clean()
        origin = urlsplit(self.origin)
        for url in self.requested:
            parts = urlsplit(url)
            if parts.scheme in ("http", "https"):
                assert parts.netloc == origin.netloc, url


@pytest.fixture(scope="module")
def chromium() -> Iterator[Browser]:
    yield from launch_browser()


@pytest.fixture
def offline(chromium: Browser, server: Server) -> Iterator[Offline]:
    context = new_context(chromium)
    context.add_init_script(CSP_RECORDER_JS)
    page = context.new_page()
    guard = Offline(page, watch(page), server.url)
    # Every request of the context, the page's and its workers', goes past the guard.
    context.route("**/*", guard.route)
    page.on("request", guard.on_request)
    page.on("requestfailed", guard.on_failed)
    try:
        yield guard
    finally:
        context.close()


@pytest.mark.browser
def test_swagger_ui_renders_synthesize_offline(offline: Offline) -> None:
    from playwright.sync_api import expect

    offline.open("/docs")
    operation = offline.page.locator(
        ".opblock.opblock-post:has(.opblock-summary-path[data-path='/synthesize'])"
    )
    expect(operation).to_be_visible(timeout=UI_MS)
    expect(operation.locator(".opblock-summary-description")).to_have_text(
        "Synthesize a texture of any size from a sample"
    )
    # It is a working page, not a picture of one: the operation opens with its parameters.
    operation.locator(".opblock-summary").first.click()
    expect(operation.locator(".opblock-body")).to_contain_text("texture", timeout=UI_MS)
    expect(operation.locator("button.try-out__btn")).to_be_visible()
    offline.assert_loaded_only_here("/openapi.json")


@pytest.mark.browser
def test_redoc_renders_synthesize_offline(offline: Offline) -> None:
    from playwright.sync_api import expect

    offline.open("/redoc")
    entry = offline.page.locator("[data-item-id='operation/synthesize']")
    expect(entry).to_be_visible(timeout=UI_MS)
    expect(entry).to_contain_text("Synthesize a texture of any size from a sample")
    expect(entry).to_contain_text("post")
    # The operation's section is rendered too, with its path.
    section = offline.page.locator("[id='operation/synthesize']").first
    expect(section).to_contain_text("/synthesize", timeout=UI_MS)
    offline.assert_loaded_only_here("/openapi.json")


@pytest.mark.browser
def test_the_web_page_loads_nothing_from_elsewhere(offline: Offline) -> None:
    offline.open("/")
    # The page builds its form from the OpenAPI document: once it is there, all has loaded.
    offline.page.locator("#opt-block").wait_for(state="attached", timeout=UI_MS)
    offline.assert_loaded_only_here("/web/app.js")
