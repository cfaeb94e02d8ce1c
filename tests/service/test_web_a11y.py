"""An accessibility check of the web page (client/web): axe-core finds no WCAG A/AA violation.

The page is opened from a real ``quilting serve`` process in headless Chromium, as in
test_web_page.py (whose fixtures and :class:`WebPage` steps these tests reuse), brought into
each state a person meets (every operation with "More options" open, textures chosen, a
result with its seams and tiled view, an error, a phone's width, the dark colour scheme), and
checked there by axe-core's rules tagged WCAG 2.0/2.1/2.2 level A and AA.

axe-core is vendored for these tests alone in ``tests/service/vendor/axe-core/`` (see its
README.md): the page never loads it. It is injected as a script tag, so the page's
Content-Security-Policy (this service alone) is bypassed in the tests' browser contexts.

A failure lists each violation's rule, impact and help, with the first elements it found
(their CSS selectors and HTML), so that it says what to fix.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import test_web_page
from service_helpers import DATA, Server
from test_web_extract import open_alpha
from test_web_page import TILED, WebPage, wait_thumbnails

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
open_page = test_web_page.open_page

pytestmark = pytest.mark.browser

AXE = Path(__file__).parent / "vendor" / "axe-core" / "axe.min.js"

#: axe-core's tags of the WCAG success criteria of levels A and AA (2.0, 2.1 and 2.2).
WCAG_TAGS = ["wcag2a", "wcag2aa", "wcag21a", "wcag21aa", "wcag22aa"]

#: Fewer rules passing than this means axe checked next to nothing (a blank page, say).
MIN_PASSES = 15

#: How many elements of each violation a failure shows.
SHOWN_NODES = 5

GRAVEL = DATA / "gravel.png"  # 256 x 256, gray
GRASS = DATA / "grass.png"  # 256 x 256, gray
WOOD = DATA / "wood.png"  # 136 x 136, RGB
SIZE = (96, 96)  # a small job: gravel at 96 x 96, block 24
JOB = {"width": SIZE[0], "height": SIZE[1], "block": 24, "seed": 3, "backend": "fft"}

#: The operations' radios, by their labels.
OPERATIONS = {
    "synthesize": "Synthesize",
    "transfer": "Transfer",
    "tile": "Make tileable",
    "matte": "Lay on a surface (matting)",
    "fill": "Fill a hole",
    "extend": "Extend (uncrop)",
    "wang": "Wang tiles",
}

#: Runs axe on the whole document; what a report needs of its result.
AXE_RUN_JS = """async (tags) => {
  const result = await axe.run(document, {runOnly: {type: 'tag', values: tags}});
  return {
    version: axe.version,
    passes: result.passes.length,
    incomplete: result.incomplete.map((r) => r.id),
    violations: result.violations.map((v) => ({
      id: v.id,
      impact: v.impact,
      help: v.help,
      tags: v.tags.filter((t) => t.startsWith('wcag')),
      nodes: v.nodes.map((n) => ({
        target: n.target.map(String).join(' '),
        html: n.html,
        summary: n.failureSummary || '',
      })),
    })),
  };
}"""


def report(state: str, violations: list[dict[str, Any]]) -> str:
    """What a failure says: each violation with the first few elements it was found on."""
    lines = [f"{state}: {len(violations)} accessibility violation(s) (axe-core, WCAG A/AA)"]
    for violation in violations:
        nodes = violation["nodes"]
        lines.append(
            f"- {violation['id']} ({violation['impact']}; {', '.join(violation['tags'])}): "
            f"{violation['help']} — {len(nodes)} element(s)"
        )
        for node in nodes[:SHOWN_NODES]:
            summary = " ".join(node["summary"].split())
            lines.append(f"    {node['target']}\n      {node['html'][:300]}\n      {summary[:300]}")
        if len(nodes) > SHOWN_NODES:
            lines.append(f"    ... and {len(nodes) - SHOWN_NODES} more")
    return "\n".join(lines)


def check(web: WebPage, state: str) -> dict[str, Any]:
    """Run axe-core on the page as it is now; fail with a report of every violation."""
    if not web.page.evaluate("() => typeof window.axe === 'object'"):
        web.page.add_script_tag(path=str(AXE))
    result: dict[str, Any] = web.page.evaluate(AXE_RUN_JS, WCAG_TAGS)
    assert not result["violations"], report(state, result["violations"])
    assert result["passes"] >= MIN_PASSES, (
        f"{state}: axe-core {result['version']} passed only {result['passes']} rules: "
        "did it check the page?"
    )
    return result


def open_checked(open_page: Callable[..., WebPage], server: Server, **options: Any) -> WebPage:
    """The page, in a context that lets the test inject axe-core despite the page's CSP."""
    return open_page(server, bypass_csp=True, **options)


