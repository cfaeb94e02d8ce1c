"""Regenerate the screenshots of the browser page: ``examples/web_page.png`` (the README's)
and those of docs/web-page.md.

Starts ``quilting serve`` on a free loopback port the way a user does, opens the page in
Debian's headless Chromium through Playwright, launched as the tests launch it
(``tests/service/browser.py``: ``executable_path``, no browser download),
synthesizes 384x256 from ``examples/gravel.png`` with the Medium block preset and seed 7,
turns the seam overlay on and takes a screenshot of the whole page; then, in *Fill a hole*
mode, paints a stroke over ``tests/data/wood.png`` with the mouse and fills it
(``docs/images/web_fill.png``); last, in *Wang tiles* mode, makes a set of 2 colours and 96 px
tiles from ``examples/gravel.png`` (seed 4), its atlas and 6x6 preview on the page
(``docs/images/web_wang.png``); and, with ``examples/extract_photo.png`` as the texture,
opens the alpha panel, paints a few white and black scribbles over it and extracts its alpha
(``docs/images/web_alpha.png``); the form with its inputs' thumbnails, a size preset and
the block drawn on the texture (``docs/images/web_inputs.png``); and a tileable result in its
3 x 3 view with its figures in words (``docs/images/web_results.png``); four variations of
gravel (``docs/images/web_variations.png``); and the history after three runs and a reload
(``docs/images/web_history.png``). Run from the
repository root (needs
``pip install -e '.[dev]'`` and ``apt-get install chromium``)::

    .venv/bin/python examples/make_screenshot.py            # all of them
    .venv/bin/python examples/make_screenshot.py wang       # or some, by name (see --help)
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
from PIL import Image
from playwright.sync_api import Page, expect, sync_playwright
from scipy import ndimage

HERE = Path(__file__).resolve().parent
# Launched as the browser tests launch it (tests/service/browser.py: Debian's Chromium, flags
# for a sandbox without a display or outside network).
sys.path.insert(0, str(HERE.parent / "tests" / "service"))
from browser import CHROMIUM_ARGS, chromium_path  # noqa: E402


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def fresh(page: Page) -> None:
    """The page loaded anew with an empty history, its options form built (a screenshot
    starts from nothing)."""
    page.evaluate(
        """() => new Promise((resolve) => {
          const request = indexedDB.deleteDatabase('quilting');
          request.onsuccess = request.onerror = request.onblocked = () => resolve();
        })"""
    )
    page.reload()
    expect(page.locator("#job-form")).to_have_attribute("data-ready", "true")


def options(page: Page, **values: str) -> None:
    """Type each option's value in its field (``#opt-<name>``)."""
    for name, value in values.items():
        page.fill(f"#opt-{name}", value)


def fill_screenshot(page: Page, out: Path) -> None:
    """The page in *Fill a hole* mode: a stroke painted with the mouse over the wood image
    (brush 16 px), filled with seed 3, before and after side by side."""
    fresh(page)
    page.get_by_role("radio", name="Fill a hole", exact=True).check()
    page.set_input_files("#texture", HERE.parent / "tests" / "data" / "wood.png")
    expect(page.locator("#mask-editor")).to_be_visible()
    page.fill("#brush-size", "16")
    drag(page, "#mask-canvas", [(30, 40), (70, 60), (100, 95)])
    expect(page.locator("#mask-info")).to_contain_text("pixels to fill")
    page.fill("#opt-seed", "3")
    page.click("#run")
    expect(page.locator("#status")).to_have_text("done", timeout=60_000)
    page.screenshot(path=out, full_page=True)


def wang_screenshot(page: Page, out: Path) -> None:
    """The page in *Wang tiles* mode: gravel, 2 colours, 96 px tiles, seed 4; the atlas and
    its 6 x 6 preview."""
    fresh(page)
    page.get_by_role("radio", name="Wang tiles", exact=True).check()
    page.set_input_files("#texture", HERE / "gravel.png")
    expect(page.locator("#textures-order img")).to_have_count(1)
    options(page, tile="96", block="32", seed="4")
    page.click("#run")
    expect(page.locator("#status")).to_have_text("done", timeout=120_000)
    expect(page.locator("#wang-preview")).to_be_visible()
    page.screenshot(path=out, full_page=True)


