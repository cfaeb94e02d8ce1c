"""The API documentation pages, Swagger UI at ``/docs`` and ReDoc at ``/redoc``, offline.

FastAPI's own pages load Swagger UI and ReDoc from a CDN (jsDelivr) and ReDoc's fonts from
Google: without internet they stay blank. Here both pages are FastAPI's HTML
(:func:`fastapi.openapi.docs.get_swagger_ui_html`, :func:`~fastapi.openapi.docs.get_redoc_html`)
pointed at files this service serves itself under ``/docs/static/``, with a
Content-Security-Policy that lets the page load from this origin alone, so that a page which
tried to reach another host would fail visibly instead of working by luck.

Where the files come from: the PyPI package ``fastapi-offline`` (a dependency of the
``server`` extra; 1.7.7 bundles swagger-ui-dist 5.32.6 and ReDoc 2.5.3). It was chosen over
copying the npm ``swagger-ui-dist`` and ``redoc`` bundles into this repository because it is
installed by pip like every other dependency, its version is pinned and upgraded in one place,
and it keeps 2.8 MB of minified JavaScript out of the repository and of this package's wheel.
Only its ``static`` folder is used, found through :mod:`importlib.resources`; its
``FastAPIOffline()`` constructor is not, since the app is built by
:func:`quilting.service.app.create_app`. Licences: Swagger UI is Apache-2.0 (SmartBear), ReDoc
is MIT (Redocly), fastapi-offline and FastAPI's favicon are MIT; fastapi-offline's README says
so, and the two bundles name their licences in their first line.

FastAPI stays in :mod:`quilting.service.app`, which builds the two pages' HTML; this module
finds the files and says which headers (the policy above all) each answer carries.
"""

from __future__ import annotations

import base64
import hashlib
import importlib.resources
import re
from dataclasses import dataclass
from functools import cache
from importlib.resources.abc import Traversable

#: The package whose ``static`` folder holds the bundles.
ASSET_PACKAGE = "fastapi_offline"

#: Where the bundles are served (under the docs page's own path).
STATIC_PATH = "/docs/static"

#: The files served, with their media types; nothing else in the folder is.
ASSETS = {
    "swagger-ui-bundle.js": "text/javascript; charset=utf-8",
    "swagger-ui.css": "text/css; charset=utf-8",
    "redoc.standalone.js": "text/javascript; charset=utf-8",
    "favicon.png": "image/png",
}

#: Changes made to a bundle as it is read: ReDoc's sidebar shows Redocly's logo from its CDN
#: (the only file of another host either page loads). An empty ``data:`` image fails to decode,
#: and ReDoc's own error handler then leaves the logo out; the "API docs by Redocly" link stays.
PATCHES: dict[str, tuple[tuple[bytes, bytes], ...]] = {
    "redoc.standalone.js": ((b'src:"https://cdn.redoc.ly/redoc/logo-mini.svg"', b'src:"data:,"'),),
}

#: What the package is missing from, for the error a person sees.
INSTALL_HINT = "pip install 'quilting[server]' (the API docs' files come from fastapi-offline)"

#: Inline <script> and <style> blocks of a page (the ones CSP hashes must allow).
_INLINE = re.compile(r"<(script|style)>(.*?)</\1>", re.DOTALL)


class DocsUnavailableError(Exception):
    """The package with the bundles is not installed (or lacks one of the files)."""


@dataclass(frozen=True)
class DocsFile:
    """One answer of the docs routes: its bytes and the headers it is served with."""

    body: bytes
    media_type: str
    headers: dict[str, str]


def _static_root() -> Traversable:
    try:
        return importlib.resources.files(ASSET_PACKAGE) / "static"
    except ModuleNotFoundError:
        raise DocsUnavailableError(f"{ASSET_PACKAGE} is not installed: {INSTALL_HINT}") from None


@cache
def _asset(name: str) -> DocsFile:
    """The bundle ``name`` (one of :data:`ASSETS`), read once: it cannot change while we run."""
    entry = _static_root() / name
    if not entry.is_file():
        raise DocsUnavailableError(f"{ASSET_PACKAGE} has no static/{name}: {INSTALL_HINT}")
    body = entry.read_bytes()
    for old, new in PATCHES.get(name, ()):
        # A newer bundle without the string needs no change (the browser test would tell).
        body = body.replace(old, new)
    # nosniff is added to every answer by the app's ResponseHeaders.
    headers = {
        # The URLs carry no version: revalidate, and the ETag makes that a 304 without a body.
        "Cache-Control": "no-cache",
        "ETag": '"' + hashlib.sha256(body).hexdigest()[:32] + '"',
    }
    return DocsFile(body, ASSETS[name], headers)


def asset(name: str) -> DocsFile | None:
    """The bundle ``name`` with its headers, or None for a name that is not one of ours.

    Raises
    ------
    DocsUnavailableError
        When ``fastapi-offline`` is missing.
    """
    return _asset(name) if name in ASSETS else None


def content_security_policy(html: str, *, inline_styles: bool = False) -> str:
    """A policy that lets ``html`` load from its own origin only.

    Every inline ``<script>`` and ``<style>`` of the page is allowed by its SHA-256 hash, so no
    other inline code can run. ``inline_styles`` allows style elements the page's script makes
    at run time (ReDoc's styled-components inject them); a style cannot load anything from
    another host while ``default-src``, ``img-src`` and ``font-src`` stay ``'self'``.
    """
    hashes: dict[str, list[str]] = {"script": [], "style": []}
    for kind, text in _INLINE.findall(html):
        digest = base64.b64encode(hashlib.sha256(text.encode()).digest()).decode()
        hashes[kind].append(f"'sha256-{digest}'")
    # 'unsafe-inline' would be ignored next to a hash (CSP level 2), so it goes alone.
    styles = ["'unsafe-inline'"] if inline_styles else hashes["style"]
    return "; ".join(
        [
            "default-src 'self'",
            "script-src " + " ".join(["'self'", *hashes["script"]]),
            "style-src " + " ".join(["'self'", *styles]),
            # Swagger UI's stylesheet draws its icons as data: SVGs.
            "img-src 'self' data:",
            "font-src 'self'",
            "connect-src 'self'",
            # ReDoc runs its search index in a worker made from a blob: of its own code.
            "worker-src 'self' blob:",
            "object-src 'none'",
            "base-uri 'none'",
            "frame-ancestors 'none'",
            "form-action 'self'",
        ]
    )


def page(html: str, *, inline_styles: bool = False) -> DocsFile:
    """A docs page's answer: its HTML with the policy of :func:`content_security_policy`."""
    headers = {
        "Content-Security-Policy": content_security_policy(html, inline_styles=inline_styles),
        "Cache-Control": "no-cache",
    }
    return DocsFile(html.encode(), "text/html; charset=utf-8", headers)


def require(*names: str) -> None:
    """Check that the bundles ``names`` are there before a page that needs them is served.

    A page whose bundle is missing would be blank; the app answers 503 instead.

    Raises
    ------
    DocsUnavailableError
        When ``fastapi-offline`` is missing.
    """
    for name in names:
        _asset(name)


def asset_url(root_path: str, name: str) -> str:
    """Where the page finds the bundle ``name`` (behind a proxy's ``root_path``, if any)."""
    return f"{root_path}{STATIC_PATH}/{name}"
