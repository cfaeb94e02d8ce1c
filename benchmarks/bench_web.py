"""The web page's weight and speed: what a browser loads and how soon an artist can use it.

Starts ``quilting serve`` once and opens its page in Debian's headless Chromium (launched as
the browser tests launch it), for this checkout's ``client/web`` and, with ``--against REV``,
for that commit's (checked out in a temporary git worktree; its files are served in place of
this checkout's through Playwright's routing, so the same service answers both). For each:

- the page's files: how many, their bytes (HTML, CSS and JavaScript, no build step);
- ``ready ms``: from navigation to the options form built from ``/openapi.json``
  (``#job-form[data-ready]``), median of ``--repeat`` fresh loads, and its spread;
- ``result ms``: from the Run click to the result shown (a 128 x 128 gravel synthesis, block
  32), median of ``--repeat`` runs, and its spread: the page's own work around one small job.

The two trees are measured in alternation in one run, so that a busy moment hurts both alike.

Run: ``.venv/bin/python benchmarks/bench_web.py --against d6f220a``.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchtools import (
    ServeProcess,
    fmt,
    parser,
    service_machine,
    show_machine,
    table,
    wall_time,
    write_json,
)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "service"))
from browser import CHROMIUM_ARGS, chromium_path  # type: ignore[import-not-found]  # noqa: E402

GRAVEL = ROOT / "tests" / "data" / "gravel.png"
TYPES = {".js": "text/javascript", ".css": "text/css", ".html": "text/html"}


def page_files(web: Path) -> tuple[int, int]:
    """How many files the page is made of, and their bytes."""
    files = [p for p in web.iterdir() if p.suffix in TYPES]
    return len(files), sum(p.stat().st_size for p in files)


def serve_from(page: Any, web: Path) -> None:
    """Answer the page (``/``) and its files (``/web/...``) from the folder ``web``."""

    def answer(route: Any) -> None:
        path = route.request.url.split("?", 1)[0].split("/", 3)[3]
        name = "index.html" if path in ("", "index.html") else path.removeprefix("web/")
        file = web / name
        if not file.is_file():
            route.fulfill(status=404, body="not here")
            return
        route.fulfill(status=200, body=file.read_bytes(), content_type=TYPES[file.suffix])

    page.route(lambda url: url.split("?")[0].rstrip("/").count("/") == 2, answer)
    page.route("**/web/**", answer)


def load(browser: Any, url: str, web: Path) -> tuple[float, float]:
    """One fresh load of the page from ``web``: ms to ready, and ms from Run to the result."""
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    try:
        page = context.new_page()
        serve_from(page, web)
        page.goto(url + "/")
        page.wait_for_selector("#job-form[data-ready='true']", state="attached")
        ready = page.evaluate("() => performance.now()")
        page.set_input_files("#texture", GRAVEL)
        for name, value in (("width", "128"), ("height", "128"), ("block", "32"), ("seed", "1")):
            page.fill(f"#opt-{name}", value)
        page.wait_for_function(
            "() => document.querySelector('#texture-info').textContent.includes('256')"
        )
        started = time.perf_counter()
        page.click("#run")
        page.wait_for_function(
            """() => { const i = document.querySelector('#result-image');
              return document.querySelector('#status').textContent === 'done' &&
                i.complete && i.naturalWidth === 128; }""",
            timeout=120_000,
        )
        return float(ready), (time.perf_counter() - started) * 1000
    finally:
        context.close()


def main() -> int:
    args = parser(__doc__)
    args.add_argument("--against", help="also measure this commit's page (a temporary worktree)")
    args.add_argument("--repeat", type=int, default=7)
    options = args.parse_args()
    from playwright.sync_api import sync_playwright

    info = service_machine()
    show_machine(info)
    started = time.perf_counter()
    trees = {"this checkout": ROOT / "client" / "web"}
    scratch = tempfile.TemporaryDirectory()
    other = Path(scratch.name) / "tree"
    if options.against:
        subprocess.run(
            ["git", "worktree", "add", "-q", "--detach", str(other), options.against],
            cwd=ROOT,
            check=True,
        )
        trees[options.against] = other / "client" / "web"
    timings: dict[str, dict[str, list[float]]] = {n: {"ready": [], "result": []} for n in trees}
    try:
        with tempfile.TemporaryFile() as log, ServeProcess(log, workers=1) as server:
            server.wait_for("/healthz", 60)
            with sync_playwright() as playwright:
                browser = playwright.chromium.launch(
                    executable_path=chromium_path(), args=list(CHROMIUM_ARGS)
                )
                for web in trees.values():  # a first load each, not counted: caches
                    load(browser, server.url, web)
                for _ in range(options.repeat):
                    for name, web in trees.items():
                        ready, result = load(browser, server.url, web)
                        timings[name]["ready"].append(ready)
                        timings[name]["result"].append(result)
                browser.close()
        weights = {name: page_files(web) for name, web in trees.items()}
    finally:
        if options.against:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(other)], cwd=ROOT, check=False
            )
        scratch.cleanup()

    rows: list[list[str]] = []
    measured: dict[str, object] = {}
    for name in trees:
        count, size = weights[name]
        row = [name, str(count), f"{size / 1024:.1f}"]
        for figure in ("ready", "result"):
            values = timings[name][figure]
            spread = f"{min(values):.0f}-{max(values):.0f}"
            row += [fmt(statistics.median(values), 0), spread]
        rows.append(row)
        measured[name] = {"files": count, "bytes": size, **timings[name]}
    print(
        table(
            ["page", "files", "KiB", "ready ms", "ready range", "result ms", "result range"], rows
        )
    )
    write_json(options.json, {"machine": info, "trees": measured})
    wall_time(started)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
