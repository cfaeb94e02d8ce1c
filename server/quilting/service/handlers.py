"""Every error as an ``application/problem+json`` answer: the :class:`Problem` a route
raises, a request the schema refuses, Starlette's 404 and 405, a missing docs bundle, and
anything unexpected (a 500 without a trace)."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator, MutableMapping
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import BaseRoute, Match, Route

from quilting.service import apidocs
from quilting.service.problems import Problem

log = logging.getLogger("quilting.service")

PROBLEM_JSON = "application/problem+json"


def problem_response(problem: Problem) -> JSONResponse:
    """The answer a :class:`Problem` stands for."""
    return JSONResponse(
        problem.body(), status_code=problem.status, headers=problem.headers, media_type=PROBLEM_JSON
    )


def add_exception_handlers(app: FastAPI) -> None:
    """Answer every error ``app`` meets as a problem."""
    app.add_exception_handler(Problem, _on_problem)  # type: ignore[arg-type]
    app.add_exception_handler(RequestValidationError, _on_invalid_request)  # type: ignore[arg-type]
    app.add_exception_handler(StarletteHTTPException, _on_http)  # type: ignore[arg-type]
    app.add_exception_handler(Exception, _on_unexpected)
    app.add_exception_handler(apidocs.DocsUnavailableError, _on_docs_unavailable)


async def _on_problem(request: Request, exc: Problem) -> JSONResponse:
    return problem_response(exc)


async def _on_invalid_request(request: Request, exc: RequestValidationError) -> JSONResponse:
    first = exc.errors()[0] if exc.errors() else {}
    # The form part, query parameter or header itself: not where it was, nor the index of a
    # repeated part's value.
    location = [
        str(part)
        for part in first.get("loc", ())
        if part not in ("body", "query", "header", "path", "cookie") and not isinstance(part, int)
    ]
    field = ".".join(location) or "request"
    code = "missing_field" if first.get("type") == "missing" else "invalid_parameter"
    detail = f"{field}: {first.get('msg', 'invalid value')}"
    return problem_response(Problem(422, code, detail, field=field))


async def _on_http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
    code = {404: "not_found", 405: "method_not_allowed"}.get(exc.status_code, "http_error")
    headers = dict(exc.headers or {})
    detail = str(exc.detail)
    if exc.status_code == 405:
        # Every route of the path, not only the first that matched (GET and DELETE of
        # /jobs/{id} are two routes).
        allowed = allowed_methods(request.app, request.scope)
        headers["Allow"] = allowed
        detail = f"{request.method} is not allowed on {request.url.path}; allowed: {allowed}"
    return problem_response(Problem(exc.status_code, code, detail, headers=headers))


def allowed_methods(app: FastAPI, scope: MutableMapping[str, Any]) -> str:
    """The methods of every route of ``app`` matching the request's path, for ``Allow``."""
    methods: set[str] = set()
    for route in _routes(app.router.routes):
        if route.methods:
            match, _ = route.matches(scope)
            if match is not Match.NONE:
                methods |= route.methods
    return ", ".join(sorted(methods))


def _routes(routes: Iterable[BaseRoute]) -> Iterator[Route]:
    """Every route, those of included routers too (FastAPI keeps an included router as one
    entry that holds it; the service includes them without a prefix)."""
    for route in routes:
        if isinstance(route, Route):
            yield route
        included = getattr(route, "original_router", None)
        if included is not None:
            yield from _routes(included.routes)


async def _on_unexpected(request: Request, exc: Exception) -> JSONResponse:
    log.exception("unexpected error on %s %s", request.method, request.url.path)
    return problem_response(Problem(500, "internal_error", "unexpected server error"))


async def _on_docs_unavailable(request: Request, exc: Exception) -> JSONResponse:
    # 503 docs_unavailable rather than a blank page when a bundle is missing.
    return problem_response(Problem(503, "docs_unavailable", str(exc)))
