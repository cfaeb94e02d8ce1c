"""End-to-end tests of the web page's history of results in headless Chromium.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright. Every result the page shows is added to
the strip under it and kept in IndexedDB (database "quilting", store "history"): a reload
keeps it, its download is the job's result under the service's name, "Show" shows it again,
"Use these options again" puts its operation and options back into the form, "Remove" and
"Clear history" take entries out, and no more than ``MAX_ENTRIES`` are kept (checked through
the module's own ``add``, with small images, rather than 31 jobs).
"""

from __future__ import annotations

import json
from collections.abc import Callable

import pytest
import test_web_page
from service_helpers import Server, png_image
from test_web_page import UI_S, UNLABELLED_JS, WebPage
from test_web_variations import GRAVEL, JOB, saved

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
open_page = test_web_page.open_page

pytestmark = pytest.mark.browser

ENTRIES = "#history-list .history-entry"
MAX_ENTRIES = 30  # history.js's

#: ``count`` entries added through the page's own history (history.js), oldest first, each a
#: small PNG with its seed as its number.
ADD_JS = """async (count) => {
  const { pageHistory } = await import('/web/history.js');
  const history = pageHistory();
  for (let seed = 0; seed < count; seed += 1) {
    const canvas = new OffscreenCanvas(8, 6);
    const context = canvas.getContext('2d');
    context.fillStyle = `rgb(${seed * 8}, 100, 50)`;
    context.fillRect(0, 0, 8, 6);
    const result = await canvas.convertToBlob({ type: 'image/png' });
    await history.add({
      time: Date.now(), operation: 'synthesize', options: { width: 8, height: 6, seed },
      inputs: ['small.png'], result, resultName: `small-seed${seed}.png`, width: 8, height: 6,
      seed, stats: [], layout: null, layoutName: null, input: null, display: {},
    });
  }
}"""

#: Installed before the page's scripts: this browser has no IndexedDB (as some private
#: windows).
NO_INDEXEDDB_JS = (
    "Object.defineProperty(window, 'indexedDB', { value: undefined, configurable: true });"
)


def run_gravel(web: WebPage, seed: int) -> str:
    """Synthesize gravel 96 x 96 with ``seed``; the job id, once the result is shown."""
    web.options(**JOB, seed=seed)
    job_id = web.run()
    web.wait_image("#result-image", (96, 96))
    return job_id


def seeds_listed(web: WebPage) -> list[str]:
    entries = web(ENTRIES)
    return [entries.nth(i).get_attribute("data-seed") or "" for i in range(entries.count())]


