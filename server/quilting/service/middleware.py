"""The ASGI middleware around every request: a deadline for the body, a limit on its size,
the headers every answer carries, and CORS when the settings name origins."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

import anyio
from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from starlette.datastructures import MutableHeaders

from quilting.service.downloads import EXTRACTED_HEADER
from quilting.service.handlers import problem_response
from quilting.service.problems import Problem
from quilting.service.settings import Settings

Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]


def add_middleware(app: FastAPI, settings: Settings) -> None:
    """Wrap ``app`` in the service's middleware, innermost first."""
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["Authorization", "X-API-Key", "Idempotency-Key", "Content-Type"],
            # Content-Disposition: a page on another origin can save a result under its name;
            # Quilting-Extracted: and say how its alpha was found.
            expose_headers=[
                "Location",
                "Retry-After",
                "X-Job-Id",
                "Content-Disposition",
                EXTRACTED_HEADER,
            ],
        )
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    # Outside the body limit, so that its reads are timed too; the headers outermost, so
    # that every answer (a 413 or a 408 among them) carries them.
    app.add_middleware(RequestTimeout, seconds=settings.request_timeout_s)
    app.add_middleware(ResponseHeaders)


class RequestTimeout:
    """ASGI middleware: a client has ``seconds`` to send its whole request body.

    A client that stalls mid-upload would otherwise hold its connection and its request open
    for ever (uvicorn times out idle connections, not a body that stops coming). Past the
    deadline the app is told the client left, and the client gets 408 ``request_timeout``
    (with ``Connection: close``) unless an answer had begun.
    """

    def __init__(self, app: Any, seconds: float) -> None:
        self.app = app
        self.seconds = seconds

    async def __call__(self, scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        deadline = anyio.current_time() + self.seconds
        complete = timed_out = started = False

        async def timed() -> MutableMapping[str, Any]:
            nonlocal complete, timed_out
            if timed_out:
                return {"type": "http.disconnect"}
            if complete:  # past the body, receive only waits for a disconnect (streams)
                return await receive()
            try:
                with anyio.fail_after(max(0.0, deadline - anyio.current_time())):
                    message = await receive()
            except TimeoutError:
                timed_out = True
                return {"type": "http.disconnect"}
            if message["type"] != "http.request" or not message.get("more_body", False):
                complete = True
            return message

        async def guarded(message: MutableMapping[str, Any]) -> None:
            nonlocal started
            if timed_out and not started:
                return  # the app's answer to the "disconnect" is not sent
            started = True
            await send(message)

        try:
            await self.app(scope, timed, guarded)
        except Exception:
            if not timed_out:
                raise
        if timed_out and not started:
            problem = Problem(
                408,
                "request_timeout",
                f"the request body did not arrive within {self.seconds:g} s (request_timeout_s)",
                headers={"Connection": "close"},
            )
            await problem_response(problem)(scope, receive, send)


class ResponseHeaders:
    """ASGI middleware: ``X-Content-Type-Options: nosniff`` on every answer, and
    ``Cache-Control: no-store`` on those whose route set no policy of its own.

    Job status, problems and metrics change from one request to the next, so no-store is the
    default; the routes whose answers may be kept say so themselves (a finished job's files,
    the web page, the API docs, the event stream).
    """

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def stamped(message: MutableMapping[str, Any]) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                headers.setdefault("X-Content-Type-Options", "nosniff")
                headers.setdefault("Cache-Control", "no-store")
            await send(message)

        await self.app(scope, receive, stamped)


class BodyLimit:
    """ASGI middleware: refuse request bodies over ``limit`` bytes with 413 ``body_too_large``.

    The rest of an oversized body is read and discarded first (up to ``drain`` bytes), so the
    client, which sends its whole body before reading, gets the answer instead of a reset.
    """

    def __init__(self, app: Any, limit: int, drain: int = 1 << 30) -> None:
        self.app = app
        self.limit = limit
        self.drain = drain

    async def __call__(
        self,
        scope: MutableMapping[str, Any],
        receive: Callable[[], Awaitable[MutableMapping[str, Any]]],
        send: Callable[[MutableMapping[str, Any]], Awaitable[None]],
    ) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            await self._refuse(receive, send, int(declared))
            return
        seen = 0
        exceeded = False
        ended = False  # the message that crossed the limit was the body's last
        started = False

        async def counted() -> MutableMapping[str, Any]:
            # Past the limit the app is told the client left, so whatever parses the body
            # stops; the 413 is sent below, after the app has returned.
            nonlocal seen, exceeded, ended
            if exceeded:
                return {"type": "http.disconnect"}
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > self.limit:
                exceeded = True
                ended = not message.get("more_body", False)
                return {"type": "http.disconnect"}
            return message

        async def guarded(message: MutableMapping[str, Any]) -> None:
            nonlocal started
            if exceeded:
                return  # the app's own answer to the "disconnect" is not sent
            started = True
            await send(message)

        try:
            await self.app(scope, counted, guarded)
        except Exception:
            if not exceeded:
                raise
        if exceeded and not started:
            # A body that has ended has nothing left to drain: another read would wait for
            # the client to leave, and the 413 would never go out.
            await self._refuse(receive, send, seen, drain=not ended)

    def _detail(self, size: int) -> str:
        return (
            f"the request body is {size} bytes or more; the limit is {self.limit} (max_body_bytes)"
        )

    async def _refuse(
        self,
        receive: Callable[[], Awaitable[MutableMapping[str, Any]]],
        send: Callable[[MutableMapping[str, Any]], Awaitable[None]],
        size: int,
        drain: bool = True,
    ) -> None:
        drained = 0
        while drain and drained < self.drain:
            message = await receive()
            drained += len(message.get("body", b""))
            if not message.get("more_body", False):
                break
        response = problem_response(Problem(413, "body_too_large", self._detail(size)))
        await response({"type": "http"}, receive, send)