def drag(page: Page, selector: str, points: list[tuple[float, float]]) -> None:
    """Drag the mouse over the painting canvas ``selector`` through ``points`` (in the
    image's own pixels)."""
    canvas = page.locator(selector)
    canvas.scroll_into_view_if_needed()
    box = canvas.bounding_box()
    assert box is not None
    scale = box["width"] / canvas.evaluate("c => c.width")
    page.mouse.move(box["x"] + points[0][0] * scale, box["y"] + points[0][1] * scale)
    page.mouse.down()
    for x, y in points[1:]:
        page.mouse.move(box["x"] + x * scale, box["y"] + y * scale, steps=12)
    page.mouse.up()


def inside(region: np.ndarray, count: int) -> list[tuple[int, int]]:
    """One (x, y) point in each of the ``count`` largest parts of ``region`` (a boolean map),
    at least 2 pixels inside it, the part's pixel nearest its centre: where a short stroke
    stays within what the trimap says."""
    parts, found = ndimage.label(ndimage.binary_erosion(region, iterations=2))
    sizes = ndimage.sum_labels(np.ones_like(parts), parts, range(1, found + 1))
    points = []
    for label in np.argsort(sizes)[::-1][:count] + 1:
        ys, xs = np.nonzero(parts == label)
        nearest = np.argmin((xs - xs.mean()) ** 2 + (ys - ys.mean()) ** 2)
        points.append((int(xs[nearest]), int(ys[nearest])))
    return points


def alpha_screenshot(page: Page, out: Path) -> None:
    """The cloud-over-grass photo (``examples/make_extract.py``) as the texture, its alpha
    panel opened (it is folded until then), white scribbles over the cloud's core and black
    ones over the grass (where the script's trimap says so), and *Extract alpha*: the RGBA
    texture beside the photo, said in words."""
    fresh(page)
    page.set_input_files("#texture", HERE / "extract_photo.png")
    page.click("#alpha-summary")
    expect(page.locator("#scribble-editor")).to_be_visible()
    page.fill("#scribble-size", "6")
    trimap = np.asarray(Image.open(HERE / "extract_trimap.png"))
    for brush, value, count in (("keep", 255, 8), ("remove", 0, 10)):
        page.check(f"input[name=scribble][value={brush}]")
        for x, y in inside(trimap == value, count):
            drag(page, "#scribble-canvas", [(x - 1, y), (x + 1, y + 1)])
    expect(page.locator("#scribble-info")).to_contain_text("to remove")
    page.click("#extract")
    expect(page.locator("#status")).to_have_text("done", timeout=120_000)
    page.screenshot(path=out, full_page=True)


def inputs_screenshot(page: Page, out: Path) -> None:
    """The form with its inputs shown: gravel as the texture and grass as a companion map (a
    thumbnail each, with size and depth), the 1K size preset, and the Coarse block preset
    under the pointer, drawn on the texture."""
    fresh(page)
    data = HERE.parent / "tests" / "data"
    page.set_input_files("#texture", HERE / "gravel.png")
    page.set_input_files("#companions", data / "grass.png")
    expect(page.locator("#companions-thumbs img")).to_have_count(1)
    page.get_by_role("button", name="1K", exact=True).click()
    page.locator("button.preset", has_text="Coarse").hover()
    expect(page.locator("#block-caption")).to_contain_text("(preset)")
    page.locator("#job-form").screenshot(path=out)


def results_screenshot(page: Page, out: Path) -> None:
    """A tileable synthesis of gravel (256 x 256, seed 2) with grass as a companion map: the
    3 x 3 view it opens in, the companion's thumbnail, and the figures in words."""
    fresh(page)
    data = HERE.parent / "tests" / "data"
    page.set_input_files("#texture", HERE / "gravel.png")
    page.set_input_files("#companions", data / "grass.png")
    options(page, width="256", height="256", seed="2")
    page.select_option("#opt-tileable", "both")
    page.click("#run")
    expect(page.locator("#status")).to_have_text("done", timeout=60_000)
    expect(page.locator("#tiled")).to_be_visible()
    page.locator("#result").screenshot(path=out)