def more_options(web: WebPage) -> None:
    """Open "More options" (if it is not open already)."""
    if not web("#more-options").evaluate("e => e.open"):
        web("#more-options > summary").click()
    web.soon("#extra-options").to_be_visible()


def small_job(web: WebPage) -> None:
    """Synthesize gravel at 96 x 96 (block 24) and wait for the result."""
    web.upload("#texture", GRAVEL)
    web.options(**JOB)
    web.run()
    web.wait_image("#result-image", SIZE)


# --- tests --------------------------------------------------------------------------------------


@pytest.mark.parametrize("scheme", ["light", "dark"])
def test_fresh_page(server: Server, open_page: Callable[..., WebPage], scheme: str) -> None:
    web = open_checked(open_page, server, color_scheme=scheme)
    result = check(web, f"the fresh page ({scheme})")
    assert result["version"].startswith("4."), result["version"]
    web.console.assert_clean()


@pytest.mark.parametrize("operation", list(OPERATIONS))
def test_each_operation_with_more_options(
    server: Server, open_page: Callable[..., WebPage], operation: str
) -> None:
    web = open_checked(open_page, server)
    web.operation(OPERATIONS[operation])
    more_options(web)
    check(web, f"{operation} with more options open")
    web.console.assert_clean()


def test_textures_chosen(server: Server, open_page: Callable[..., WebPage]) -> None:
    """Two textures: thumbnails, weights, move and remove buttons, block presets."""
    web = open_checked(open_page, server)
    web.upload("#texture", GRAVEL, GRASS)
    wait_thumbnails(web, 2)
    web.soon(".preset").not_to_have_count(0)
    check(web, "two textures chosen")
    web.console.assert_clean()


def test_fill_and_alpha_painters_with_an_image(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    """The painters' canvases over their images: a fill's mask and a photo's scribbles (the
    alpha panel folded, then opened)."""
    web = open_checked(open_page, server)
    web.operation(OPERATIONS["fill"])
    web.upload("#texture", WOOD)
    web.soon("#mask-editor").to_be_visible()
    check(web, "fill with an image to paint on")
    web.operation(OPERATIONS["synthesize"])
    web.soon("#alpha-summary").to_be_visible()
    check(web, "synthesize with the alpha panel folded")
    open_alpha(web)
    web.soon("#scribble-editor").to_be_visible()
    check(web, "synthesize with a photo to paint scribbles on")
    web.console.assert_clean()


@pytest.mark.parametrize("scheme", ["light", "dark"])
def test_result_with_seams_and_tiled(
    server: Server, open_page: Callable[..., WebPage], scheme: str
) -> None:
    web = open_checked(open_page, server, color_scheme=scheme)
    small_job(web)
    seams = web.page.get_by_role("checkbox", name="Show seams")
    web.soon(seams).to_be_enabled()
    seams.check()
    web.wait_image("#seam-overlay", SIZE)
    web.soon("#downloads").to_be_visible()
    check(web, f"a result with its seams shown ({scheme})")
    web.page.get_by_role("radio", name=TILED, exact=True).check()
    web.soon("#tiled").to_be_visible()
    check(web, f"a result in the tiled view ({scheme})")
    web.console.assert_clean()


@pytest.mark.parametrize("width", [1280, 375])
def test_wang_result_and_preview(
    server: Server, open_page: Callable[..., WebPage], width: int
) -> None:
    """A Wang tile set: the atlas, the preview's canvas fitted and at its actual size (6 x 64
    pixels: wider than a phone's screen, so its box scrolls there)."""
    web = open_checked(open_page, server, viewport={"width": width, "height": 800})
    web.operation(OPERATIONS["wang"])
    web.upload("#texture", GRAVEL)
    web.options(tile=64, block=16, seed=5, backend="fft")
    web.run()
    web.wait_image("#result-image", (4 * 64, 4 * 64))
    web.soon("#wang").to_be_visible()
    check(web, f"a Wang tile set with its preview, {width} px wide")
    web.page.get_by_role("checkbox", name="Actual size").check()
    check(web, f"a Wang tile set's preview at its actual size, {width} px wide")
    web.console.assert_clean()


def test_error_shown(server: Server, open_page: Callable[..., WebPage], tmp_path: Path) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("A texture is a picture, not these words about one.\n" * 20)
    web = open_checked(open_page, server)
    web.upload("#texture", notes)
    web.options(width=SIZE[0], height=SIZE[1])
    web.start()
    web.wait_final()
    web.soon("#error").to_contain_text("415")
    check(web, "the service's 415 shown")
    web.console.assert_clean(http_errors=True)


def test_narrow_screen(server: Server, open_page: Callable[..., WebPage]) -> None:
    web = open_checked(open_page, server, viewport={"width": 375, "height": 800})
    check(web, "the fresh page, 375 px wide")
    more_options(web)
    small_job(web)
    check(web, "a result, 375 px wide")
    web.console.assert_clean()
