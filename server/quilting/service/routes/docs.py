"""The API docs, Swagger UI at ``/docs`` and ReDoc at ``/redoc``, with their scripts served
from here (:mod:`quilting.service.apidocs`), never from a CDN."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Header, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import Response

from quilting.service import apidocs
from quilting.service.problems import Problem

router = APIRouter(include_in_schema=False)


@router.get("/docs")
async def swagger_ui(request: Request) -> Response:
    root = str(request.scope.get("root_path", ""))
    apidocs.require("swagger-ui-bundle.js", "swagger-ui.css", "favicon.png")
    html = get_swagger_ui_html(
        openapi_url=root + str(request.app.openapi_url),
        title=f"{request.app.title} - Swagger UI",
        swagger_js_url=apidocs.asset_url(root, "swagger-ui-bundle.js"),
        swagger_css_url=apidocs.asset_url(root, "swagger-ui.css"),
        swagger_favicon_url=apidocs.asset_url(root, "favicon.png"),
        # On top of FastAPI's defaults: no validator badge (an image from swagger.io).
        swagger_ui_parameters={"validatorUrl": None},
    )
    return _docs_response(apidocs.page(bytes(html.body).decode()))


@router.get("/redoc")
async def redoc(request: Request) -> Response:
    root = str(request.scope.get("root_path", ""))
    apidocs.require("redoc.standalone.js", "favicon.png")
    html = get_redoc_html(
        openapi_url=root + str(request.app.openapi_url),
        title=f"{request.app.title} - ReDoc",
        redoc_js_url=apidocs.asset_url(root, "redoc.standalone.js"),
        redoc_favicon_url=apidocs.asset_url(root, "favicon.png"),
        with_google_fonts=False,  # the system's fonts: nothing from Google
    )
    # ReDoc's styled-components add style elements at run time.
    return _docs_response(apidocs.page(bytes(html.body).decode(), inline_styles=True))


@router.get(apidocs.STATIC_PATH + "/{name}")
async def docs_asset(name: str, if_none_match: Annotated[str | None, Header()] = None) -> Response:
    found = apidocs.asset(name)
    if found is None:
        raise Problem(404, "not_found", f"the API docs have no file {name!r}")
    if if_none_match is not None and found.headers["ETag"] in if_none_match:
        return Response(status_code=304, headers=found.headers)
    return _docs_response(found)


def _docs_response(found: apidocs.DocsFile) -> Response:
    return Response(found.body, media_type=found.media_type, headers=found.headers)
