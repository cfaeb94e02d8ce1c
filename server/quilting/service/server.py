"""Running the service under uvicorn, with a graceful drain on SIGTERM.

On the first SIGTERM (or SIGINT) the app starts draining: readiness answers 503 and new jobs
get 503 ``draining``, while running and queued jobs go on for up to ``drain_grace_s``; then
uvicorn shuts down. A second signal stops at once.
"""

from __future__ import annotations

import asyncio
import logging
import signal
import time
from types import FrameType
from typing import TYPE_CHECKING

import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from quilting.service.app import create_app
from quilting.service.settings import Settings

if TYPE_CHECKING:  # only app.py imports FastAPI at run time
    from fastapi import FastAPI

log = logging.getLogger("quilting.service")

#: Seconds the server stays up after its last job ends while draining.
LINGER_S = 1.0


class DrainingServer(uvicorn.Server):
    """A uvicorn server whose first shutdown signal drains the job queue first."""

    def __init__(self, config: uvicorn.Config, app: FastAPI, settings: Settings) -> None:
        super().__init__(config)
        # The app itself: uvicorn's loaded_app is wrapped in its own middleware.
        self.app = app
        self.settings = settings
        self.draining_since: float | None = None
        self.idle_since: float | None = None

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        if self.draining_since is not None:
            super().handle_exit(sig, frame)  # a second signal: stop now
            return
        log.info("signal %s: draining (grace %.0f s)", sig, self.settings.drain_grace_s)
        self.draining_since = time.monotonic()
        self.app.state.drain_deadline = self.draining_since + self.settings.drain_grace_s
        self.app.state.draining = True

    async def on_tick(self, counter: int) -> bool:
        if self.draining_since is not None and not self.should_exit:
            now = time.monotonic()
            if self.app.state.service.jobs.busy():
                self.idle_since = None
            elif self.idle_since is None:
                self.idle_since = now
            # Linger a moment once idle, so clients following the last jobs can fetch results.
            lingered = self.idle_since is not None and now - self.idle_since >= LINGER_S
            if lingered or now - self.draining_since > self.settings.drain_grace_s:
                self.should_exit = True
        return await super().on_tick(counter)


def header_timed(seconds: float) -> type[H11Protocol]:
    """uvicorn's HTTP/1.1 protocol, closing a connection whose next request's headers have
    not all arrived within ``seconds``: the first request's, counted from the connection, and
    every later one's on a kept-alive connection, counted from the end of the answer before.

    uvicorn waits for headers for ever: its keep-alive timer is cancelled by the first byte of
    the next request, so a client that sends half its headers and stalls holds the connection
    (the app's :class:`~quilting.service.app.RequestTimeout` times the body, once the headers
    are in).
    """

    class HeaderTimedProtocol(H11Protocol):
        _header_timer: asyncio.TimerHandle | None = None

        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            self._await_headers(None)

        def on_response_complete(self) -> None:
            ended = self.cycle
            super().on_response_complete()  # may start a pipelined request's cycle
            if not self.transport.is_closing():
                self._await_headers(ended)

        def connection_lost(self, exc: Exception | None) -> None:
            if self._header_timer is not None:
                self._header_timer.cancel()
            super().connection_lost(exc)

        def _await_headers(self, ended: object) -> None:
            """Close the connection in ``seconds`` unless a request has begun since the one
            that ``ended`` (None: since the connection was made)."""
            if self._header_timer is not None:
                self._header_timer.cancel()
            self._header_timer = self.loop.call_later(seconds, self._headers_overdue, ended)

        def _headers_overdue(self, ended: object) -> None:
            self._header_timer = None
            # Still the cycle that ended (or none yet): the next request's headers never came.
            if self.cycle is ended and not self.transport.is_closing():
                self.transport.close()

    return HeaderTimedProtocol


def serve(settings: Settings) -> None:
    """Start the service and block until it has shut down."""
    app = create_app(settings)
    config = uvicorn.Config(
        app,
        host=settings.host,
        port=settings.port,
        log_level="info",
        timeout_graceful_shutdown=5,
        http=header_timed(settings.request_timeout_s),
    )
    server = DrainingServer(config, app, settings)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, server.handle_exit)
    asyncio.run(server.serve())