def test_a_result_is_kept_across_a_reload(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = open_page(server)
    assert web("#history-list").is_hidden()
    assert web("#history-clear").is_disabled()
    web.upload("#texture", GRAVEL)
    job_id = run_gravel(web, 5)
    png = web.download("#download-png")
    entries = web(ENTRIES)
    web.soon(entries).to_have_count(1)
    entry = entries.first
    assert entry.get_attribute("data-seed") == "5"
    assert entry.get_attribute("data-operation") == "synthesize"
    caption = entry.locator(".history-caption").text_content() or ""
    assert "Synthesize, 96 \u00d7 96, seed 5" in caption and "gravel.png" in caption, caption
    web.wait_image(f"{ENTRIES} .history-thumb", (96, 96))

    web.page.reload()
    web("#opt-block").wait_for(state="attached", timeout=UI_S * 1000)
    web.soon(entries).to_have_count(1)
    assert "kept in this browser" in (web("#history-info").text_content() or "").lower()
    name, download = saved(web, entries.first.locator(".history-download"))
    assert name == "gravel-synth-96x96-seed5.png", name
    assert download == png
    with server.client() as client:
        assert download == client.get(f"/jobs/{job_id}/result").content

    # "Show": the stored result in the main view, its layout too, no seams (not kept).
    assert web("#result-figure").is_hidden()
    show = web.page.get_by_role("button", name="Show Synthesize, 96 \u00d7 96, seed 5", exact=False)
    show.click()
    web.wait_image("#result-image", (96, 96))
    assert web.download("#download-png") == png
    assert web("#download-png").get_attribute("download") == "gravel-synth-96x96-seed5.png"
    layout = json.loads(web.download("#download-layout"))
    assert layout["output_shape"] == [96, 96]
    assert web("#seams").is_disabled()
    assert "not kept" in (web("#seams-info").text_content() or "")
    assert web.page.evaluate(UNLABELLED_JS) == []
    web.console.assert_clean()


def test_use_these_options_again(server: Server, open_page: Callable[..., WebPage]) -> None:
    web = open_page(server)
    web.upload("#texture", GRAVEL)
    web.options(tileable="both", mode="cut")
    web("#opt-transforms").select_option("(other)")  # a list of transforms of one's own
    web("#opt-transforms-other").fill("rot90, flip_x")
    run_gravel(web, 7)
    sent = web.request_options()
    assert sent["seed"] == 7 and sent["tileable"] == "both", sent
    assert sent["transforms"] == "rot90,flip_x", sent
    reuse = web(f"{ENTRIES} .history-reuse")
    web.soon(reuse).to_have_count(1)
    # The entry says the options it was made with, beyond the size and seed of its caption.
    said = "; ".join(f"{k} {v}" for k, v in sent.items() if k not in {"width", "height", "seed"})
    assert "tileable both" in said and "transforms rot90,flip_x" in said, said
    web.soon(f"{ENTRIES} .history-options").to_have_text(said)

    # The same operation, other options: all back as sent (and what was not sent, default).
    web.options(width=200, height=150, seed=9, block=40, tileable="x", mode="auto", overlap=6)
    web("#opt-transforms").select_option("flips")
    assert web.request_options() != sent
    reuse.click()
    assert web.request_options() == sent
    for name, value in (("width", "96"), ("height", "96"), ("seed", "7"), ("block", "24")):
        assert web(f"#opt-{name}").input_value() == value, name
    assert web("#opt-tileable").input_value() == "both"
    assert web("#opt-overlap").input_value() == ""
    assert web("#opt-transforms").input_value() == "(other)"
    assert web("#opt-transforms-other").input_value() == "rot90, flip_x"
    assert web("#opt-transforms-other").is_visible()

    # Another operation: the entry's is chosen again, its options with it.
    web.operation("Make tileable")
    assert web("#opt-width").count() == 0  # the tile's own form: no size
    reuse.focus()
    web.page.keyboard.press("Enter")
    assert web.page.get_by_role("radio", name="Synthesize", exact=True).is_checked()
    assert web.request_options() == sent
    # Run again: the same bytes as the first run (the same options, the same seed).
    first = web(f"{ENTRIES} .history-download").first.get_attribute("href")
    assert first
    run_gravel(web, 7)
    entries = web(ENTRIES)
    web.soon(entries).to_have_count(2)
    _, again = saved(web, entries.nth(0).locator(".history-download"))
    _, before = saved(web, entries.nth(1).locator(".history-download"))
    assert again == before
    web.console.assert_clean()


def test_remove_and_clear(server: Server, open_page: Callable[..., WebPage]) -> None:
    web = open_page(server)
    web.upload("#texture", GRAVEL)
    run_gravel(web, 1)
    run_gravel(web, 2)
    web.operation("Make tileable")  # answered at once, not a job: kept too
    web.run()
    web.wait_image("#result-image", (256, 256))
    entries = web(ENTRIES)
    web.soon(entries).to_have_count(3)
    assert seeds_listed(web) == ["0", "2", "1"]  # newest first
    assert entries.first.get_attribute("data-operation") == "tile"

    # Remove the middle one (seed 2) from the keyboard: the focus moves to the next.
    remove = entries.nth(1).locator(".history-remove")
    remove.focus()
    web.page.keyboard.press("Enter")
    web.soon(entries).to_have_count(2)
    assert seeds_listed(web) == ["0", "1"]
    focused = web.page.evaluate(
        "() => document.activeElement.closest('.history-entry')?.dataset.seed ?? null"
    )
    assert focused == "1", focused
    web.page.reload()
    web("#opt-block").wait_for(state="attached", timeout=UI_S * 1000)
    web.soon(entries).to_have_count(2)
    assert seeds_listed(web) == ["0", "1"]

    web.page.get_by_role("button", name="Clear history", exact=True).click()
    web.soon(entries).to_have_count(0)
    web.soon("#history-list").to_be_hidden()
    web.soon("#history-clear").to_be_disabled()
    web.page.reload()
    web("#opt-block").wait_for(state="attached", timeout=UI_S * 1000)
    web.soon("#history-info").to_contain_text("added here")
    assert entries.count() == 0
    web.console.assert_clean()


def test_at_most_thirty_entries_the_oldest_dropped(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = open_page(server)
    web.soon("#history-info").to_contain_text("added here")
    web.page.evaluate(ADD_JS, MAX_ENTRIES + 1)
    entries = web(ENTRIES)
    web.soon(entries).to_have_count(MAX_ENTRIES)
    expected = [str(seed) for seed in range(MAX_ENTRIES, 0, -1)]  # seed 0 dropped
    assert seeds_listed(web) == expected
    web.page.reload()
    web("#opt-block").wait_for(state="attached", timeout=UI_S * 1000)
    web.soon(entries).to_have_count(MAX_ENTRIES)
    assert seeds_listed(web) == expected
    name, png = saved(web, entries.first.locator(".history-download"))
    assert name == f"small-seed{MAX_ENTRIES}.png"
    assert png_image(png).size == (8, 6)
    web.console.assert_clean()


def test_without_indexeddb_the_page_still_works(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = open_page(server)
    web.page.context.add_init_script(NO_INDEXEDDB_JS)
    web.page.reload()
    web("#opt-block").wait_for(state="attached", timeout=UI_S * 1000)
    assert web.page.evaluate("() => window.indexedDB") is None
    web.soon("#history-info").to_contain_text("does not keep the history")
    web.upload("#texture", GRAVEL)
    run_gravel(web, 4)
    web.soon(web(ENTRIES)).to_have_count(1)  # listed for as long as the page lasts
    assert "does not keep" in (web("#history-info").text_content() or "")
    web.console.assert_clean()
