"""End-to-end tests of the web page's several textures (``POST /synthesize`` with the
``texture`` part repeated, ``transforms``, ``weights``) and Wang tiles (``POST /wang-tiles``)
in headless Chromium.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright. What the page sent is read back from the
``FormData`` it gave ``fetch`` (test_web_fill.py's recorder); its results are compared with
the job's files and with the service's answer to the same request over plain HTTP. The Wang
preview is checked cell by cell: its arrangement (``data-arrangement`` on the canvas) obeys
the edge rule of the manifest, and every cell's pixels are its tile's in the atlas.
"""

from __future__ import annotations

import base64
import io
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import test_web_fill
import test_web_page
from PIL import Image
from service_helpers import DATA, Server, png_image
from test_web_fill import sent, sent_part
from test_web_page import OUTSIDE_THE_FORM, UNLABELLED_JS, WebPage, wait_thumbnails

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
# The page recording what it sends, as the fill tests open it.
open_sent_page = test_web_fill.open_sent_page

pytestmark = pytest.mark.browser

WANG = "Wang tiles"  # the operation's radio
GRAVEL = DATA / "gravel.png"  # 256 x 256, gray
GRASS = DATA / "grass.png"  # 256 x 256, gray
BRICK = DATA / "brick.png"  # 256 x 256, gray
PREVIEW_TILES = 6  # the preview is 6 x 6 tiles

#: Every part of a name in the ``index``-th FormData sent, in order: base64 of each.
PARTS_JS = """async ([index, name]) => {
  const parts = window.__quiltingSent.at(index).body.getAll(name);
  return Promise.all(parts.map((part) => new Promise((resolve, reject) => {
    if (typeof part === 'string') return resolve(btoa(part));
    const reader = new FileReader();
    reader.onload = () => resolve(reader.result.slice(reader.result.indexOf(',') + 1));
    reader.onerror = () => reject(reader.error);
    reader.readAsDataURL(part);
  })));
}"""

#: The preview canvas: its size, seed, arrangement and pixels (a PNG data URL).
CANVAS_JS = """() => {
  const canvas = document.querySelector('#wang-preview');
  return {
    width: canvas.width,
    height: canvas.height,
    seed: canvas.dataset.seed,
    arrangement: JSON.parse(canvas.dataset.arrangement || 'null'),
    png: canvas.toDataURL('image/png'),
  };
}"""


# --- helpers ------------------------------------------------------------------------------------


def sent_parts(web: WebPage, name: str, index: int = -1) -> list[bytes]:
    """The bytes of every part ``name`` of the ``index``-th multipart request, in order."""
    data: list[str] = web.page.evaluate(PARTS_JS, [index, name])
    return [base64.b64decode(part) for part in data]


def post_over_http(
    server: Server, path: str, textures: list[Path], options: dict[str, Any]
) -> httpx.Response:
    """``POST path?wait=60`` with one ``texture`` part per file, as plain HTTP."""
    files = [("texture", (p.name, p.read_bytes(), "image/png")) for p in textures]
    with server.client() as client:
        return client.post(
            path, params={"wait": 60}, files=files, data={"options": json.dumps(options)}
        )


def job_file(server: Server, path: str) -> httpx.Response:
    with server.client() as client:
        response = client.get(path)
    assert response.status_code == 200, (path, response.status_code, response.text[:300])
    return response


def texture_names(web: WebPage) -> list[str]:
    """The names the texture list shows, in order."""
    return [
        re.sub(r" \(.*\)$", "", text)
        for text in web("#textures-order .texture-name").all_text_contents()
    ]


def canvas(web: WebPage) -> dict[str, Any]:
    state: dict[str, Any] = web.page.evaluate(CANVAS_JS)
    return state


def assert_edges_agree(arrangement: list[list[int]], manifest: dict[str, Any]) -> None:
    """Every cell's north edge is the south edge of the tile above, its west edge the east
    edge of the tile on its left (the colours of the manifest)."""
    tiles = {entry["index"]: entry for entry in manifest["tiles"]}
    assert len(arrangement) == PREVIEW_TILES, arrangement
    for i, row in enumerate(arrangement):
        assert len(row) == PREVIEW_TILES, arrangement
        for j, index in enumerate(row):
            assert index in tiles, f"cell ({i}, {j}): no tile {index} in the manifest"
            if i > 0:
                above = tiles[arrangement[i - 1][j]]
                assert tiles[index]["n"] == above["s"], (
                    f"cell ({i}, {j}): north {tiles[index]['n']} under south {above['s']}"
                )
            if j > 0:
                left = tiles[row[j - 1]]
                assert tiles[index]["w"] == left["e"], (
                    f"cell ({i}, {j}): west {tiles[index]['w']} beside east {left['e']}"
                )


