"""End-to-end tests of the web page's fill (``POST /fill``) and extension (``POST /extend``) in
headless Chromium.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright. The mask is painted with the mouse on the
canvas over the image, shown larger than its natural size, or chosen as a file; what the page
sent is read back from the ``FormData`` it gave ``fetch`` (Chromium does not hand multipart
bodies with files to Playwright), and the result is checked pixel by pixel against the input:
every pixel outside the mask kept, the painted ones filled.
"""

from __future__ import annotations

import base64
import json
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest
import test_web_page
from browser import new_context, watch
from PIL import Image
from service_helpers import DATA, Server, png_image
from test_web_page import UNLABELLED_JS, WebPage

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium

if TYPE_CHECKING:
    from playwright.sync_api import Browser, BrowserContext

pytestmark = pytest.mark.browser

FILL = "Fill a hole"  # the operations' radios
EXTEND = "Extend (uncrop)"
GRAVEL = DATA / "gravel.png"  # 256 x 256, gray
WOOD = DATA / "wood.png"  # 136 x 136, RGB
OPTIONS = {"block": 24, "seed": 3, "backend": "fft"}

#: Installed before the page's own scripts: keeps every FormData the page gives fetch, so that
#: a test reads the parts it sent (the mask above all) as the service received them.
SENT_JS = """(() => {
  const sent = [];
  window.__quiltingSent = sent;
  const original = window.fetch;
  window.fetch = function (input, init) {
    if (init && init.body instanceof FormData) sent.push({ url: String(input), body: init.body });
    return original.apply(this, arguments);
  };
})();"""

#: One part of the ``index``-th FormData sent: base64 of its bytes, or null when absent.
PART_JS = """async ([index, name]) => {
  const part = window.__quiltingSent.at(index).body.get(name);
  if (part === null) return null;
  if (typeof part === 'string') return btoa(part);
  const url = await new Promise((resolve, reject) => {
    const reader = new FileReader();
    reader.onload = () => resolve(reader.result);
    reader.onerror = () => reject(reader.error);
    reader.readAsDataURL(part);
  });
  return url.slice(url.indexOf(',') + 1);
}"""


@pytest.fixture
def open_sent_page(chromium: Browser) -> Iterator[Callable[..., WebPage]]:
    """``open_sent_page(server, **context_options)``: the page, recording what it sends."""
    contexts: list[BrowserContext] = []

    def open_(server: Server, **context_options: Any) -> WebPage:
        context = new_context(chromium, **context_options)
        contexts.append(context)
        context.add_init_script(SENT_JS)
        page = context.new_page()
        return WebPage(page, server, watch(page)).open()

    yield open_
    for context in contexts:
        context.close()


# --- helpers ------------------------------------------------------------------------------------


def pixels(path_or_bytes: Path | bytes) -> np.ndarray:
    """An image's pixels as Pillow decodes them (gray: 2-D)."""
    if isinstance(path_or_bytes, Path):
        return np.asarray(Image.open(path_or_bytes))
    return np.asarray(png_image(path_or_bytes))


def sent(web: WebPage) -> list[str]:
    """The URLs of the multipart requests the page has sent."""
    urls: list[str] = web.page.evaluate("() => window.__quiltingSent.map((s) => s.url)")
    return urls


def sent_part(web: WebPage, name: str, index: int = -1) -> bytes | None:
    """The bytes of the part ``name`` of the ``index``-th multipart request the page sent."""
    data = web.page.evaluate(PART_JS, [index, name])
    return None if data is None else base64.b64decode(data)


def painted_count(web: WebPage) -> int:
    """The number of mask pixels the page says are painted (#mask-info)."""
    text = web("#mask-info").text_content() or ""
    match = re.match(r"(\d+) pixels to fill", text)
    assert match, f"#mask-info: {text!r}"
    return int(match.group(1))


def stroke(web: WebPage, *points: tuple[float, float]) -> float:
    """Drag the mouse over the mask's canvas through ``points`` (in the image's own pixels);
    the scale the image is shown at (CSS pixels per image pixel)."""
    return stroke_on(web, "#mask-canvas", *points)


