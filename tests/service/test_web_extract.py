"""End-to-end tests of the web page's alpha from an ordinary photo (``POST /extract-alpha``,
and ``trimap`` / ``scribbles`` parts beside a synthesis's ``texture``) in headless Chromium.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright. The photo is made here: ``cloud_rgba.png``
made small and composited over a gradient, so that it has no alpha; its trimap is white where
the cloud is nearly opaque, black where it is absent. What the page sent is read back from the
``FormData`` it gave ``fetch`` (test_web_fill.py's recorder); the RGBA texture it shows is its
download, checked against the trimap and the scribbles and against the service's answer to the
same request over plain HTTP.
"""

from __future__ import annotations

import base64
import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import test_web_fill
import test_web_page
from PIL import Image
from service_helpers import DATA, Server, lit_sphere, png_image
from test_web_fill import segment_distance, sent, sent_part, stroke_on
from test_web_page import UNLABELLED_JS, WebPage

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
# The page recording what it sends, as the fill tests open it.
open_sent_page = test_web_fill.open_sent_page

pytestmark = pytest.mark.browser

CLOUD = DATA / "cloud_rgba.png"  # 192 x 192, RGBA: the cloud over nothing
WIDTH, HEIGHT = 80, 64  # the photo's size: small, and not square
#: The cloud's alpha over which the trimap says "foreground", and under which "background".
SURE, ABSENT = 0.8, 0.02
SYNTH = {"width": 96, "height": 96, "block": 16, "seed": 3, "backend": "fft"}
MATTE = "Lay on a surface (matting)"  # the operation's radio
MATTE_OPTIONS = {"block": 16, "seed": 3, "clusters": 4, "backend": "fft"}
SPHERE = 96  # the matting target's side

#: Every part ``name`` of the ``index``-th FormData the page sent: base64 of each one's bytes.
ALL_PARTS_JS = """async ([index, name]) => {
  const parts = window.__quiltingSent.at(index).body.getAll(name);
  return Promise.all(parts.map(async (part) => {
    if (typeof part === 'string') return btoa(part);
    const bytes = new Uint8Array(await part.arrayBuffer());
    let text = '';
    for (const byte of bytes) text += String.fromCharCode(byte);
    return btoa(text);
  }));
}"""


# --- the images ---------------------------------------------------------------------------------


@dataclass
class Photo:
    """An opaque photo of a cloud over a gradient, its trimap and a trimap of another size."""

    photo: Path
    trimap: Path
    small_trimap: Path  # half the photo's size
    foreground: np.ndarray  # where the trimap is white
    background: np.ndarray  # where it is black


@pytest.fixture
def cloud_photo(tmp_path: Path) -> Photo:
    cloud = np.asarray(Image.open(CLOUD).resize((WIDTH, HEIGHT), Image.Resampling.LANCZOS))
    alpha = cloud[..., 3:].astype(np.float64) / 255
    ramp = np.linspace(0.0, 1.0, WIDTH)[None, :, None]
    sky = (1 - ramp) * np.array([30.0, 60.0, 120.0]) + ramp * np.array([200.0, 120.0, 40.0])
    sky = np.broadcast_to(sky, (HEIGHT, WIDTH, 3))
    photo = np.rint(alpha * cloud[..., :3] + (1 - alpha) * sky).astype(np.uint8)
    foreground = alpha[..., 0] >= SURE
    background = alpha[..., 0] <= ABSENT
    trimap = np.full((HEIGHT, WIDTH), 128, np.uint8)
    trimap[foreground] = 255
    trimap[background] = 0
    assert foreground.sum() > 50 and background.sum() > 50  # both are marked
    paths = [tmp_path / name for name in ("cloud-photo.png", "trimap.png", "small-trimap.png")]
    Image.fromarray(photo, "RGB").save(paths[0])
    Image.fromarray(trimap, "L").save(paths[1])
    Image.fromarray(trimap[::2, ::2], "L").save(paths[2])
    return Photo(*paths, foreground=foreground, background=background)


