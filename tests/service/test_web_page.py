"""End-to-end tests of the web page (client/web) in a real headless Chromium.

The service runs as a real ``quilting serve`` process (tests/service/conftest.py); the page is
opened from its ``/`` and driven through Playwright like a person would: upload, run, watch the
progress, look at the result, download it. What the page shows is checked against what the
service answers for the same request over plain HTTP.

One Chromium per module, a fresh browser context (storage, downloads) per test. The browser is
Debian's ``chromium`` (``sh docker/install.sh ci`` installs it); without it or Playwright the
tests skip, or fail when ``QUILTING_REQUIRE_BROWSER`` is set (see ``browser.py``).
"""

from __future__ import annotations

import base64
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import pytest
from browser import Console, launch_browser, missing, new_context, skip_or_fail, watch
from PIL import Image
from service_helpers import DATA, Server, png_image, synth, texture, wait_expired

if TYPE_CHECKING:
    from playwright.sync_api import Browser, BrowserContext, Locator, LocatorAssertions, Page

pytestmark = pytest.mark.browser

#: Generous waits: a 2-core machine runs the service, its workers and Chromium at once.
FAST_JOB_S = 45
UI_S = 15

TILED = "Tiled 3\u00d73"  # the tiled view's label

GRAVEL = DATA / "gravel.png"  # 256 x 256, the shared texture
WOOD = DATA / "wood.png"  # 136 x 136
CAMERA = DATA / "target_camera.png"  # 256 x 256, a transfer target

#: Records every change of #status, #error and #progress from the moment it is installed, so
#: that a wait sees the states a run passes through (and not the previous run's final one).
RECORDER_JS = """() => {
  const status = document.querySelector('#status');
  const error = document.querySelector('#error');
  const progress = document.querySelector('#progress');
  const shown = (el) => el.checkVisibility() ? el.textContent.trim() : null;
  const snap = () => ({
    status: status.textContent.trim(),
    error: shown(error),
    progress: Number(progress.value),
  });
  if (window.__quiltingObserver) window.__quiltingObserver.disconnect();
  const log = [snap()];
  window.__quiltingLog = log;
  window.__quiltingObserver = new MutationObserver(() => log.push(snap()));
  for (const el of [status, error, progress]) {
    window.__quiltingObserver.observe(
      el, {subtree: true, childList: true, characterData: true, attributes: true});
  }
}"""

#: Controls (not type=hidden) without a label, aria-label or aria-labelledby with text.
UNLABELLED_JS = """() => [...document.querySelectorAll('input, select, textarea')]
  .filter((e) => e.type !== 'hidden')
  .filter((e) => {
    const labels = [...(e.labels || [])].map((l) => l.textContent.trim());
    const aria = (e.getAttribute('aria-label') || '').trim();
    const by = (e.getAttribute('aria-labelledby') || '').split(/\\s+/).filter(Boolean)
      .map((id) => (document.getElementById(id)?.textContent || '').trim());
    return !(labels.some(Boolean) || aria || by.some(Boolean));
  })
  .map((e) => e.id || e.name || e.outerHTML.slice(0, 120))"""

#: Options the page asks for outside the options form: a synthesis's weights, one per texture
#: beside its thumbnail (test_web_wang.py).
OUTSIDE_THE_FORM = {"SynthesizeOptions": {"weights"}, "WangOptions": {"weights"}}

#: The horizontal overflow of the document (0: no horizontal scroll bar).
OVERFLOW_JS = "() => document.scrollingElement.scrollWidth - window.innerWidth"


# --- the browser ----------------------------------------------------------------------------


@pytest.fixture(scope="session", autouse=True)
def browser_available() -> None:
    """Skip (or fail) before any server starts when Playwright or Chromium is missing."""
    reason = missing()
    if reason is not None:
        skip_or_fail(reason)


@pytest.fixture(scope="module")
def chromium() -> Iterator[Browser]:
    """Debian's Chromium, headless, once per module."""
    yield from launch_browser()


@pytest.fixture
def open_page(chromium: Browser) -> Iterator[Callable[..., WebPage]]:
    """``open_page(server, **context_options)``: the page of ``server`` in a fresh context."""
    contexts: list[BrowserContext] = []

    def open_(server: Server, **context_options: Any) -> WebPage:
        context = new_context(chromium, **context_options)
        contexts.append(context)
        page = context.new_page()
        return WebPage(page, server, watch(page)).open()

    yield open_
    for context in contexts:
        context.close()


