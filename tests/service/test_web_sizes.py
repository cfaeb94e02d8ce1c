"""End-to-end tests of the web page's size and block helpers in headless Chromium: output size
presets (512, 1K, 2K, 4K), the texture's aspect and the lock that keeps it, and the block drawn
to scale on the texture as a square outline.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import test_web_page
from PIL import Image
from service_helpers import DATA, Server
from test_web_page import WebPage

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
open_page = test_web_page.open_page

pytestmark = pytest.mark.browser

GRAVEL = DATA / "gravel.png"  # 256 x 256


def wide_texture(path: Path, width: int = 300, height: int = 200) -> Path:
    """A 3 : 2 texture (noise, so that it is a texture the service takes)."""
    rng = np.random.default_rng(5)
    Image.fromarray(rng.integers(0, 256, (height, width, 3), dtype=np.uint8)).save(path)
    return path


def size_of(web: WebPage) -> tuple[int, int]:
    return int(web("#opt-width").input_value()), int(web("#opt-height").input_value())


def test_size_presets_and_the_texture_s_aspect(
    server: Server, open_page: Callable[..., WebPage], tmp_path: Path
) -> None:
    """A preset sets the size (square with the lock off); "Texture's aspect" makes the
    output the texture's proportions and locks them; a preset then keeps them, and typing one
    side sets the other; the request sent follows. Only a synthesis has an output size."""
    web = open_page(server)
    group = web.page.get_by_role("group", name="Output size:")
    web.soon(group).to_be_visible()
    web.soon("#size-aspect").to_be_disabled()  # no texture yet
    group.get_by_role("button", name="2K", exact=True).click()
    assert size_of(web) == (2048, 2048)
    assert {k: web.request_options()[k] for k in ("width", "height")} == {
        "width": 2048,
        "height": 2048,
    }
    web.soon("#size-info").to_have_text("2048 \u00d7 2048, 4.2 megapixels, 1.00 : 1")

    web.upload("#texture", wide_texture(tmp_path / "wide.png"))
    web.soon("#size-aspect").to_be_enabled()
    web("#size-aspect").click()
    assert web("#size-lock").is_checked()
    assert size_of(web) == (2048, 1365)  # the longer side kept, 3 : 2
    group.get_by_role("button", name="1K", exact=True).click()
    assert size_of(web) == (1024, 683)
    web("#opt-width").fill("600")  # typed: the height follows
    assert size_of(web) == (600, 400)
    web("#opt-height").fill("300")
    assert size_of(web) == (450, 300)
    assert {k: web.request_options()[k] for k in ("width", "height")} == {
        "width": 450,
        "height": 300,
    }
    web.soon("#size-info").to_contain_text("1.50 : 1 (kept)")

    web("#size-lock").uncheck()  # the lock off: each side on its own, presets square
    web("#opt-width").fill("700")
    assert size_of(web) == (700, 300)
    group.get_by_role("button", name="512", exact=True).click()
    assert size_of(web) == (512, 512)
    # A lock turned on keeps the proportions the fields have then.
    web("#opt-width").fill("800")
    web("#opt-height").fill("200")
    web("#size-lock").check()
    group.get_by_role("button", name="4K", exact=True).click()
    assert size_of(web) == (4096, 1024)

    web.operation("Transfer")  # the target gives the size: no presets
    web.soon("#size-presets").to_be_hidden()
    web.operation("Synthesize")
    web.soon("#size-presets").to_be_visible()
    web.console.assert_clean()


def outline_scale(web: WebPage) -> float:
    """The outline's side over the shown texture's width (the block over the texture's)."""
    scale: float = web.page.evaluate(
        """() => {
          const outline = document.querySelector('#block-outline').getBoundingClientRect();
          const image = document.querySelector('#block-view .block-texture')
            .getBoundingClientRect();
          return outline.width / image.width;
        }"""
    )
    return scale


def test_the_block_is_drawn_on_the_texture(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    """The block field's size is a square outline on the texture, to scale; a preset under the
    pointer or the focus shows its block, and leaving it shows the field's again."""
    web = open_page(server)
    web.soon("#block-view").to_be_hidden()  # no texture: nothing to draw on
    web.upload("#texture", GRAVEL)
    web.soon("#block-view").to_be_visible()
    web.page.wait_for_function(
        "() => document.querySelector('#block-view .block-texture').naturalWidth === 256"
    )
    web.option("block", 64)
    web.soon("#block-caption").to_have_text(
        "A block of 64 \u00d7 64 px on gravel.png (256 \u00d7 256), 25 % of its shorter side"
    )
    assert outline_scale(web) == pytest.approx(64 / 256, abs=0.02)
    box = web.box("#block-outline")
    assert box["width"] == pytest.approx(box["height"], abs=1), "the outline is not square"

    coarse = web.page.locator("button.preset", has_text="Coarse")  # a third of 256: 85
    coarse.hover()
    web.soon("#block-caption").to_contain_text("A block of 85 \u00d7 85 px")
    web.soon("#block-caption").to_contain_text("(preset)")
    assert outline_scale(web) == pytest.approx(85 / 256, abs=0.02)
    web("#opt-seed").hover()
    web.soon("#block-caption").not_to_contain_text("(preset)")
    assert outline_scale(web) == pytest.approx(64 / 256, abs=0.02)
    fine = web.page.locator("button.preset", has_text="Fine")  # an eighth: 32
    fine.focus()
    web.soon("#block-caption").to_contain_text("A block of 32 \u00d7 32 px")
    web.page.keyboard.press("Enter")  # chosen: the field's block now
    web("#opt-seed").focus()
    assert web("#opt-block").input_value() == "32"
    web.soon("#block-caption").to_have_text(
        "A block of 32 \u00d7 32 px on gravel.png (256 \u00d7 256), 13 % of its shorter side"
    )
    web.option("block", 300)
    web.soon("#block-caption").to_contain_text("larger than the texture")
    web.option("block", "")  # no number: nothing drawn
    web.soon("#block-outline").to_be_hidden()
    web.console.assert_clean()