def assert_cells_are_tiles(
    preview: np.ndarray, atlas: np.ndarray, arrangement: list[list[int]], manifest: dict[str, Any]
) -> None:
    """Every cell of the preview is its tile's pixels in the atlas (gray: on R, G and B)."""
    t = manifest["tile"]
    tiles = {entry["index"]: entry for entry in manifest["tiles"]}
    if atlas.ndim == 2:
        atlas = np.repeat(atlas[..., None], 3, axis=-1)
    for i, row in enumerate(arrangement):
        for j, index in enumerate(row):
            x, y = tiles[index]["x"], tiles[index]["y"]
            cell = preview[i * t : (i + 1) * t, j * t : (j + 1) * t, :3]
            assert np.array_equal(cell, atlas[y : y + t, x : x + t, :3]), (
                f"cell ({i}, {j}) is not tile {index} of the atlas"
            )


# --- several textures ---------------------------------------------------------------------------


def test_two_textures_send_two_parts_with_weights_and_transforms(
    server: Server, open_sent_page: Callable[..., WebPage]
) -> None:
    """Three textures chosen, the last removed: two thumbnails in order, each with its weight;
    a weight that is no number > 0 is refused on the page; the run sends one ``texture`` part
    per texture, in order, and the weights as an array; the result has the requested size and
    is the service's answer to the same request."""
    web = open_sent_page(server)
    assert web("#texture").evaluate("e => e.multiple"), "the synthesis takes one texture only"
    web.upload("#texture", GRAVEL, GRASS, BRICK)
    wait_thumbnails(web, 3)
    assert texture_names(web) == ["gravel.png", "grass.png", "brick.png"]
    web.page.get_by_role("button", name="Remove brick.png", exact=True).click()
    wait_thumbnails(web, 2)
    assert texture_names(web) == ["gravel.png", "grass.png"]
    assert web("#texture").evaluate("e => [...e.files].map((f) => f.name)") == [
        "gravel.png",
        "grass.png",
    ]
    web.soon("#texture-info").to_contain_text("2 textures")
    web.soon(".texture-weight").to_have_count(2)
    assert web.page.evaluate(UNLABELLED_JS) == []

    options = {"width": 200, "height": 160, "block": 32, "seed": 3, "backend": "fft"}
    web.options(**options)
    web.option("transforms", "rotations")
    web.page.get_by_label("Weight of gravel.png").fill("-1")
    web("#run").click()
    web.soon("#error").to_contain_text("weights")
    web.soon("#texture-weight-0").to_be_focused()
    assert sent(web) == [], "a weight below 0 was sent"

    web.page.get_by_label("Weight of gravel.png").fill("3")
    expected = {**options, "transforms": "rotations", "weights": [3, 1]}
    assert web.request_options() == expected
    job_id = web.run()
    web.wait_image("#result-image", (200, 160))
    assert web("#error").is_hidden(), web.state()
    assert sent(web)[-1].endswith("/synthesize?wait=0"), sent(web)
    assert sent_parts(web, "texture") == [GRAVEL.read_bytes(), GRASS.read_bytes()]
    assert json.loads(sent_part(web, "options") or b"") == expected

    png = web.download("#download-png")
    assert png_image(png).size == (200, 160)
    assert png == job_file(server, f"/jobs/{job_id}/result").content
    again = post_over_http(server, "/synthesize", [GRAVEL, GRASS], expected)
    assert again.status_code == 200, again.text[:300]
    assert png == again.content, "the page's result differs from the service's for its request"
    web.console.assert_clean()