def variations_screenshot(page: Page, out: Path) -> None:
    """*Make 4 variations* of gravel (160 x 160, block 40): the four seeds side by side under
    the result panel, each to download or keep."""
    fresh(page)
    page.set_input_files("#texture", HERE / "gravel.png")
    options(page, width="160", height="160", block="40")
    page.click("#variations-run")
    expect(page.locator(".variation-image")).to_have_count(4, timeout=120_000)
    page.locator("#variations").screenshot(path=out)


def history_screenshot(page: Page, out: Path) -> None:
    """The history strip after three runs (wood at seeds 1 to 3, one of them tileable) and a
    reload: kept in the browser, each to show, download or run again."""
    fresh(page)
    page.set_input_files("#texture", HERE.parent / "tests" / "data" / "wood.png")
    options(page, width="192", height="128")
    for seed in ("1", "2", "3"):
        page.fill("#opt-seed", seed)
        page.select_option("#opt-tileable", "both" if seed == "2" else "")
        page.click("#run")
        expect(page.locator("#history-list > li")).to_have_count(int(seed), timeout=60_000)
    page.reload()
    expect(page.locator("#history-list > li")).to_have_count(3)
    page.locator("#history").screenshot(path=out)


def page_screenshot(page: Page, out: Path) -> None:
    """The page after a synthesis of gravel (384x256, Medium preset, seed 7), seams shown."""
    fresh(page)
    page.set_input_files("#texture", HERE / "gravel.png")
    options(page, width="384", height="256", seed="7")
    page.get_by_role("button", name=re.compile("^Medium")).click()
    page.click("#run")
    expect(page.locator("#status")).to_have_text("done", timeout=60_000)
    page.check("#seams")
    expect(page.locator("#seam-overlay")).to_be_visible()
    page.screenshot(path=out, full_page=True)


#: Each screenshot: its name on the command line, the file and the steps that make it.
SCREENSHOTS = {
    "page": (HERE / "web_page.png", page_screenshot),
    "fill": (HERE.parent / "docs" / "images" / "web_fill.png", fill_screenshot),
    "wang": (HERE.parent / "docs" / "images" / "web_wang.png", wang_screenshot),
    "alpha": (HERE.parent / "docs" / "images" / "web_alpha.png", alpha_screenshot),
    "inputs": (HERE.parent / "docs" / "images" / "web_inputs.png", inputs_screenshot),
    "results": (HERE.parent / "docs" / "images" / "web_results.png", results_screenshot),
    "variations": (HERE.parent / "docs" / "images" / "web_variations.png", variations_screenshot),
    "history": (HERE.parent / "docs" / "images" / "web_history.png", history_screenshot),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "names", nargs="*", help=f"screenshots to make: {', '.join(SCREENSHOTS)} (default: all)"
    )
    names = parser.parse_args().names or list(SCREENSHOTS)
    unknown = [name for name in names if name not in SCREENSHOTS]
    if unknown:
        parser.error(f"no screenshot {', '.join(unknown)}; one of {', '.join(SCREENSHOTS)}")
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**os.environ, "QUILTING_WORKERS": "1", "QUILTING_BACKEND": "fft"}
    server = subprocess.Popen(
        [sys.executable, "-m", "quilting", "serve", "--port", str(port)], env=env
    )
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                if httpx.get(url + "/healthz").status_code == 200:
                    break
            except httpx.TransportError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(
                executable_path=chromium_path(), args=list(CHROMIUM_ARGS)
            )
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            page.goto(url)
            expect(page.locator("#job-form")).to_have_attribute("data-ready", "true")
            for name in names:
                out, make = SCREENSHOTS[name]
                make(page, out)
                print(f"wrote {out}")
            browser.close()
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