# --- helpers ------------------------------------------------------------------------------------


def open_alpha(web: WebPage) -> None:
    """Open the folded "Alpha from the photo" panel (if it is not open already)."""
    if not web("#alpha-details").evaluate("e => e.open"):
        web("#alpha-summary").click()
    web.soon("#alpha-details").to_have_attribute("open", "")


def is_open(web: WebPage) -> bool:
    """Whether the alpha panel is open."""
    return bool(web("#alpha-details").evaluate("e => e.open"))


def choose_photo(web: WebPage, photo: Path) -> None:
    """Synthesize, with ``photo`` as the texture; open the alpha panel and wait until the
    photo is there to be painted on."""
    web.operation("Synthesize")
    web.soon("#alpha").to_be_visible()
    web.upload("#texture", photo)
    open_alpha(web)
    web.soon("#scribble-editor").to_be_visible()
    web.soon("#scribble-info").to_contain_text("Nothing painted")
    web.soon("#alpha-info").to_contain_text("is opaque")


def extract(web: WebPage) -> None:
    """Click Extract alpha and wait until the page is done with it."""
    web.record()
    web("#extract").click()
    status = web.wait_final()
    assert status.startswith("done"), f"status {status!r}\n{web.state()}"


def stroke(web: WebPage, *points: tuple[float, float]) -> float:
    """Drag the mouse over the scribbles' canvas through ``points`` (in the photo's own
    pixels); the scale the photo is shown at (CSS pixels per photo pixel)."""
    return stroke_on(web, "#scribble-canvas", *points)


def painted(web: WebPage) -> tuple[int, int]:
    """The keep and remove pixels the page says are painted (#scribble-info)."""
    text = web("#scribble-info").text_content() or ""
    match = re.match(r"(\d+) pixels to keep, (\d+) to remove", text)
    assert match, f"#scribble-info: {text!r}"
    return int(match.group(1)), int(match.group(2))


def extract_over_http(
    server: Server, parts: dict[str, tuple[str, bytes]], options: dict[str, Any]
) -> httpx.Response:
    """``POST /extract-alpha`` of ``parts`` ({name: (file name, bytes)}), as plain HTTP."""
    files = [(name, (filename, data, "image/png")) for name, (filename, data) in parts.items()]
    with server.client() as client:
        return client.post(
            "/extract-alpha",
            params={"wait": 60},
            files=files,
            data={"options": json.dumps(options)},
        )


def matting_choices(server: Server) -> tuple[list[str], str]:
    """The ``matting`` choices of the synthesis's options schema, and its default."""
    schemas = httpx.get(server.url + "/openapi.json", timeout=30).json()["components"]["schemas"]
    spec = schemas["SynthesizeOptions"]["properties"]["matting"]
    spec = next((v for v in spec.get("anyOf", []) if "enum" in v), spec)
    return list(spec["enum"]), str(spec["default"])


def sent_parts(web: WebPage, name: str, index: int = -1) -> list[bytes]:
    """The bytes of every part ``name`` of the ``index``-th multipart request, in order."""
    data: list[str] = web.page.evaluate(ALL_PARTS_JS, [index, name])
    return [base64.b64decode(part) for part in data]


def alpha_choices(server: Server, name: str) -> tuple[list[str], str]:
    """The choices of ``AlphaOptions.<name>`` (the extraction's options), and its default."""
    schemas = httpx.get(server.url + "/openapi.json", timeout=30).json()["components"]["schemas"]
    spec = schemas["AlphaOptions"]["properties"][name]
    return list(spec["enum"]), str(spec["default"])


def figures(web: WebPage) -> dict[str, str]:
    """The result's figures (#stats), by label."""
    return dict(
        zip(
            web("#stats dt").all_text_contents(),
            web("#stats dd").all_text_contents(),
            strict=True,
        )
    )


# --- tests --------------------------------------------------------------------------------------