def test_texture_list_moves_fits_and_single_texture_operations(
    server: Server, open_sent_page: Callable[..., WebPage]
) -> None:
    """The list's order can change (the weights move with their textures); it fits a phone's
    width; an operation that takes one texture hides it and says it uses the first; one
    texture has no weight; the transforms' menu offers the presets and names typed."""
    web = open_sent_page(server, viewport={"width": 380, "height": 800})
    web.upload("#texture", GRAVEL, GRASS)
    wait_thumbnails(web, 2)
    web.page.get_by_label("Weight of grass.png").fill("2.5")
    web.page.get_by_role("button", name="Move grass.png earlier", exact=True).click()
    wait_thumbnails(web, 2)
    assert texture_names(web) == ["grass.png", "gravel.png"]
    web.soon("#texture-weight-0").to_have_value("2.5")
    web.soon("#texture-weight-1").to_have_value("1")
    assert web.request_options().get("weights") == [2.5, 1]
    assert web.overflow() <= 1, "horizontal scroll with the texture list"

    web.operation("Transfer")  # one texture: only the first is shown, without a weight
    wait_thumbnails(web, 1)
    assert texture_names(web) == ["grass.png"]
    web.soon(".texture-weight").to_have_count(0)
    web.soon("#texture-info").to_contain_text("the first of the 2 chosen")
    assert "weights" not in web.request_options()
    web.operation("Synthesize")
    web.soon("#textures-order").to_be_visible()
    wait_thumbnails(web, 2)

    web.page.get_by_role("button", name="Remove gravel.png", exact=True).click()
    wait_thumbnails(web, 1)
    web.soon(".texture-weight").to_have_count(0)
    web.soon("#texture-info").to_contain_text("grass.png: 256 \u00d7 256")
    assert "weights" not in web.request_options()

    menu = web("#opt-transforms")
    assert menu.evaluate("e => e.tagName") == "SELECT"
    offered = menu.evaluate("e => [...e.options].map((o) => o.value)")
    assert offered[:4] == ["none", "flips", "rotations", "all"], offered
    assert "transforms" not in web.request_options()
    web.soon("#opt-transforms-other").to_be_hidden()
    menu.select_option(index=4)
    web.soon("#opt-transforms-other").to_be_visible()
    web("#opt-transforms-other").fill("rot90, flip_x")
    assert web.request_options().get("transforms") == "rot90,flip_x"
    assert web.page.evaluate(UNLABELLED_JS) == []
    web.console.assert_clean()


# --- Wang tiles ---------------------------------------------------------------------------------


def test_wang_tiles_atlas_preview_and_downloads(
    server: Server, open_sent_page: Callable[..., WebPage]
) -> None:
    """Wang tiles of gravel (2 colours, 64 px tiles): the atlas (4 x 4 tiles) is shown and is
    the job's result and the service's answer; the manifest downloads; the preview is a canvas
    of 6 x 64 pixels square whose cells obey the edge rule and are the atlas's tiles; a re-roll
    draws another arrangement and its seed brings it back."""
    schemas = httpx.get(server.url + "/openapi.json", timeout=30).json()["components"]["schemas"]
    assert "WangOptions" in schemas, "the service has no WangOptions schema (POST /wang-tiles)"
    web = open_sent_page(server)
    web.operation(WANG)
    for name in schemas["WangOptions"]["properties"]:
        expected_count = 0 if name in OUTSIDE_THE_FORM["WangOptions"] else 1
        web.soon(f"#opt-{name}").to_have_count(expected_count)
    assert web.page.evaluate(UNLABELLED_JS) == []
    assert web("#texture").evaluate("e => e.multiple")
    # The schema's multipleOf is the field's step: the browser offers even tiles only.
    assert schemas["WangOptions"]["properties"]["tile"]["multipleOf"] == 2
    assert web("#opt-tile").evaluate("e => [e.step, e.min]") == ["2", "16"]

    web.upload("#texture", GRAVEL)
    wait_thumbnails(web, 1)
    options = {"tile": 64, "block": 16, "seed": 5, "backend": "fft"}
    web.options(**options)
    assert web.request_options() == options
    job_id = web.run()
    tile, colors = 64, 2
    side = colors * colors * tile
    web.wait_image("#result-image", (side, side))
    assert web("#error").is_hidden(), web.state()
    assert sent(web)[-1].endswith("/wang-tiles?wait=0"), sent(web)
    assert sent_parts(web, "texture") == [GRAVEL.read_bytes()]
    assert json.loads(sent_part(web, "options") or b"") == options
    web.soon("#result-caption").to_contain_text("Atlas")

    # The atlas and the manifest: the job's, and the service's for the same request.
    atlas_png = web.download("#download-png")
    assert atlas_png == job_file(server, f"/jobs/{job_id}/result").content
    manifest_bytes = web.download("#download-manifest")
    manifest = json.loads(manifest_bytes)
    assert manifest == job_file(server, f"/jobs/{job_id}/manifest").json()
    assert (manifest["format"], manifest["tile"], manifest["colors"]) == (
        "quilting.wang",
        tile,
        colors,
    )
    assert len(manifest["tiles"]) == colors**4
    again = post_over_http(server, "/wang-tiles", [GRAVEL], options)
    assert again.status_code == 200, again.text[:300]
    assert atlas_png == again.content, "the page's atlas differs from the service's"
    atlas = np.asarray(png_image(atlas_png))

    # The preview: 6 x 6 tiles, the edge rule kept, each cell its tile.
    web.soon("#wang").to_be_visible()
    web.soon("#wang-preview").to_be_visible()
    first = canvas(web)
    assert (first["width"], first["height"]) == (PREVIEW_TILES * tile,) * 2, first["width"]
    assert first["seed"] == web("#wang-seed").input_value() == str(options["seed"])
    assert_edges_agree(first["arrangement"], manifest)
    assert len({i for row in first["arrangement"] for i in row}) > 1, first["arrangement"]
    pixels = np.asarray(
        Image.open(io.BytesIO(base64.b64decode(first["png"].split(",", 1)[1]))).convert("RGBA")
    )
    assert pixels.shape == (PREVIEW_TILES * tile, PREVIEW_TILES * tile, 4)
    assert (pixels[..., 3] == 255).all(), "the preview has transparent pixels"
    assert_cells_are_tiles(pixels, atlas, first["arrangement"], manifest)
    download = png_image(web.download("#download-preview"))
    assert download.size == (PREVIEW_TILES * tile,) * 2

    # Re-roll: another seed and arrangement, the rule kept; the first seed gives it back.
    web.page.get_by_role("button", name="Re-roll", exact=True).click()
    web.page.wait_for_function(
        "(seed) => document.querySelector('#wang-preview').dataset.seed !== seed",
        arg=first["seed"],
        timeout=15_000,
    )
    second = canvas(web)
    assert second["seed"] == web("#wang-seed").input_value()
    assert second["arrangement"] != first["arrangement"], "the re-roll drew the same tiles"
    assert_edges_agree(second["arrangement"], manifest)
    web("#wang-seed").fill(first["seed"])
    web("#wang-seed").dispatch_event("change")
    web.soon("#wang-preview").to_have_attribute("data-seed", first["seed"])
    assert canvas(web)["arrangement"] == first["arrangement"]

    # The atlas has no seams overlay, and its layout is the manifest (no second download).
    web.soon("#seams").to_be_disabled()
    web.soon("#layout-item").to_be_hidden()
    web.console.assert_clean()


