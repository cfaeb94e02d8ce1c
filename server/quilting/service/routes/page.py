"""The browser page: ``/`` and its files under ``/web/`` (only when ``web_page`` is on)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import Response

from quilting.service.page import page_files
from quilting.service.problems import Problem

router = APIRouter(include_in_schema=False)


@router.get("/")
async def page_index() -> Response:
    return _page_file("index.html")


@router.get("/web/{name}")
async def page_asset(name: str) -> Response:
    return _page_file(name)


def _page_file(name: str) -> Response:
    page = page_files().get(name)
    if page is None:
        raise Problem(404, "not_found", f"the page has no file {name!r}")
    return Response(page.body, media_type=page.media_type, headers=page.headers)