def test_alpha_panel_folded_until_opened(
    server: Server, open_sent_page: Callable[..., WebPage], cloud_photo: Photo
) -> None:
    """The common options first (issue 27): with an opaque texture chosen, the alpha panel is
    folded to its summary (title and one-line intro), the scribble editor is not shown and the
    options follow right under it; a run sends nothing for alpha. Enter on the summary opens
    it. A trimap chosen opens it by itself and keeps it open; folded by hand, the summary names
    what it holds (all of it is sent). A reload folds it again."""
    web = open_sent_page(server)
    web.operation("Synthesize")
    web.upload("#texture", cloud_photo.photo)
    web.soon("#alpha-info").to_contain_text("is opaque")
    web.soon("#scribble-info").to_contain_text("Nothing painted")  # the photo is read
    assert not is_open(web)
    web.soon("#alpha-summary").to_be_visible()
    web.soon("#alpha-intro").to_be_visible()
    web.soon("#alpha-intro").to_contain_text("For an opaque photo of ice, smoke or leaves")
    web.soon("#alpha-summary").to_have_accessible_name("Alpha from the photo (optional)")
    web.soon("#alpha-summary").to_have_accessible_description(
        re.compile(r"^For an opaque photo of ice, smoke or leaves: .*then quilted\.$")
    )
    for hidden in ("#scribble-canvas", "#scribble-editor", "#trimap", "#extract"):
        web.soon(hidden).to_be_hidden()
    web.soon("#opt-width").to_be_visible()
    summary, panel, width = (web.box(s) for s in ("#alpha-summary", "#alpha", "#opt-width"))

    # Enter on the summary (focusable, labelled) opens it: the editor comes between.
    web("#alpha-summary").focus()
    web.soon("#alpha-summary").to_be_focused()
    web.page.keyboard.press("Enter")
    web.soon("#alpha-details").to_have_attribute("open", "")
    web.soon("#scribble-canvas").to_be_visible()
    editor, opened, moved = (web.box(s) for s in ("#scribble-editor", "#alpha", "#opt-width"))
    between = moved["y"] - (opened["y"] + opened["height"])  # the panel's end to the options
    # Folded, the panel ends within one summary's height under its summary, and the options
    # follow as closely as they follow the open panel: nothing of it in between.
    threshold = summary["y"] + 2 * summary["height"] + between
    assert panel["y"] + panel["height"] <= summary["y"] + 2 * summary["height"], (panel, summary)
    assert width["y"] <= threshold + 1, (width, threshold)
    assert moved["y"] - width["y"] >= editor["height"], (moved, width, editor)
    web.page.keyboard.press("Space")  # the same key folds it
    web.soon("#scribble-canvas").to_be_hidden()
    assert not is_open(web)

    # Folded and empty: a run sends no trimap and no scribbles.
    web.options(**SYNTH)
    web.run()
    assert sent_parts(web, "texture") == [cloud_photo.photo.read_bytes()]
    assert sent_parts(web, "trimap") == [] and sent_parts(web, "scribbles") == []

    # A trimap chosen opens it; it stays open while it holds one (a new texture, another
    # operation and back); folded by hand, its summary names the trimap.
    web.upload("#trimap", cloud_photo.trimap)
    web.soon("#alpha-details").to_have_attribute("open", "")
    web.soon("#trimap-info").to_contain_text(f"{WIDTH} \u00d7 {HEIGHT} pixels")
    web.soon("#alpha-state").to_have_text("")  # open: the panel itself shows it
    web.upload("#texture", cloud_photo.photo)
    web.soon("#scribble-info").to_contain_text("Nothing painted")
    web.operation(MATTE)
    web.soon("#alpha").to_be_hidden()
    web.operation("Synthesize")
    web.soon("#scribble-editor").to_be_visible()
    assert is_open(web)
    stroke(web, (20.0, 20.0), (40.0, 24.0))
    web.soon("#scribble-info").to_contain_text("pixels to keep, 0 to remove")
    keep, _ = painted(web)
    web("#alpha-summary").click()
    web.soon("#scribble-editor").to_be_hidden()
    named = (
        f"Alpha from the photo (optional): trimap {cloud_photo.trimap.name} and scribbles "
        f"({keep} px to keep, 0 to remove)"
    )
    web.soon("#alpha-summary").to_contain_text(named)
    web.soon("#alpha-summary").to_have_accessible_name(named)

    # A reload starts folded again.
    web.page.reload()
    web("#opt-block").wait_for(state="attached")
    web.soon("#alpha-summary").to_be_visible()
    assert not is_open(web)
    web.soon("#trimap").to_be_hidden()
    web.soon("#alpha-state").to_have_text("")
    web.console.assert_clean()