def stroke_on(web: WebPage, selector: str, *points: tuple[float, float]) -> float:
    """Drag the mouse over the painting canvas ``selector`` through ``points`` (in the
    image's own pixels); the scale the image is shown at (CSS pixels per image pixel)."""
    canvas = web(selector)
    canvas.scroll_into_view_if_needed()
    box = web.box(selector)
    scale = box["width"] / canvas.evaluate("c => c.width")
    mouse = web.page.mouse
    (x, y), *rest = points
    mouse.move(box["x"] + x * scale, box["y"] + y * scale)
    mouse.down()
    for x, y in rest:
        mouse.move(box["x"] + x * scale, box["y"] + y * scale, steps=12)
    mouse.up()
    return scale


def segment_distance(
    shape: tuple[int, int], a: tuple[float, float], b: tuple[float, float]
) -> np.ndarray:
    """Each pixel centre's distance to the segment from ``a`` to ``b`` (x, y)."""
    rows, cols = np.indices(shape, dtype=np.float64)
    px, py = cols + 0.5 - a[0], rows + 0.5 - a[1]
    dx, dy = b[0] - a[0], b[1] - a[1]
    t = np.clip((px * dx + py * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    return np.hypot(px - t * dx, py - t * dy)


def fill_over_http(
    server: Server, image: Path, mask: bytes, options: dict[str, Any]
) -> httpx.Response:
    """``POST /fill?wait=60`` of what the page sent, as plain HTTP."""
    files = [
        ("image", (image.name, image.read_bytes(), "image/png")),
        ("mask", ("mask.png", mask, "image/png")),
    ]
    with server.client() as client:
        return client.post(
            "/fill", params={"wait": 60}, files=files, data={"options": json.dumps(options)}
        )


def job(server: Server, job_id: str) -> dict[str, Any]:
    with server.client() as client:
        response = client.get(f"/jobs/{job_id}")
    assert response.status_code == 200, response.text[:300]
    status: dict[str, Any] = response.json()
    return status


def result_of(server: Server, job_id: str) -> bytes:
    with server.client() as client:
        response = client.get(f"/jobs/{job_id}/result")
    assert response.status_code == 200, response.text[:300]
    return response.content


def choose_fill(web: WebPage, image: Path) -> None:
    """Pick the fill and its image; wait until the image is there to be painted on."""
    web.operation(FILL)
    web.soon("#painter").to_be_visible()
    web.upload("#texture", image)
    web.soon("#mask-editor").to_be_visible()
    web.soon("#mask-info").to_contain_text("Nothing painted")


# --- tests --------------------------------------------------------------------------------------


def test_paint_a_stroke_and_fill_it(server: Server, open_sent_page: Callable[..., WebPage]) -> None:
    """A stroke painted with the mouse on the enlarged image is sent as a mask of the image's
    natural size, white under the stroke; the result keeps every other pixel byte for byte and
    fills the stroke; it is the job's result, the service's answer for the same request, and
    is shown beside the image before it."""
    web = open_sent_page(server)
    choose_fill(web, GRAVEL)
    web("#brush-size").fill("20")
    web.soon("#brush-size-value").to_have_text("20 px")
    start, end = (60.0, 100.0), (180.0, 140.0)
    scale = stroke(web, start, end)
    assert abs(scale - 1) > 0.1, f"the image is shown at its natural size ({scale}): no test"
    web.soon("#mask-info").to_contain_text("pixels to fill")
    web.soon("#mask-undo").to_be_enabled()
    web.options(**OPTIONS)
    assert web.request_options() == OPTIONS

    job_id = web.run()
    web.wait_image("#result-image", (256, 256))
    status = job(server, job_id)
    assert (status["operation"], status["status"]) == ("fill", "done"), status
    assert sent(web)[-1].endswith("/fill?wait=0"), sent(web)

    # The mask: the image's natural size, white under the stroke (radius 10) and black around.
    mask_png = sent_part(web, "mask")
    assert mask_png is not None
    mask = pixels(mask_png)
    assert mask.shape[:2] == (256, 256), mask.shape
    assert set(np.unique(mask[..., :3])) <= {0, 255}, np.unique(mask)
    painted = mask[..., :3].max(axis=-1) > 0
    assert painted.sum() == painted_count(web)
    # One CSS pixel is less than an image pixel here: the pointer lands within 1.5 of it.
    distance = segment_distance((256, 256), start, end)
    assert painted[distance <= 10 - 1.5].all(), "the stroke's middle is not in the mask"
    assert not painted[distance > 10 + 1.5].any(), "the mask reaches past the stroke"
    assert sent_part(web, "image") == GRAVEL.read_bytes()
    assert json.loads(sent_part(web, "options") or b"") == OPTIONS

    png = web.download("#download-png")
    assert png == result_of(server, job_id), "the download is not the job's result"
    before, after = pixels(GRAVEL), pixels(png)
    assert after.shape == before.shape, (after.shape, before.shape)
    assert np.array_equal(after[~painted], before[~painted]), "a pixel outside the mask changed"
    changed = after[painted] != before[painted]
    assert changed.mean() > 0.5, f"only {changed.mean():.0%} of the painted pixels changed"
    again = fill_over_http(server, GRAVEL, mask_png, OPTIONS)
    assert again.status_code == 200, again.text[:300]
    assert png == again.content, "the page's result differs from the service's for its request"

    # Before and after, side by side.
    web.soon("#input-figure").to_be_visible()
    web.soon("#input-caption").to_have_text("Before")
    web.soon("#result-caption").to_have_text(re.compile(r"^After, 256 \u00d7 256"))
    web.wait_image("#input-image", (256, 256))
    web.console.assert_clean()


def test_upload_a_mask_then_erase_part_of_it(
    server: Server, open_sent_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """A mask file is shown on the image as the painted area (any colour fills, alpha 0 keeps)
    and sent as it is; erased in part with the brush, the painted mask is sent instead."""
    before = pixels(WOOD)  # 136 x 136 RGB
    mask = np.zeros((136, 136, 4), np.uint8)
    mask[40:80, 30:100] = (255, 255, 255, 255)  # white: fill
    mask[10:20, 10:30] = (0, 0, 1, 255)  # the least non-zero colour: fill
    mask[100:120, 10:50] = (255, 0, 0, 0)  # any colour of alpha 0: keep
    expected = mask[..., 3].astype(bool) & mask[..., :3].any(axis=-1)
    mask_path = tmp_path / "mask.png"
    Image.fromarray(mask).save(mask_path)

    web = open_sent_page(server)
    choose_fill(web, WOOD)
    web.upload("#mask", mask_path)
    web.soon("#mask-file-info").to_contain_text("shown on the image")
    web.soon("#mask-info").to_contain_text(f"{expected.sum()} pixels to fill")
    web.options(**OPTIONS)
    job_id = web.run()
    web.wait_image("#result-image", (136, 136))
    assert sent_part(web, "mask") == mask_path.read_bytes(), "the mask file was not sent as is"
    after = pixels(result_of(server, job_id))
    assert np.array_equal(after[~expected], before[~expected]), "a pixel outside the mask changed"
    assert (after[expected] != before[expected]).any(axis=-1).mean() > 0.5
    again = fill_over_http(server, WOOD, mask_path.read_bytes(), OPTIONS)
    assert again.status_code == 200, again.text[:300]
    assert web.download("#download-png") == again.content

    # Erase a band across the rectangle: now the painted mask is sent.
    web.page.get_by_role("radio", name="Erase", exact=True).check()
    web("#brush-size").fill("10")
    stroke(web, (65.0, 30.0), (65.0, 110.0))
    web.soon("#mask-info").not_to_contain_text(f"{expected.sum()} pixels")
    job_id = web.run()
    web.wait_image("#result-image", (136, 136))
    assert len(sent(web)) == 2, sent(web)
    erased = pixels(sent_part(web, "mask") or b"")
    assert erased.shape[:2] == (136, 136), erased.shape
    kept = erased[..., :3].max(axis=-1) > 0
    assert kept.sum() == painted_count(web)
    assert not (kept & ~expected).any(), "erasing painted pixels outside the mask"
    distance = segment_distance((136, 136), (65.0, 30.0), (65.0, 110.0))
    assert not kept[distance <= 5 - 1.5].any(), "the erased band is still in the mask"
    assert kept[expected & (distance > 5 + 1.5)].all(), "erased outside the stroke"
    after = pixels(result_of(server, job_id))
    assert np.array_equal(after[~kept], before[~kept]), "a pixel outside the mask changed"
    web.console.assert_clean()


def test_undo_and_clear_and_refusals(
    server: Server, open_sent_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """Nothing painted: the page says so and sends nothing. Undo takes a stroke back, Clear
    them all. A mask file of another size is named as such and the service's refusal shown."""
    web = open_sent_page(server)
    choose_fill(web, GRAVEL)
    web("#run").click()
    web.soon("#error").to_contain_text("paint over the area to fill")
    web.soon("#mask").to_be_focused()
    assert sent(web) == []

    stroke(web, (20.0, 20.0), (100.0, 20.0))
    first = painted_count(web)
    stroke(web, (20.0, 200.0), (200.0, 200.0))
    web.soon("#mask-info").not_to_contain_text(f"{first} pixels")
    web("#mask-undo").click()
    web.soon("#mask-info").to_contain_text(f"{first} pixels to fill")
    web("#mask-clear").click()
    web.soon("#mask-info").to_contain_text("Nothing painted")
    web.soon("#mask-clear").to_be_disabled()

    small = tmp_path / "small-mask.png"
    Image.new("L", (128, 128), 255).save(small)
    web.upload("#mask", small)
    web.soon("#mask-file-info").to_contain_text("128 \u00d7 128, not the image's 256 \u00d7 256")
    web.start()
    web.wait_final()
    web.soon("#error").to_contain_text("422")
    assert sent_part(web, "mask") == small.read_bytes()
    web.console.assert_clean(http_errors=True)


def test_extend_adds_pixels_around_the_image(
    server: Server, open_sent_page: Callable[..., WebPage]
) -> None:
    """Extend: nothing added is refused on the page; 16 rows on top and 24 columns on the
    right give a 160 x 152 image with the input in place, byte for byte."""
    web = open_sent_page(server)
    web.operation(EXTEND)
    for side in ("top", "bottom", "left", "right"):
        web.soon(f"#opt-{side}").to_be_visible()
    web.soon("#painter").to_be_hidden()
    web.upload("#texture", WOOD)
    web.option("block", 24)
    web("#run").click()
    web.soon("#error").to_contain_text("give the pixels to add")
    web.soon("#opt-top").to_be_focused()
    assert sent(web) == []

    web.options(top=16, right=24, seed=2)
    assert web.request_options() == {"block": 24, "seed": 2, "top": 16, "right": 24}
    job_id = web.run()
    web.wait_image("#result-image", (160, 152))
    assert sent(web)[-1].endswith("/extend?wait=0"), sent(web)
    assert sent_part(web, "mask") is None
    assert job(server, job_id)["operation"] == "extend"
    after = pixels(result_of(server, job_id))
    assert after.shape == (152, 160, 3), after.shape
    assert np.array_equal(after[16:, :136], pixels(WOOD)), "the image was not kept in place"
    web.soon("#input-caption").to_have_text("Before")
    web.console.assert_clean()


def test_fill_controls_are_labelled_and_fit_a_narrow_screen(
    server: Server, open_sent_page: Callable[..., WebPage]
) -> None:
    """Every option of the fill, the extension and the tile's method has its field (a tile made
    by 'fill' is the service's); every control has a label; the painter fits a phone's width."""
    schemas = httpx.get(server.url + "/openapi.json", timeout=30).json()["components"]["schemas"]
    web = open_sent_page(server, viewport={"width": 380, "height": 800})
    for label, schema in ((FILL, "FillOptions"), (EXTEND, "ExtendOptions")):
        web.operation(label)
        for name in schemas[schema]["properties"]:
            web.soon(f"#opt-{name}").to_have_count(1)
        unlabelled = web.page.evaluate(UNLABELLED_JS)
        assert unlabelled == [], f"{label}: controls without an accessible label: {unlabelled}"
    # The tile's method comes from its schema; 'fill' is sent and made as the service makes it.
    web.operation("Make tileable")
    assert web("#opt-method option").all_text_contents() == ["cut", "fill"]
    web.upload("#texture", WOOD)
    web.option("method", "fill")
    assert web.request_options() == {"method": "fill"}
    web.run()
    web.wait_image("#result-image", (136, 136))
    with server.client() as client:
        tiled = client.post(
            "/tile",
            files=[("image", (WOOD.name, WOOD.read_bytes(), "image/png"))],
            data={"options": json.dumps({"method": "fill"})},
        )
    assert tiled.status_code == 200, tiled.text[:300]
    assert web.download("#download-png") == tiled.content

    web.operation(FILL)
    web.upload("#texture", GRAVEL)
    web.soon("#mask-editor").to_be_visible()
    box = web.box("#mask-canvas")
    assert box["width"] < 380, box
    assert web.overflow() <= 1, "horizontal scroll with the painter shown"
    assert abs(web.box("#mask-image")["width"] - box["width"]) < 1, "overlay and image differ"
    web.console.assert_clean()
