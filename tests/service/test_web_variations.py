"""End-to-end tests of the web page's "Make 4 variations" in headless Chromium.

Like test_web_page.py (whose :class:`WebPage` steps these tests reuse): a real ``quilting
serve`` process, its page driven through Playwright. The four jobs the page submits at once
are checked against the service itself: each variation's download is the job's result and the
same bytes as a plain HTTP request with that seed gives (the service is deterministic for a
seed), under the service's own file name; keeping one puts its seed in the form and shows its
job as a Run's result; Cancel cancels all four on the service.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest
import test_web_page
from service_helpers import DATA, Server, png_image, synth
from test_web_page import FAST_JOB_S, UI_S, UNLABELLED_JS, WebPage

if TYPE_CHECKING:
    from playwright.sync_api import Locator, Route

# The browser fixtures of the page's tests, shared rather than written twice.
browser_available = test_web_page.browser_available
chromium = test_web_page.chromium
open_page = test_web_page.open_page

pytestmark = pytest.mark.browser

GRAVEL = DATA / "gravel.png"  # 256 x 256, gray
#: A small, quick job (the seed is left to the variations).
JOB = {"width": 96, "height": 96, "block": 24, "backend": "fft"}
VARIATIONS = 4
CELLS = "#variations-grid .variation"

#: True once every cell of the grid has ended (done, failed or cancelled).
ENDED_JS = """(count) => {
  const cells = [...document.querySelectorAll('#variations-grid .variation')];
  return cells.length === count &&
    cells.every((c) => ['done', 'failed', 'cancelled'].includes(c.dataset.status));
}"""


def gravel_page(open_page: Callable[..., WebPage], server: Server) -> WebPage:
    """The page of ``server`` with gravel chosen and the options of the small :data:`JOB`."""
    web = open_page(server)
    web.upload("#texture", GRAVEL)
    web.options(**JOB)
    return web


def make_variations(web: WebPage, timeout_s: float = FAST_JOB_S) -> str:
    """Click "Make 4 variations" and wait until the page says the work is over; #status."""
    web.record()
    web.page.get_by_role("button", name="Make 4 variations", exact=True).click()
    status = web.wait_final(timeout_s)
    web.page.wait_for_function(ENDED_JS, arg=VARIATIONS, timeout=UI_S * 1000)
    return status


def saved(web: WebPage, link: Locator) -> tuple[str, bytes]:
    """Click the download ``link``: the suggested file name and the bytes saved."""
    web.soon(link).to_be_visible()
    with web.page.expect_download(timeout=UI_S * 1000) as info:
        link.click()
    download = info.value
    assert download.failure() is None, download.failure()
    return download.suggested_filename, Path(download.path()).read_bytes()


def cell_statuses(web: WebPage) -> list[str]:
    """Each cell's ``data-status``: submitting, queued, running, done, failed, cancelled."""
    cells = web(CELLS)
    return [cells.nth(i).get_attribute("data-status") or "" for i in range(cells.count())]


def keep_and_wait(web: WebPage, keep: Callable[[], None]) -> None:
    """Keep a variation with ``keep()`` and wait until its result is shown ("done")."""
    web.record()
    keep()
    status = web.wait_final()
    assert status == "done", f"status {status!r}\n{web.state()}"


def seeds_and_ids(web: WebPage) -> tuple[list[int], list[str]]:
    cells = web(CELLS)
    seeds = [int(cells.nth(i).get_attribute("data-seed") or "-1") for i in range(VARIATIONS)]
    ids = [cells.nth(i).get_attribute("data-job") or "" for i in range(VARIATIONS)]
    return seeds, ids