def test_extract_alpha_from_a_trimap(
    server: Server, open_sent_page: Callable[..., WebPage], cloud_photo: Photo
) -> None:
    """A photo and its trimap: Extract alpha sends them with the method chosen from the
    schema's menu, and shows the RGBA texture beside the photo with the extraction's summary;
    its alpha is 255 where the trimap is white and 0 where black, and it is the service's
    answer to the same request."""
    choices, default = matting_choices(server)
    web = open_sent_page(server)
    choose_photo(web, cloud_photo.photo)
    assert web("#alpha-method option").all_text_contents() == choices
    assert web("#alpha-method").input_value() == default
    foregrounds, foreground = alpha_choices(server, "foreground")
    assert web("#alpha-foreground option").all_text_contents() == foregrounds
    assert web("#alpha-foreground").input_value() == foreground
    web.upload("#trimap", cloud_photo.trimap)
    web.soon("#trimap-info").to_contain_text(f"{WIDTH} \u00d7 {HEIGHT} pixels")
    web.soon("#trimap-info").not_to_contain_text("not the photo's")
    web.soon("#alpha-info").to_contain_text("extracted from the trimap")
    method = "knn" if "knn" in choices else choices[0]
    web("#alpha-method").select_option(method)

    extract(web)
    web.wait_image("#result-image", (WIDTH, HEIGHT))
    assert sent(web)[-1].endswith("/extract-alpha?wait=0"), sent(web)
    assert sent_part(web, "photo") == cloud_photo.photo.read_bytes()
    assert sent_part(web, "trimap") == cloud_photo.trimap.read_bytes()
    assert sent_part(web, "scribbles") is None
    options = json.loads(sent_part(web, "options") or b"")
    assert options == {"method": method}, options

    png = web.download("#download-png")
    rgba = np.asarray(png_image(png))
    assert rgba.shape == (HEIGHT, WIDTH, 4), rgba.shape
    alpha = rgba[..., 3]
    assert (alpha[cloud_photo.foreground] == 255).all(), "a white trimap pixel is not opaque"
    assert (alpha[cloud_photo.background] == 0).all(), "a black trimap pixel is not transparent"
    unknown = ~(cloud_photo.foreground | cloud_photo.background)
    assert 0 < alpha[unknown].mean() < 255, "the grey band was not solved for"

    # The photo beside it, and the summary: the method, the unknown share, the time.
    web.soon("#input-figure").to_be_visible()
    web.soon("#input-caption").to_have_text("Photo")
    web.soon("#result-caption").to_have_text(re.compile(r"^Extracted RGBA, 80 \u00d7 64"))
    web.soon("#alpha-info").to_contain_text(f"Extracted with {method}")
    web.soon("#seams").to_be_disabled()

    again = extract_over_http(
        server,
        {
            "photo": (cloud_photo.photo.name, cloud_photo.photo.read_bytes()),
            "trimap": (cloud_photo.trimap.name, cloud_photo.trimap.read_bytes()),
        },
        options,
    )
    assert again.status_code == 200, again.text[:300]
    served = np.asarray(png_image(again.content)).astype(int)
    assert np.abs(served - rgba.astype(int)).max() <= 1, "the page's result is not the service's"
    extracted = json.loads(again.headers["Quilting-Extracted"])
    assert isinstance(extracted, list) and len(extracted) == 1, extracted
    summary = extracted[0]
    assert summary["method"] == method, summary
    assert summary["unknown"] == pytest.approx(unknown.mean(), abs=1e-3), summary
    shown = figures(web)
    assert shown["matting"] == method, shown
    assert shown["foreground"] == summary["foreground"], shown
    assert shown["unknown"] == f"{100 * summary['unknown']:.1f} % of the photo", shown
    assert shown["iterations"] == str(summary["iterations"]), shown
    assert re.fullmatch(r"\d+\.\d\d s", shown["extraction time"]), shown
    web.soon("#alpha-info").to_contain_text(
        f"Extracted with {method} (foreground {summary['foreground']}): "
        f"{100 * summary['unknown']:.1f} % of the photo solved for, "
        f"in {summary['iterations']} iteration"
    )
    web.console.assert_clean()


