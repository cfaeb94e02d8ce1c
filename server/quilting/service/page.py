"""The browser page's files, as the service serves them: which exist, their types, headers.

The page lives in ``client/web`` and ships inside the wheel as the package ``quilting.web``.
Only names listed in the folder are served (no paths), each with its media type and a
Content-Security-Policy that lets the page talk to this service alone.
"""

from __future__ import annotations

import importlib.resources
from dataclasses import dataclass
from functools import cache

#: Media types of the files the page is made of.
MEDIA_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
}

#: The page loads nothing from elsewhere and shows images it fetched itself (blob: URLs).
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)


@dataclass(frozen=True)
class PageFile:
    """One file of the page: its bytes and the headers it is served with."""

    body: bytes
    media_type: str

    @property
    def headers(self) -> dict[str, str]:
        return {
            "Content-Security-Policy": CONTENT_SECURITY_POLICY,
            # Revalidate on every load: a new service version brings a new page at once.
            "Cache-Control": "no-cache",
        }


@cache
def page_files() -> dict[str, PageFile]:
    """Every servable file of the page by name (``index.html``, ``app.js``, ...).

    Read once: the page does not change while the service runs.
    """
    root = importlib.resources.files("quilting.web")
    files: dict[str, PageFile] = {}
    for entry in root.iterdir():
        suffix = "." + entry.name.rpartition(".")[2]
        if entry.is_file() and suffix in MEDIA_TYPES:
            files[entry.name] = PageFile(entry.read_bytes(), MEDIA_TYPES[suffix])
    return files