def test_four_variations_are_the_service_s_results_for_four_seeds(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = gravel_page(open_page, server)
    button = web.page.get_by_role("button", name="Make 4 variations", exact=True)
    assert button.is_visible() and button.is_enabled()
    assert web("#variations").is_hidden()

    status = make_variations(web)
    assert status == f"done: {VARIATIONS} variations", f"status {status!r}\n{web.state()}"
    assert web("#variations").is_visible()
    assert web(CELLS).count() == VARIATIONS
    seeds, ids = seeds_and_ids(web)
    assert len(set(seeds)) == VARIATIONS, seeds
    assert all(0 <= seed < 2**31 for seed in seeds), seeds
    assert all(ids) and len(set(ids)) == VARIATIONS, ids
    for i, seed in enumerate(seeds):
        cell = web(CELLS).nth(i)
        assert f"seed {seed}" in (cell.locator(".variation-seed").text_content() or "")
        web.wait_image(f"{CELLS}:nth-child({i + 1}) .variation-image", (96, 96))
        assert cell.get_attribute("data-status") == "done"
    # The form's own seed is not sent: the main view shows nothing yet.
    assert web("#result-figure").is_hidden()

    results = []
    with server.client() as client:
        for i, (seed, job_id) in enumerate(zip(seeds, ids, strict=True)):
            name, png = saved(web, web(CELLS).nth(i).locator(".variation-download"))
            assert name == f"gravel-synth-96x96-seed{seed}.png", name
            stored = client.get(f"/jobs/{job_id}/result")
            assert stored.status_code == 200, stored.text[:300]
            assert png == stored.content, f"seed {seed}: the download is not the job's result"
            plain = synth(client, {**JOB, "seed": seed})
            assert plain.status_code == 200, plain.text[:300]
            assert png == plain.content, f"seed {seed}: not what a plain request gives"
            results.append(np.asarray(png_image(png)))
    for i in range(VARIATIONS):
        for j in range(i + 1, VARIATIONS):
            assert not np.array_equal(results[i], results[j]), f"variations {i} and {j} are equal"
    assert web.page.evaluate(UNLABELLED_JS) == []
    web.console.assert_clean()


def test_keeping_a_variation_sets_the_seed_and_shows_its_job(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = gravel_page(open_page, server)
    make_variations(web)
    seeds, ids = seeds_and_ids(web)

    # "Keep this one", from the keyboard.
    second = web(CELLS).nth(1)
    keep = web.page.get_by_role("button", name=f"Keep this one: seed {seeds[1]}", exact=True)
    assert keep.is_enabled()
    keep.focus()
    keep_and_wait(web, lambda: web.page.keyboard.press("Enter"))
    web.wait_image("#result-image", (96, 96))
    assert web("#opt-seed").input_value() == str(seeds[1])
    assert web.request_options()["seed"] == seeds[1]
    assert web.job_id() == ids[1]
    assert second.get_attribute("aria-current") == "true"
    _, kept = saved(web, second.locator(".variation-download"))
    assert web.download("#download-png") == kept
    # Shown as a Run's result: its seams and layout are the job's.
    seams = web.page.get_by_role("checkbox", name="Show seams")
    web.soon(seams).to_be_enabled()
    seams.check()
    web.wait_image("#seam-overlay", (96, 96))
    layout = json.loads(web.download("#download-layout"))
    assert layout["output_shape"] == [96, 96]

    # A click on a thumbnail keeps it too.
    keep_and_wait(web, web(CELLS).nth(3).locator(".variation-image").click)
    assert web("#opt-seed").input_value() == str(seeds[3])
    assert web.job_id() == ids[3]
    _, fourth = saved(web, web(CELLS).nth(3).locator(".variation-download"))
    web.soon("#download-png").to_be_visible()
    assert web.download("#download-png") == fourth
    assert second.get_attribute("aria-current") is None

    # Kept once another operation is chosen: the variations' operation and options come back.
    web.operation("Transfer")
    keep_and_wait(web, web(CELLS).nth(0).locator(".variation-keep").click)
    assert web.page.get_by_role("radio", name="Synthesize", exact=True).is_checked()
    assert web.request_options() == {**JOB, "seed": seeds[0]}
    assert web.job_id() == ids[0]
    web.wait_image("#result-image", (96, 96))
    # Each result kept is in the history, the last first.
    history = web("#history-list .history-entry")
    web.soon(history).to_have_count(3)
    listed = [history.nth(i).get_attribute("data-seed") for i in range(3)]
    assert listed == [str(seeds[0]), str(seeds[3]), str(seeds[1])], (listed, seeds)
    web.console.assert_clean()


def test_cancel_cancels_every_variation(
    start_server: Callable[[str, dict[str, str]], Server], open_page: Callable[..., WebPage]
) -> None:
    server = start_server("web-variations-cancel", {"QUILTING_WORKERS": "2"})
    web = gravel_page(open_page, server)
    # About a minute each with the direct-sum backend on a 2-core machine: all four are queued
    # or running when cancelled.
    web.options(width=800, height=800, block=32, backend="reference")
    web.record()
    web("#variations-run").click()
    ids: list[str] = []
    try:
        web.page.wait_for_function(
            """(count) => {
              const cells = [...document.querySelectorAll('#variations-grid .variation')];
              return cells.length === count && cells.every((c) => c.dataset.job);
            }""",
            arg=VARIATIONS,
            timeout=FAST_JOB_S * 1000,
        )
        _, ids = seeds_and_ids(web)
        # Busy as during a Run: nothing else starts, Cancel is there.
        for selector in ("#run", "#variations-run", "#extract"):
            assert web(selector).is_disabled(), selector
        assert web(CELLS).first.locator(".variation-keep").is_disabled()
        web.soon("#cancel").to_be_enabled()
        web("#cancel").click()
        status = web.wait_final()
        assert status.startswith("cancelled"), f"status {status!r}\n{web.state()}"
        web.page.wait_for_function(ENDED_JS, arg=VARIATIONS, timeout=UI_S * 1000)
        statuses = cell_statuses(web)
        assert statuses == ["cancelled"] * VARIATIONS, statuses
        with server.client() as client:
            on_service = [client.get(f"/jobs/{job_id}").json()["status"] for job_id in ids]
        assert on_service == ["cancelled"] * VARIATIONS, on_service
        for selector in ("#run", "#variations-run"):
            web.soon(selector).to_be_enabled()
        web.soon("#cancel").to_be_disabled()
    finally:
        with server.client() as client:
            for job_id in ids:
                client.delete(f"/jobs/{job_id}")
    web.console.assert_clean()


def test_a_failed_variation_shows_its_problem_and_the_others_still_show(
    server: Server, open_page: Callable[..., WebPage]
) -> None:
    web = gravel_page(open_page, server)
    detail = "the queue is full: try again in a minute"
    posts: list[int] = []

    def refuse_the_second(route: Route) -> None:
        """The service's refusal of the second of the four requests (a full queue)."""
        posts.append(1)
        if len(posts) != 2:
            route.continue_()
            return
        problem = {"type": "about:blank", "title": "Busy", "status": 503, "detail": detail}
        route.fulfill(
            status=503,
            content_type="application/problem+json",
            body=json.dumps({**problem, "code": "queue_full"}),
        )

    web.page.route(re.compile(r"/synthesize\?wait=0$"), refuse_the_second)
    status = make_variations(web)
    assert status == "done: 3 of 4 variations done, 1 failed", f"{status!r}\n{web.state()}"
    statuses = cell_statuses(web)
    assert sorted(statuses) == ["done", "done", "done", "failed"], statuses
    failed = web(f"{CELLS}[data-status='failed']")
    text = failed.locator(".variation-status").text_content() or ""
    assert detail in text and "queue_full" in text, text
    assert failed.locator(".variation-keep").is_disabled()
    assert failed.locator(".variation-download").is_hidden()
    for i, state in enumerate(statuses):
        if state == "done":
            web.wait_image(f"{CELLS}:nth-child({i + 1}) .variation-image", (96, 96))
    assert web("#error").is_hidden(), web.state()
    web.console.assert_clean(http_errors=True)


def test_no_variations_for_a_tile(server: Server, open_page: Callable[..., WebPage]) -> None:
    """Making an image tileable is answered with the image, not run as a job: no variations
    there; every operation run as a job with a seed has them."""
    web = open_page(server)
    button = web("#variations-run")
    web.operation("Make tileable")
    web.soon(button).to_be_hidden()
    for label in ("Transfer", "Fill a hole", "Extend (uncrop)", "Wang tiles"):
        web.operation(label)
        web.soon(button).to_be_visible()
    web.console.assert_clean()