def test_paint_scribbles_extract_and_undo(
    server: Server, open_sent_page: Callable[..., WebPage], cloud_photo: Photo
) -> None:
    """Strokes painted with the mouse on the enlarged photo are sent as a PNG of the photo's
    own size: white and opaque under the keep stroke, black under the remove stroke (less what
    the eraser took), transparent elsewhere; the extraction's alpha follows them. Undo takes a
    stroke back, Clear all of them."""
    web = open_sent_page(server)
    choose_photo(web, cloud_photo.photo)
    web("#scribble-size").fill("8")
    web.soon("#scribble-size-value").to_have_text("8 px")
    keep = ((10.0, 14.0), (60.0, 20.0))
    remove = ((8.0, 52.0), (70.0, 50.0))
    erase = ((40.0, 40.0), (40.0, 60.0))

    scale = stroke(web, *keep)
    assert abs(scale - 1) > 0.5, f"the photo is shown at its natural size ({scale}): no test"
    web.soon("#scribble-info").to_have_text(re.compile(r"^[1-9]\d* pixels to keep, 0 to remove$"))
    web.page.get_by_role("radio", name="Remove (black)", exact=True).check()
    stroke(web, *remove)
    web.soon("#scribble-info").to_have_text(re.compile(r"^\d+ pixels to keep, [1-9]\d* to remove$"))
    with_remove = painted(web)
    web.page.get_by_role("radio", name="Eraser", exact=True).check()
    web("#scribble-size").fill("6")
    stroke(web, *erase)
    web.soon("#scribble-info").not_to_have_text(
        re.compile(rf"^{with_remove[0]} pixels to keep, {with_remove[1]} to remove$")
    )
    counts = painted(web)
    web.soon("#alpha-info").to_contain_text("extracted from the scribbles")
    # The photo's own colours: the one option that differs from the service's defaults.
    web("#alpha-foreground").select_option("photo")

    extract(web)
    web.wait_image("#result-image", (WIDTH, HEIGHT))
    assert sent(web)[-1].endswith("/extract-alpha?wait=0"), sent(web)
    assert sent_part(web, "trimap") is None
    assert json.loads(sent_part(web, "options") or b"") == {"foreground": "photo"}
    web.soon("#alpha-info").to_contain_text("(foreground photo)")
    scribbles_png = sent_part(web, "scribbles")
    assert scribbles_png is not None
    scribbles = png_image(scribbles_png)
    assert scribbles.size == (WIDTH, HEIGHT), scribbles.size
    assert scribbles.mode == "RGBA", scribbles.mode
    marks = np.asarray(scribbles)
    white = (marks == (255, 255, 255, 255)).all(axis=-1)
    black = (marks == (0, 0, 0, 255)).all(axis=-1)
    clear = marks[..., 3] == 0
    assert (white | black | clear).all(), "a scribble pixel is neither white, black nor clear"
    assert (white.sum(), black.sum()) == counts, ((white.sum(), black.sum()), counts)

    # One CSS pixel is less than a photo pixel here: the pointer lands within 1.5 of it.
    shape = (HEIGHT, WIDTH)
    near_keep = segment_distance(shape, *keep)
    near_remove = segment_distance(shape, *remove)
    near_erase = segment_distance(shape, *erase)
    assert white[near_keep <= 4 - 1.5].all(), "the keep stroke's middle is not white"
    assert black[(near_remove <= 4 - 1.5) & (near_erase > 3 + 1.5)].all(), (
        "the remove stroke's middle is not black"
    )
    assert clear[near_erase <= 3 - 1.5].all(), "the eraser left paint"
    far = (near_keep > 4 + 1.5) & (near_remove > 4 + 1.5)
    assert clear[far].all(), "paint away from the strokes"

    alpha = np.asarray(png_image(web.download("#download-png")))[..., 3]
    assert (alpha[white] == 255).all(), "the keep stroke is not opaque in the result"
    assert (alpha[black] == 0).all(), "the remove stroke is not transparent in the result"

    # Undo the eraser's stroke, then clear them all.
    web("#scribble-undo").click()
    web.soon("#scribble-info").to_contain_text(
        f"{with_remove[0]} pixels to keep, {with_remove[1]} to remove"
    )
    web("#scribble-clear").click()
    web.soon("#scribble-info").to_contain_text("Nothing painted")
    web.soon("#scribble-clear").to_be_disabled()
    web.console.assert_clean()