class WebPage:
    """The quilting page in one tab, and the steps a person takes on it."""

    def __init__(self, page: Page, server: Server, console: Console) -> None:
        self.page = page
        self.server = server
        self.console = console

    def open(self) -> WebPage:
        self.page.goto(self.server.url + "/")
        # The options form is built from the service's schema once the page has loaded it.
        self.page.locator("#opt-block").wait_for(state="attached", timeout=UI_S * 1000)
        return self

    def __call__(self, selector: str) -> Locator:
        return self.page.locator(selector)

    def soon(self, target: str | Locator) -> LocatorAssertions:
        """Playwright's ``expect`` on ``target`` (a selector or a locator): for states the
        page reaches a moment after what the test waited for (the controls reset when a run's
        downloads are in place, not when #status says done)."""
        from playwright.sync_api import expect

        expect.set_options(timeout=UI_S * 1000)
        return expect(self(target) if isinstance(target, str) else target)

    def state(self) -> str:
        """What the page shows about the run, for assertion messages."""
        return (
            json.dumps(
                self.page.evaluate(
                    """() => ({
                  status: document.querySelector('#status')?.textContent,
                  error: document.querySelector('#error')?.textContent,
                  errorShown: document.querySelector('#error')?.checkVisibility(),
                  progress: document.querySelector('#progress')?.value,
                  jobId: document.querySelector('#job-id')?.textContent,
                  log: (window.__quiltingLog || []).slice(-12),
                })"""
                )
            )
            + f"\nconsole errors: {self.console.errors}\npage errors: {self.console.page_errors}"
        )

    # -- the form --

    def operation(self, label: str) -> None:
        self.page.get_by_role("radio", name=label, exact=True).check()

    def upload(self, selector: str, *paths: Path) -> None:
        self.page.set_input_files(selector, list(paths))

    def option(self, name: str, value: Any) -> None:
        """Set the options field ``#opt-<name>`` (opening "More options" if it is in there)."""
        field = self(f"#opt-{name}")
        field.wait_for(state="attached", timeout=UI_S * 1000)
        if not field.is_visible():
            self(f"details:has(#opt-{name}) > summary").click()
        kind = field.evaluate("e => e.tagName === 'SELECT' ? 'select' : e.type")
        if kind == "select":
            field.select_option(str(value))
        elif kind == "checkbox":
            field.set_checked(bool(value))
        else:
            field.fill(str(value))

    def options(self, **values: Any) -> None:
        for name, value in values.items():
            self.option(name, value)

    def request_options(self) -> dict[str, Any]:
        """The options JSON the page shows for its request (#request-json)."""
        text = self("#request-json").text_content() or ""
        assert text.strip(), f"#request-json is empty\n{self.state()}"
        options: dict[str, Any] = json.loads(text)
        return options

    def job_id(self) -> str:
        return (self("#job-id").text_content() or "").strip()

    # -- running --

    def record(self) -> None:
        """Start recording the run's states (see RECORDER_JS)."""
        self.page.evaluate(RECORDER_JS)

    def start(self, press: str | None = None) -> None:
        """Run: a click on #run, or ``press`` (a key) on the focused Run button."""
        self.record()
        if press is None:
            self("#run").click()
        else:
            self.page.keyboard.press(press)
        try:  # the page says at once that it is at work ("submitting", "queued", ...)
            self.page.wait_for_function(
                "() => window.__quiltingLog.length > 1", timeout=UI_S * 1000
            )
        except Exception as exc:
            how = "the click on #run" if press is None else f"{press} on the focused element"
            raise AssertionError(
                f"{how} started nothing: #status, #error and #progress stayed as they were "
                f"for {UI_S} s\n{self.state()}"
            ) from exc

    def wait_final(self, timeout_s: float = FAST_JOB_S) -> str:
        """Wait until the run is over (#status final, or a new error shown); #status's text.

        Only changes after :meth:`record` count: the previous run's final state does not.
        """
        try:
            self.page.wait_for_function(
                """() => (window.__quiltingLog || []).some((s, i, log) => i > 0 && (
                  /^(done|cancelled|failed)\\b/.test(s.status) ||
                  (s.error && s.error !== log[0].error)))""",
                timeout=timeout_s * 1000,
            )
        except Exception as exc:
            raise AssertionError(f"the run did not end in {timeout_s} s\n{self.state()}") from exc
        return (self("#status").text_content() or "").strip()

    def run(self, timeout_s: float = FAST_JOB_S) -> str:
        """Run and wait until the job is done; its job id."""
        self.start()
        status = self.wait_final(timeout_s)
        assert status.startswith("done"), f"status {status!r}\n{self.state()}"
        return self.job_id()

    def wait_running(self) -> None:
        """Wait until the job runs (#status 'running...' or progress above 0)."""
        try:
            self.page.wait_for_function(
                """() => /^\\s*running/.test(document.querySelector('#status').textContent) ||
                  Number(document.querySelector('#progress').value) > 0""",
                timeout=FAST_JOB_S * 1000,
            )
        except Exception as exc:
            raise AssertionError(f"the job did not start running\n{self.state()}") from exc

    # -- the result --

    def wait_image(self, selector: str, size: tuple[int, int]) -> None:
        """Wait until the <img> ``selector`` has loaded a picture of ``size`` (width, height)."""
        try:
            self.page.wait_for_function(
                """([selector, w, h]) => {
                  const img = document.querySelector(selector);
                  return img && img.complete && img.naturalWidth === w && img.naturalHeight === h;
                }""",
                arg=[selector, *size],
                timeout=UI_S * 1000,
            )
        except Exception as exc:
            actual = self.page.evaluate(
                """(s) => { const i = document.querySelector(s);
                  return i && [i.naturalWidth, i.naturalHeight, i.complete, i.src.slice(0, 60)];
                }""",
                selector,
            )
            raise AssertionError(
                f"{selector} did not show a {size[0]}x{size[1]} picture: {actual}\n{self.state()}"
            ) from exc

    def download(self, selector: str) -> bytes:
        """Click the link ``selector`` and return the bytes of what the browser downloaded."""
        self.soon(selector).to_be_visible()
        with self.page.expect_download(timeout=UI_S * 1000) as info:
            self(selector).click()
        download = info.value
        path = download.path()
        assert download.failure() is None, f"download of {selector} failed: {download.failure()}"
        return Path(path).read_bytes()

    def box(self, selector: str) -> dict[str, float]:
        box = self(selector).bounding_box()
        assert box is not None, f"{selector} is not rendered\n{self.state()}"
        return box

    def overflow(self) -> int:
        overflow: int = self.page.evaluate(OVERFLOW_JS)
        return overflow


