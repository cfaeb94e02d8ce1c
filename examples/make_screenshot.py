"""Regenerate the README's screenshot of the browser page: ``examples/web_page.png``.

Starts ``quilting serve`` on a free loopback port the way a user does, opens the page in
Debian's headless Chromium through Playwright, launched as the tests launch it
(``tests/service/browser.py``: ``executable_path``, no browser download),
synthesizes 384x256 from ``examples/gravel.png`` with the Medium block preset and seed 7,
turns the seam overlay on and takes a screenshot of the whole page. Run from the repository
root (needs ``pip install -e '.[dev]'`` and ``apt-get install chromium``)::

    .venv/bin/python examples/make_screenshot.py
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
from playwright.sync_api import expect, sync_playwright

HERE = Path(__file__).resolve().parent
# Launched as the browser tests launch it (tests/service/browser.py: Debian's Chromium, flags
# for a sandbox without a display or outside network).
sys.path.insert(0, str(HERE.parent / "tests" / "service"))
from browser import CHROMIUM_ARGS, chromium_path  # noqa: E402


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def main() -> None:
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
            page.set_input_files("#texture", HERE / "gravel.png")
            page.fill("#opt-width", "384")
            page.fill("#opt-height", "256")
            page.fill("#opt-seed", "7")
            page.get_by_role("button", name=re.compile("^Medium")).click()
            page.click("#run")
            expect(page.locator("#status")).to_have_text("done", timeout=60_000)
            page.check("#seams")
            expect(page.locator("#seam-overlay")).to_be_visible()
            out = HERE / "web_page.png"
            page.screenshot(path=out, full_page=True)
            browser.close()
        print(f"wrote {out}")
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