def test_refusals_and_a_trimap_of_another_size(
    server: Server, open_sent_page: Callable[..., WebPage], cloud_photo: Photo
) -> None:
    """Nothing given: the page says so and sends nothing. A photo with alpha needs none. A
    trimap of another size is named as such, and the service's invalid_trimap refusal shown
    with its detail."""
    web = open_sent_page(server)
    choose_photo(web, cloud_photo.photo)
    unlabelled = web.page.evaluate(UNLABELLED_JS)
    assert unlabelled == [], f"controls without an accessible label: {unlabelled}"
    web("#extract").click()
    web.soon("#error").to_contain_text("give a trimap, or paint scribbles")
    web.soon("#trimap").to_be_focused()
    assert sent(web) == []

    web.upload("#trimap", cloud_photo.small_trimap)
    web.soon("#trimap-info").to_contain_text(
        f"{WIDTH // 2} \u00d7 {HEIGHT // 2} pixels, not the photo's {WIDTH} \u00d7 {HEIGHT}"
    )
    web.record()
    web("#extract").click()
    web.wait_final()
    web.soon("#error").to_contain_text("invalid_trimap")
    web.soon("#error").to_contain_text("422")
    assert sent_part(web, "trimap") == cloud_photo.small_trimap.read_bytes()
    refused = extract_over_http(
        server,
        {
            "photo": (cloud_photo.photo.name, cloud_photo.photo.read_bytes()),
            "trimap": (cloud_photo.small_trimap.name, cloud_photo.small_trimap.read_bytes()),
        },
        {},
    )
    assert refused.status_code == 422, refused.text[:300]
    assert refused.json()["code"] == "invalid_trimap", refused.text[:300]
    web.soon("#error").to_contain_text(refused.json()["detail"])
    web.soon("#extract").to_be_enabled()

    # The cloud itself has alpha: nothing to paint on, nothing to extract, nothing sent.
    web.upload("#texture", CLOUD)
    web.soon("#alpha-info").to_contain_text("has an alpha channel of its own")
    web.soon("#scribble-editor").to_be_hidden()
    # The summary says so too, open or folded (what is in it is named only when folded).
    web.soon("#alpha-state").to_have_text(f": not needed, {CLOUD.name} has alpha of its own")
    web("#alpha-summary").click()
    web.soon("#alpha-state").to_have_text(
        f": not needed, {CLOUD.name} has alpha of its own; trimap {cloud_photo.small_trimap.name}"
    )
    web("#alpha-summary").click()
    count = len(sent(web))
    web("#extract").click()
    web.soon("#error").to_contain_text("nothing to extract")
    web("#run").click()
    web.soon("#error").to_contain_text("needs no trimap or scribbles")
    assert len(sent(web)) == count
    web.console.assert_clean(http_errors=True)