def wait_thumbnails(web: WebPage, count: int) -> None:
    """Wait until the texture list shows ``count`` thumbnails, each a loaded picture."""
    web.soon("#textures-order li").to_have_count(count)
    web.page.wait_for_function(
        """(n) => {
          const thumbs = [...document.querySelectorAll('#textures-order img.thumb')];
          return thumbs.length === n && thumbs.every((i) => i.complete && i.naturalWidth > 0);
        }""",
        arg=count,
        timeout=UI_S * 1000,
    )


def gravel_job(web: WebPage, width: int = 200, height: int = 160) -> str:
    """Synthesize gravel at ``width`` x ``height`` (block 32, seed 3); the job id."""
    web.upload("#texture", GRAVEL)
    web.options(width=width, height=height, block=32, seed=3)
    job_id = web.run()
    web.wait_image("#result-image", (width, height))
    return job_id


def problem_detail(response: httpx.Response, status: int) -> str:
    assert response.status_code == status, (response.status_code, response.text[:300])
    detail: str = response.json()["detail"]
    return detail


# --- tests ----------------------------------------------------------------------------------


def test_page_loads_with_labels_and_operations(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    response = httpx.get(server.url + "/", timeout=30)
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/html")
    assert "<title>" in response.text

    web = open_page(server)
    assert "quilting" in web.page.title().lower(), web.page.title()
    assert web("input[type=radio][name=operation]").count() == 7
    for label in (
        "Synthesize",
        "Transfer",
        "Make tileable",
        "Lay on a surface (matting)",
        "Fill a hole",
        "Extend (uncrop)",
        "Wang tiles",
    ):
        radio = web.page.get_by_role("radio", name=label, exact=True)
        assert radio.get_attribute("name") == "operation", label
        assert radio.is_visible(), label
    assert web.page.get_by_role("radio", name="Synthesize", exact=True).is_checked()

    schemas = httpx.get(server.url + "/openapi.json", timeout=30).json()["components"]["schemas"]
    for label, schema in (
        ("Synthesize", "SynthesizeOptions"),
        ("Transfer", "TransferOptions"),
        ("Make tileable", "TileOptions"),
        ("Lay on a surface (matting)", "MatteOptions"),
    ):
        web.operation(label)
        for name in schemas[schema]["properties"]:
            expected = 0 if name in OUTSIDE_THE_FORM.get(schema, ()) else 1
            assert web(f"#opt-{name}").count() == expected, f"{label}: #opt-{name}"
        unlabelled = web.page.evaluate(UNLABELLED_JS)
        assert unlabelled == [], f"{label}: controls without an accessible label: {unlabelled}"

    for selector in ("#texture", "#source-mask", "#companions", "#api-key", "#job-id"):
        assert web(selector).count() == 1, selector
    assert web("#companions").evaluate("e => e.multiple")
    assert web("#status").get_attribute("role") == "status"
    assert web("#error").get_attribute("role") == "alert"
    assert web("#progress").evaluate("e => [e.tagName, e.max]") == ["PROGRESS", 100]
    assert web("#zoom").evaluate("e => [e.type, e.value]") == ["range", "100"]
    assert web.page.get_by_role("button", name="Run", exact=True).get_attribute("id") == "run"
    cancel = web.page.get_by_role("button", name="Cancel", exact=True)
    assert cancel.get_attribute("id") == "cancel"
    assert cancel.is_disabled()
    assert web("#error").is_hidden()
    web.console.assert_clean()


def test_synthesize_gravel_progress_result_and_downloads(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    height_map = tmp_path / "height.png"  # a companion map: named by its file name
    height_map.write_bytes(texture("grass"))  # 256 x 256 like gravel
    web = open_page(server)
    web.upload("#texture", GRAVEL)
    web.upload("#companions", height_map)
    presets = web(".preset")
    assert presets.count() >= 1, "no block presets after choosing a texture"
    presets.first.click()
    preset_block = int(web("#opt-block").input_value())
    assert 3 <= preset_block <= 256, preset_block

    web.options(width=200, height=160, block=32, seed=3)
    job_id = web.run()
    assert job_id, f"no job id\n{web.state()}"
    assert web("#progress").evaluate("e => e.value") == 100
    assert "100" in (web("#progress-text").text_content() or "")
    web.soon("#cancel").to_be_disabled()
    assert web("#error").is_hidden()
    web.wait_image("#result-image", (200, 160))
    assert web.page.get_by_role("img", name="Result", exact=True).is_visible()

    link = web.page.get_by_role("link", name="Download PNG", exact=True)
    assert link.get_attribute("id") == "download-png"
    png = web.download("#download-png")
    assert png_image(png).size == (200, 160)
    companion = web.download(".download-companion")
    assert png_image(companion).size == (200, 160)
    options = web.request_options()
    assert {k: options.get(k) for k in ("width", "height", "block", "seed")} == {
        "width": 200,
        "height": 160,
        "block": 32,
        "seed": 3,
    }, options
    with server.client() as client:
        stored = client.get(f"/jobs/{job_id}/result")
        assert stored.status_code == 200
        assert png == stored.content, "the download is not the job's result"
        stored = client.get(f"/jobs/{job_id}/result/height")
        assert stored.status_code == 200, stored.text[:300]
        assert companion == stored.content, "the companion download is not the job's"
        # The same request over plain HTTP gives the same bytes.
        again = synth(client, options, companions={"height.png": height_map.read_bytes()})
        assert again.status_code == 200, again.text[:300]
        assert png == again.content, "the page's result differs from the service's for its options"

    layout = json.loads(web.download("#download-layout"))
    assert "version" in layout, list(layout)
    assert layout["output_shape"] == [160, 200]
    web.console.assert_clean()


def test_text_file_as_texture_shows_the_problem(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("A texture is a picture, not these words about one.\n" * 20)
    with server.client() as client:
        expected = problem_detail(
            client.post(
                "/synthesize",
                files=[("texture", ("notes.txt", notes.read_bytes(), "text/plain"))],
                data={"options": json.dumps({"width": 200, "height": 160})},
            ),
            415,
        )

    web = open_page(server)
    web.upload("#texture", notes)
    web.options(width=200, height=160)
    web.start()
    web.wait_final()
    error = web("#error")
    assert error.is_visible(), web.state()
    assert error.get_attribute("role") == "alert"
    assert expected in (error.text_content() or ""), web.state()

    # The page still works: a real texture runs to the end and the error goes away.
    gravel_job(web)
    assert web("#error").is_hidden(), web.state()
    web.console.assert_clean(http_errors=True)


def test_cancel_a_running_job(
    start_server: Callable[[str, dict[str, str]], Server], open_page: Callable[..., WebPage]
) -> None:
    server = start_server("web-cancel", {"QUILTING_WORKERS": "1"})
    web = open_page(server)
    web.upload("#texture", GRAVEL)
    # About a minute with the direct-sum backend on a 2-core machine: it runs when cancelled.
    web.options(width=800, height=800, block=32, seed=1, backend="reference")
    assert web("#cancel").is_disabled()
    web.start()
    job_id = ""
    try:
        web.wait_running()
        job_id = web.job_id()
        assert job_id, web.state()
        web("#cancel").click()
        # Cancelled at the job's next progress report: a slow machine takes longer to get
        # there, and a cancel that is not honoured ends "done" (or still running), not here.
        status = web.wait_final()
        assert status.startswith("cancelled"), f"status {status!r}\n{web.state()}"
        web.soon("#cancel").to_be_disabled()
        with server.client() as client:
            assert client.get(f"/jobs/{job_id}").json()["status"] == "cancelled"

        # The only worker is free again: the next job runs to the end.
        web.options(width=200, height=160, block=32, backend="fft")
        next_id = web.run()
        assert next_id and next_id != job_id
        web.wait_image("#result-image", (200, 160))
    finally:
        if job_id:
            with server.client() as client:
                client.delete(f"/jobs/{job_id}")
    web.console.assert_clean()


def test_api_key_is_sent_with_every_request(
    secured_server: Server, open_page: Callable[..., WebPage]
) -> None:
    with secured_server.client() as client:
        expected = problem_detail(synth(client, {"width": 200, "height": 160}, wait=0), 401)

    web = open_page(secured_server)
    web.upload("#texture", GRAVEL)
    web.options(width=200, height=160, block=32, seed=3)
    web.start()
    web.wait_final()
    assert web("#error").is_visible(), web.state()
    assert expected in (web("#error").text_content() or ""), web.state()

    web("#api-key").fill("k1")
    job_id = web.run()
    assert job_id
    web.wait_image("#result-image", (200, 160))
    assert web("#error").is_hidden(), web.state()
    # The service keeps results a few seconds: once the result is gone there, the page must
    # still have the picture itself, fetched with the key.
    with secured_server.client() as client:
        wait_expired(client, job_id, headers={"X-API-Key": "k1"})
    png = web.download("#download-png")
    assert png_image(png).size == (200, 160)
    web.console.assert_clean(http_errors=True)


def test_result_views_seams_and_zoom(server: Server, open_page: Callable[..., WebPage]) -> None:
    web = open_page(server)
    gravel_job(web)
    web("#zoom").fill("100")
    result = web.box("#result-image")
    assert (round(result["width"]), round(result["height"])) == (200, 160), result

    web.page.get_by_role("radio", name=TILED, exact=True).check()
    tiled = web("#tiled")
    tiled.wait_for(state="visible", timeout=UI_S * 1000)
    box = web.box("#tiled")
    assert abs(box["width"] - 600) <= 2 and abs(box["height"] - 480) <= 2, box

    web.page.get_by_role("radio", name="Result", exact=True).check()
    seams = web.page.get_by_role("checkbox", name="Show seams")
    web.soon(seams).to_be_enabled()
    seams.check()
    web.wait_image("#seam-overlay", (200, 160))
    assert web("#seam-overlay").is_visible()
    seams.uncheck()
    web.soon("#seam-overlay").to_be_hidden()

    web.page.get_by_role("radio", name="Side by side", exact=True).check()
    web("#input-image").wait_for(state="visible", timeout=UI_S * 1000)
    web.wait_image("#input-image", (256, 256))
    left, right = web.box("#input-image"), web.box("#result-image")
    if left["x"] > right["x"]:
        left, right = right, left
    assert left["x"] + left["width"] <= right["x"] + 1, (left, right)  # beside, not overlapping
    assert max(left["y"], right["y"]) < min(  # and on one line
        left["y"] + left["height"], right["y"] + right["height"]
    ), (left, right)

    web.page.get_by_role("radio", name="Result", exact=True).check()
    web("#zoom").fill("200")
    zoomed = web.box("#result-image")
    assert abs(zoomed["width"] - 2 * result["width"]) <= 1, (result, zoomed)
    assert abs(zoomed["height"] - 2 * result["height"]) <= 1, (result, zoomed)
    web.console.assert_clean()


def test_keyboard_reaches_the_controls_and_runs(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = open_page(server)
    web.upload("#texture", GRAVEL)
    web.options(width=800, height=800, block=32, seed=1, backend="reference")

    def tab_to(target: str, presses: int = 200) -> list[str]:
        """Press Tab until ``#target`` has the focus; the ids passed on the way."""
        seen: list[str] = []
        for _ in range(presses):
            web.page.keyboard.press("Tab")
            focused = web.page.evaluate("() => document.activeElement?.id || ''")
            seen.append(focused)
            if focused == target:
                return seen
        raise AssertionError(f"Tab never reached #{target}; focus went through {seen}")

    web.page.evaluate("() => document.activeElement?.blur()")
    web.page.mouse.click(1, 1)  # the top of the page, where Tab starts
    order = tab_to("run")
    assert "texture" in order, order

    job_id = ""
    try:
        web.start(press="Space")
        web.wait_running()
        job_id = web.job_id()
        tab_to("cancel")
        web.page.keyboard.press("Enter")
        status = web.wait_final()
        assert status.startswith("cancelled"), f"status {status!r}\n{web.state()}"
    finally:
        if job_id:
            with server.client() as client:
                client.delete(f"/jobs/{job_id}")

    web.options(width=200, height=160, backend="fft")
    tab_to("run")
    web.start(press="Enter")
    status = web.wait_final()
    assert status.startswith("done"), f"status {status!r}\n{web.state()}"
    web.wait_image("#result-image", (200, 160))
    web.console.assert_clean()


def test_transfer_and_make_tileable(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    target = tmp_path / "target.png"  # not square, not the texture's size: 240 x 200
    Image.open(CAMERA).crop((8, 30, 248, 230)).save(target)

    web = open_page(server)
    assert web("#target").is_hidden()
    web.operation("Transfer")
    web("#target").wait_for(state="visible", timeout=UI_S * 1000)
    web.upload("#texture", GRAVEL)
    web.upload("#target", target)
    web.options(block=12, seed=2)
    job_id = web.run()
    web.wait_image("#result-image", (240, 200))
    with server.client() as client:
        status = client.get(f"/jobs/{job_id}").json()
        assert (status["operation"], status["width"], status["height"]) == ("transfer", 240, 200)

    web.operation("Make tileable")
    assert web("#target").is_hidden()
    label = web("#texture").evaluate("e => [...e.labels].map((l) => l.textContent.trim())")
    assert any(text.startswith("Image") for text in label), label
    web.upload("#texture", WOOD)
    web.run()
    web.wait_image("#result-image", (136, 136))
    assert web.job_id() == "", web.state()
    web.soon("#seams").to_be_disabled()
    png = web.download("#download-png")
    options = web.request_options()
    with server.client() as client:
        tiled = client.post(
            "/tile",
            files=[("image", ("wood.png", texture("wood"), "image/png"))],
            data={"options": json.dumps(options)},
        )
        assert tiled.status_code == 200, tiled.text[:300]
    assert png == tiled.content, "the page's tileable image differs from the service's"
    web.console.assert_clean()


def test_narrow_screen_has_no_horizontal_scroll(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = open_page(server, viewport={"width": 380, "height": 800})
    assert web.overflow() <= 1, "horizontal scroll before a result"
    gravel_job(web, 640, 480)  # wider than the screen
    assert web.overflow() <= 1, "horizontal scroll with a result wider than the screen"
    web.page.get_by_role("radio", name=TILED, exact=True).check()
    web("#tiled").wait_for(state="visible", timeout=UI_S * 1000)
    assert web.overflow() <= 1, "horizontal scroll with the tiled view"
    web.console.assert_clean()


def test_drop_a_texture_on_its_box(server: Server, open_page: Callable[..., WebPage]) -> None:
    """Drag-and-drop: a file dropped on the texture's box becomes the texture and runs."""
    web = open_page(server)
    dropped = web.page.evaluate_handle(
        """(b64) => {
          const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
          const transfer = new DataTransfer();
          transfer.items.add(new File([bytes], 'gravel.png', {type: 'image/png'}));
          return transfer;
        }""",
        base64.b64encode(GRAVEL.read_bytes()).decode(),
    )
    box = web('.drop[data-input="texture"]')
    box.dispatch_event("dragover", {"dataTransfer": dropped})
    assert "over" in (box.get_attribute("class") or "")
    box.dispatch_event("drop", {"dataTransfer": dropped})
    web.soon("#texture-info").to_contain_text("256 \u00d7 256")
    assert web("#texture").evaluate("e => [e.files.length, e.files[0].name]") == [1, "gravel.png"]
    assert "over" not in (box.get_attribute("class") or "")
    web.options(width=120, height=100, block=32)
    web.run()
    web.wait_image("#result-image", (120, 100))
    web.console.assert_clean()


def test_an_option_s_whole_help_opens_on_demand(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    """Each option's help is one line; its "more" button (reached from the keyboard) shows
    the whole text in place, says so to a screen reader, and "less" folds it again."""
    web = open_page(server)
    hint, toggle = web("#opt-block-hint"), web("#opt-block + .hint + .hint-more")
    description = httpx.get(server.url + "/openapi.json", timeout=30).json()["components"][
        "schemas"
    ]["SynthesizeOptions"]["properties"]["block"]["description"]
    assert hint.text_content() == description
    folded = hint.evaluate("e => [e.clientHeight, e.scrollHeight]")
    assert folded[1] > folded[0], f"the help is not cut to one line: {folded}"
    assert toggle.get_attribute("aria-expanded") == "false"
    assert toggle.get_attribute("aria-controls") == "opt-block-hint"
    toggle.focus()
    web.page.keyboard.press("Enter")
    assert toggle.get_attribute("aria-expanded") == "true" and toggle.text_content() == "less"
    opened = hint.evaluate("e => [e.clientHeight, e.scrollHeight]")
    assert opened[0] >= opened[1] and opened[0] > folded[0], (folded, opened)
    toggle.click()
    assert toggle.get_attribute("aria-expanded") == "false" and toggle.text_content() == "more"
    assert hint.evaluate("e => e.clientHeight") == folded[0]
    # Every option of the form has one (the page's own fields, the alpha's menus, have none).
    fields = web(".field .hint[id^='opt-']").count()
    assert web(".field .hint-more").count() == fields > 10
    assert web.page.evaluate(UNLABELLED_JS) == []
    web.console.assert_clean()


def test_another_seed_draws_a_new_one(server: Server, open_page: Callable[..., WebPage]) -> None:
    """The seed's "Another seed" button (reached from the keyboard) puts a new random seed
    in the field, a whole number the service takes; each press draws again."""
    web = open_page(server)
    seed = web("#opt-seed")
    dice = web.page.get_by_role("button", name="Another seed", exact=True)
    assert dice.get_attribute("aria-controls") == "opt-seed"
    assert seed.input_value() == "0"
    drawn = []
    for _ in range(3):
        dice.focus()
        web.page.keyboard.press("Enter")
        drawn.append(seed.input_value())
    values = [int(value) for value in drawn]
    assert all(0 <= value < 2**31 for value in values), values
    assert len(set(values)) == 3 and 0 not in values, values  # 3 draws of 2^31 collide ~never
    assert seed.evaluate("e => e.checkValidity()")
    web.console.assert_clean()