def test_wang_tiles_of_two_textures_and_a_new_job(
    server: Server, open_sent_page: Callable[..., WebPage]
) -> None:
    """Two textures for a Wang set (3 colours, 64 px tiles) on a phone's screen: two parts
    sent, a 9 x 9 atlas and a 384 px preview obeying the rule, fitted to the screen or at its
    own size in a box that scrolls, never the page; running a synthesis afterwards hides the
    preview and the manifest's download."""
    web = open_sent_page(server, viewport={"width": 380, "height": 800})
    web.operation(WANG)
    web.upload("#texture", GRAVEL, GRASS)
    wait_thumbnails(web, 2)
    options = {"colors": 3, "tile": 64, "block": 16, "seed": 2, "backend": "fft"}
    web.options(**options)
    web.page.get_by_label("Weight of grass.png").fill("2")
    assert web.request_options() == {**options, "weights": [1, 2]}
    job_id = web.run()
    web.wait_image("#result-image", (9 * 64, 9 * 64))
    assert sent_parts(web, "texture") == [GRAVEL.read_bytes(), GRASS.read_bytes()]
    manifest = job_file(server, f"/jobs/{job_id}/manifest").json()
    assert len(manifest["tiles"]) == 81
    state = canvas(web)
    assert (state["width"], state["height"]) == (PREVIEW_TILES * 64,) * 2
    assert_edges_agree(state["arrangement"], manifest)
    web.soon("#manifest-item").to_be_visible()
    web("#wang-preview").scroll_into_view_if_needed()
    assert web.box("#wang-preview")["width"] < 380
    assert web.overflow() <= 1, "horizontal scroll with the Wang preview"
    web("#wang-actual").check()
    assert abs(web.box("#wang-preview")["width"] - PREVIEW_TILES * 64) <= 1
    assert web.overflow() <= 1, "horizontal scroll with the preview at its own size"

    web.operation("Synthesize")
    web.options(width=120, height=100, block=32)
    web.run()
    web.wait_image("#result-image", (120, 100))
    web.soon("#wang").to_be_hidden()
    web.soon("#manifest-item").to_be_hidden()
    web.soon("#download-png").to_have_text("Download PNG")
    web.console.assert_clean()