def test_synthesize_a_photo_with_its_trimap(
    server: Server, open_sent_page: Callable[..., WebPage], cloud_photo: Photo
) -> None:
    """Run with a trimap beside the opaque photo: the texture and trimap parts are sent with
    the method chosen in the panel as the ``matting`` option (one choice: the field follows
    the menu and the menu the field), and the result is alpha-quilted RGBA."""
    choices, default = matting_choices(server)
    other = next(choice for choice in choices if choice != default)
    web = open_sent_page(server)
    choose_photo(web, cloud_photo.photo)
    web.upload("#trimap", cloud_photo.trimap)
    web.options(**SYNTH)
    web("#alpha-method").select_option(other)
    web.soon("#opt-matting").to_have_value(other)
    web.option("matting", default)
    web.soon("#alpha-method").to_have_value(default)
    web("#alpha-method").select_option(other)
    options = web.request_options()
    assert options == {**SYNTH, "matting": other}, options

    job_id = web.run()
    web.wait_image("#result-image", (SYNTH["width"], SYNTH["height"]))
    assert sent(web)[-1].endswith("/synthesize?wait=0"), sent(web)
    assert sent_part(web, "texture") == cloud_photo.photo.read_bytes()
    assert sent_part(web, "trimap") == cloud_photo.trimap.read_bytes()
    assert sent_part(web, "scribbles") is None
    assert json.loads(sent_part(web, "options") or b"") == options
    with server.client() as client:
        status = client.get(f"/jobs/{job_id}").json()
        stored = client.get(f"/jobs/{job_id}/result")
    assert (status["operation"], status["status"]) == ("synthesize", "done"), status
    png = web.download("#download-png")
    assert png == stored.content, "the download is not the job's result"
    result = png_image(png)
    assert result.mode == "RGBA", result.mode
    alpha = np.asarray(result)[..., 3]
    assert alpha.min() < 64 and alpha.max() == 255, (alpha.min(), alpha.max())

    # What the service says of the extraction, in the status, the header and on the page.
    extracted = status["stats"]["extracted"]
    assert isinstance(extracted, list) and len(extracted) == 1, extracted
    summary = extracted[0]
    assert summary["method"] == other, summary
    assert json.loads(stored.headers["Quilting-Extracted"]) == extracted
    web.soon("#alpha-info").to_contain_text(
        f"Extracted with {other} (foreground {summary['foreground']}): "
        f"{100 * summary['unknown']:.1f} % of the photo solved for"
    )
    shown = figures(web)
    assert shown["matting"] == other, shown
    assert shown["unknown"] == f"{100 * summary['unknown']:.1f} % of the photo", shown
    assert shown["extraction time"] == f"{summary['seconds']:.2f} s", shown
    web.console.assert_clean()


def test_synthesize_the_photo_with_an_rgba_texture(
    server: Server, open_sent_page: Callable[..., WebPage], cloud_photo: Photo
) -> None:
    """Two textures, the opaque photo first: its trimap is sent as the first ``trimap`` part
    and an empty one stands for the RGBA texture after it; the summary names the texture."""
    web = open_sent_page(server)
    choose_photo(web, cloud_photo.photo)
    web.upload("#texture", cloud_photo.photo, CLOUD)
    web.soon("#textures-order > li").to_have_count(2)
    web.upload("#trimap", cloud_photo.trimap)
    web.soon("#alpha-info").to_contain_text(
        "the first texture; the others are sent as they are) is extracted from the trimap"
    )
    web.options(**SYNTH)

    job_id = web.run()
    web.wait_image("#result-image", (SYNTH["width"], SYNTH["height"]))
    assert sent_parts(web, "texture") == [cloud_photo.photo.read_bytes(), CLOUD.read_bytes()]
    assert sent_parts(web, "trimap") == [cloud_photo.trimap.read_bytes(), b""]
    assert sent_parts(web, "scribbles") == []
    with server.client() as client:
        status = client.get(f"/jobs/{job_id}").json()
    assert status["status"] == "done", status
    extracted = status["stats"]["extracted"]
    assert len(extracted) == 2 and extracted[1] is None, extracted
    web.soon("#alpha-info").to_contain_text(f"Texture 1: extracted with {extracted[0]['method']}")
    shown = figures(web)
    assert shown["matting (texture 1)"] == extracted[0]["method"], shown
    assert "matting (texture 2)" not in shown, shown
    assert png_image(web.download("#download-png")).mode == "RGBA"
    web.console.assert_clean()


