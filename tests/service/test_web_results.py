"""End-to-end tests of how the web page explains a result, in headless Chromium: the job's
figures in words with what they mean, the seam overlay downloadable under the service's name,
companion maps as thumbnails, and a tileable result shown tiled 3 x 3 at once.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright; what the page says is checked against the
job's status document and files over plain HTTP.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
import test_web_page
from service_helpers import DATA, Server, png_image, texture
from test_web_page import UI_S, WebPage

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
open_page = test_web_page.open_page

pytestmark = pytest.mark.browser

GRAVEL = DATA / "gravel.png"  # 256 x 256
WOOD = DATA / "wood.png"  # 136 x 136


def figure(web: WebPage, label: str) -> tuple[str, str]:
    """The value and the meaning shown for the figure ``label`` (its <dt>)."""
    term = web.page.locator("#stats dt", has_text=re.compile(f"^{re.escape(label)}$"))
    value = term.locator("xpath=following-sibling::dd[1]")
    web.soon(value).to_be_visible()
    meaning = value.locator(".meaning")
    said = meaning.text_content() if meaning.count() else ""
    whole = value.text_content() or ""
    return whole[: len(whole) - len(said or "")], said or ""


def test_figures_in_words_seams_download_and_companion_thumbnails(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """A synthesis's figures read as words with their units and meaning, each the job's own
    number; the seam overlay downloads under the service's name with the service's bytes;
    the companion map is a thumbnail in its download link."""
    height_map = tmp_path / "height.png"
    height_map.write_bytes(texture("grass"))  # 256 x 256, as gravel
    web = open_page(server)
    web.upload("#texture", GRAVEL)
    web.upload("#companions", height_map)
    web.options(width=160, height=128, block=32, seed=5)
    job_id = web.run()
    web.wait_image("#result-image", (160, 128))
    status = httpx.get(f"{server.url}/jobs/{job_id}", timeout=30).json()
    stats = status["stats"]

    value, meaning = figure(web, "largest piece copied whole")
    share = stats["largest_copy"] * 100
    assert value == f"{share:.{1 if share < 10 else 0}f} % of the texture", (value, stats)
    assert "verbatim copy" in meaning
    value, meaning = figure(web, "never used")
    share = stats["unused"] * 100
    assert value == f"{share:.{1 if share < 10 else 0}f} % of the texture", (value, stats)
    assert "appear nowhere" in meaning
    value, meaning = figure(web, "seam mismatch")
    shown = web.page.evaluate("(x) => x.toPrecision(4)", stats["seam_error_mean"])
    assert value == f"{shown} per seam pixel", value
    assert meaning.startswith("The mean squared colour difference")
    # No raw stat names are left for a person to decode.
    labels = web("#stats dt").all_text_contents()
    assert not [label for label in labels if "_" in label], labels

    web.soon("#download-seams").to_be_visible()
    with web.page.expect_download(timeout=UI_S * 1000) as info:
        web("#download-seams").click()
    download = info.value
    seams = httpx.get(f"{server.url}/jobs/{job_id}/seams", timeout=30)
    assert seams.status_code == 200
    name = seams.headers["content-disposition"].split('filename="')[1].split('"')[0]
    assert download.suggested_filename == name
    assert name.startswith("gravel-synth-160x128-seed5") and name.endswith("-seams.png"), name
    assert Path(download.path()).read_bytes() == seams.content
    # The overlay the download fetched is the one laid over the result.
    web("#seams").check()
    web.soon("#seam-overlay").to_be_visible()

    link = web(".download-companion")
    web.soon(link.locator("img.thumb")).to_have_count(1)
    web.page.wait_for_function(
        """() => { const i = document.querySelector('.download-companion img.thumb');
          return i.complete && i.naturalWidth === 160 && i.naturalHeight === 128; }"""
    )
    assert (link.text_content() or "").strip() == "Download companion height"
    companion = web.download(".download-companion")
    assert png_image(companion).size == (160, 128)
    web.console.assert_clean()


def test_a_tileable_result_is_shown_tiled(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    """A tileable synthesis, and a tile of an image, open in the 3x3 view; a plain synthesis
    in the single one."""
    web = open_page(server)
    web.upload("#texture", WOOD)
    web.options(width=96, height=96, block=24, seed=1, tileable="both")
    web.run()
    web.wait_image("#result-image", (96, 96))
    web.soon('input[name="view"][value="tiled"]').to_be_checked()
    web.soon("#tiled").to_be_visible()
    web.option("tileable", "")
    web.run()
    web.wait_image("#result-image", (96, 96))
    web.soon('input[name="view"][value="tiled"]').to_be_checked()  # the view chosen stays
    web.page.get_by_role("radio", name="Result", exact=True).check()
    web.run()
    web.soon('input[name="view"][value="single"]').to_be_checked()
    web.soon("#tiled").to_be_hidden()

    web.operation("Make tileable")
    web.run()
    web.wait_image("#result-image", (136, 136))
    web.soon('input[name="view"][value="tiled"]').to_be_checked()
    web.console.assert_clean()


def test_fill_figures_say_how_much_was_filled(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """A fill's figures: the pixels filled, as a count and a share of the image."""
    from PIL import Image

    mask = tmp_path / "mask.png"
    pixels = Image.new("L", (136, 136), 0)
    pixels.paste(255, (40, 40, 80, 70))  # 40 x 30 = 1200 pixels
    pixels.save(mask)
    web = open_page(server)
    web.operation("Fill a hole")
    web.upload("#texture", WOOD)
    web.upload("#mask", mask)
    web.soon("#mask-file-info").to_contain_text("shown on the image")
    web.options(block=24, seed=2)
    web.run()
    web.wait_image("#result-image", (136, 136))
    value, meaning = figure(web, "pixels filled")
    assert value == f"1,200 ({1200 / 136**2 * 100:.1f} % of the image)", value
    assert "the image's own" in meaning
    web.console.assert_clean()


def test_figures_stack_on_a_narrow_screen(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    """On a phone's width each figure's name stands above its value and meaning, which have
    the panel's whole width; nothing scrolls sideways."""
    web = open_page(server, viewport={"width": 375, "height": 800})
    web.upload("#texture", WOOD)
    web.options(width=64, height=64, block=24, seed=1)
    web.run()
    web.wait_image("#result-image", (64, 64))
    term = web.page.locator("#stats dt", has_text=re.compile("^never used$"))
    value = term.locator("xpath=following-sibling::dd[1]")
    web.soon(value).to_be_visible()
    above, below = term.bounding_box(), value.bounding_box()
    assert above is not None and below is not None
    assert below["y"] >= above["y"] + above["height"] - 1, (above, below)
    assert abs(below["x"] - above["x"]) <= 1, (above, below)
    assert below["width"] >= 0.9 * web.box("#stats")["width"], (below, web.box("#stats"))
    assert web.overflow() <= 1
    web.console.assert_clean()
