"""Headless Chromium for the web page's end-to-end tests, driven by Playwright's sync API.

The browser is Debian's ``chromium`` (``sh docker/install.sh ci`` installs it), launched through
``executable_path``: Playwright's own browser downloads are not used. ``QUILTING_CHROMIUM``
names another binary (default ``/usr/bin/chromium``).

Skip policy, like the GL one in ``tests/conftest.py``: without Playwright or Chromium the browser
tests skip, except when ``QUILTING_REQUIRE_BROWSER`` is set (not ``0``), as in CI: then they
fail with a message naming what is missing.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import pytest

if TYPE_CHECKING:
    from playwright.sync_api import Browser, BrowserContext, ConsoleMessage, Error, Page

CHROMIUM_VARIABLE = "QUILTING_CHROMIUM"
REQUIRE_BROWSER_VARIABLE = "QUILTING_REQUIRE_BROWSER"
DEFAULT_CHROMIUM = "/usr/bin/chromium"

#: What this sandbox (and CI) needs: no setuid sandbox, no GPU, no network beyond the page's
#: own service. Playwright adds a fresh ``--user-data-dir`` itself.
CHROMIUM_ARGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)

#: Chromium reports every HTTP error response on the console as "Failed to load resource";
#: tests that provoke one on purpose (415, 401) ignore those lines and nothing else.
HTTP_ERROR_LINE = "Failed to load resource: the server responded with a status of"


def browser_required() -> bool:
    """True when a browser test may not skip (``QUILTING_REQUIRE_BROWSER`` set, not ``0``)."""
    return os.environ.get(REQUIRE_BROWSER_VARIABLE, "").strip() not in ("", "0")


def chromium_path() -> str:
    """The Chromium binary to drive: ``QUILTING_CHROMIUM`` or ``/usr/bin/chromium``."""
    return os.environ.get(CHROMIUM_VARIABLE, "").strip() or DEFAULT_CHROMIUM


def skip_or_fail(reason: str) -> NoReturn:
    """Skip the test, or fail it when ``QUILTING_REQUIRE_BROWSER`` is set."""
    if browser_required():
        pytest.fail(f"{REQUIRE_BROWSER_VARIABLE} is set but {reason}", pytrace=False)
    pytest.skip(reason)


def missing() -> str | None:
    """What keeps the browser tests from running (None when nothing seems to)."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError as exc:
        return (
            f"Playwright for Python is not installed (pip install playwright; no browser "
            f"download needed): {exc}"
        )
    path = chromium_path()
    resolved = shutil.which(path)
    if resolved is None or not Path(resolved).is_file():
        return (
            f"Chromium was not found at {path} (sh docker/install.sh ci installs Debian's "
            f"chromium; {CHROMIUM_VARIABLE} names another binary)"
        )
    return None


def launch_browser() -> Iterator[Browser]:
    """Chromium, started once with :data:`CHROMIUM_ARGS` (a generator, for a fixture).

    Skips, or fails with ``QUILTING_REQUIRE_BROWSER``, when it cannot start.
    """
    reason = missing()
    if reason is not None:
        skip_or_fail(reason)
    from playwright.sync_api import Error, sync_playwright

    path = chromium_path()
    with sync_playwright() as playwright:
        try:
            browser = playwright.chromium.launch(
                executable_path=shutil.which(path) or path,
                headless=True,
                args=list(CHROMIUM_ARGS),
                timeout=60_000,
            )
        except Error as exc:
            skip_or_fail(f"Chromium ({path}) did not start: {exc.message.splitlines()[0]}")
        try:
            yield browser
        finally:
            browser.close()


@dataclass
class Console:
    """What a page said on its console and the errors it threw, for asserting on."""

    errors: list[str] = field(default_factory=list)
    page_errors: list[str] = field(default_factory=list)

    def on_console(self, message: ConsoleMessage) -> None:
        if message.type == "error":
            where = message.location
            self.errors.append(f"{message.text} ({where.get('url')}:{where.get('lineNumber')})")

    def on_page_error(self, error: Error) -> None:
        self.page_errors.append(f"{error.name}: {error.message}\n{error.stack or ''}")

    def assert_clean(self, *, http_errors: bool = False) -> None:
        """No uncaught exception and no console error (HTTP error lines allowed if asked)."""
        assert not self.page_errors, "uncaught errors in the page:\n" + "\n".join(self.page_errors)
        errors = [e for e in self.errors if not (http_errors and e.startswith(HTTP_ERROR_LINE))]
        assert not errors, "console errors:\n" + "\n".join(errors)


def new_context(browser: Browser, **options: Any) -> BrowserContext:
    """A fresh context (own storage, downloads accepted), with generous default timeouts."""
    context = browser.new_context(accept_downloads=True, **options)
    context.set_default_timeout(30_000)
    return context


def watch(page: Page) -> Console:
    """Start recording ``page``'s console errors and uncaught exceptions."""
    console = Console()
    page.on("console", console.on_console)
    page.on("pageerror", console.on_page_error)
    return console