def test_matte_layer_with_a_trimap(
    server: Server, open_sent_page: Callable[..., WebPage], cloud_photo: Photo, tmp_path: Path
) -> None:
    """A matting's layers: the RGBA one says it needs no trimap, the opaque photo takes one
    (Trimap… under it), sent as the second ``trimap`` part after an empty one; the result's
    figures say how its alpha was found. The trimap follows its layer when the layers are
    reordered, and ✕ takes it off."""
    shade, mask = lit_sphere(SPHERE)
    target, silhouette = tmp_path / "sphere.png", tmp_path / "sphere-mask.png"
    Image.fromarray(shade).save(target)
    Image.fromarray(mask).save(silhouette)
    web = open_sent_page(server)
    web.operation(MATTE)
    web.soon("#layers").to_be_visible()
    web.soon("#alpha").to_be_hidden()
    web.upload("#target", target)
    web.upload("#silhouette", silhouette)
    web.upload("#layers", CLOUD, cloud_photo.photo)
    items = web("#layers-order > li")
    web.soon(items).to_have_count(2)
    web.soon(items.nth(0)).to_contain_text("has alpha: laid as it is")
    chooser = web.page.get_by_label(f"Trimap of {cloud_photo.photo.name} (optional)")
    chooser.set_input_files(cloud_photo.small_trimap)
    web.soon(items.nth(1)).to_contain_text(
        f"trimap {cloud_photo.small_trimap.name} ({WIDTH // 2} \u00d7 {HEIGHT // 2}), "
        f"not the layer's {WIDTH} \u00d7 {HEIGHT}"
    )
    chooser.set_input_files(cloud_photo.trimap)
    web.soon(items.nth(1)).to_contain_text(
        f"trimap {cloud_photo.trimap.name} ({WIDTH} \u00d7 {HEIGHT})"
    )
    # Reordered, the trimap stays with its layer (now the first).
    web.page.get_by_role("button", name=f"Move {cloud_photo.photo.name} earlier").click()
    web.soon(items.nth(0)).to_contain_text(f"trimap {cloud_photo.trimap.name}")
    web.soon(items.nth(1)).to_contain_text("has alpha")
    web.page.get_by_role("button", name=f"Move {cloud_photo.photo.name} later").click()
    web.soon(items.nth(1)).to_contain_text(f"trimap {cloud_photo.trimap.name}")
    unlabelled = web.page.evaluate(UNLABELLED_JS)
    assert unlabelled == [], f"controls without an accessible label: {unlabelled}"
    web.options(**MATTE_OPTIONS)

    job_id = web.run()
    web.wait_image("#result-image", (SPHERE, SPHERE))
    assert sent(web)[-1].endswith("/matte?wait=0"), sent(web)
    assert sent_parts(web, "layer") == [CLOUD.read_bytes(), cloud_photo.photo.read_bytes()]
    assert sent_parts(web, "trimap") == [b"", cloud_photo.trimap.read_bytes()]
    with server.client() as client:
        status = client.get(f"/jobs/{job_id}").json()
    assert (status["operation"], status["status"]) == ("matte", "done"), status
    extracted = status["stats"]["extracted"]
    assert len(extracted) == 2 and extracted[0] is None, extracted
    shown = figures(web)
    assert shown["matting (layer 2)"] == extracted[1]["method"], shown
    unknown = f"{100 * extracted[1]['unknown']:.1f} % of the photo"
    assert shown["unknown (layer 2)"] == unknown, shown

    web.page.get_by_role("button", name=f"Take the trimap off {cloud_photo.photo.name}").click()
    web.soon(items.nth(1)).to_contain_text("its trimap extracts its alpha first")
    web.soon(chooser).to_be_focused()
    web.console.assert_clean()
