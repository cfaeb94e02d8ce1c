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

import uvicorn

from quilting.service.app import create_app
from quilting.service.settings import Settings

log = logging.getLogger("quilting.service")


class DrainingServer(uvicorn.Server):
    """A uvicorn server whose first shutdown signal drains the job queue first."""

    def __init__(self, config: uvicorn.Config, settings: Settings) -> None:
        super().__init__(config)
        self.settings = settings
        self.draining_since: float | None = None

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        app = self.config.loaded_app
        state = getattr(getattr(app, "state", None), "draining", None)
        if self.draining_since is not None or state is None:
            super().handle_exit(sig, frame)
            return
        log.info("signal %s: draining (grace %.0f s)", sig, self.settings.drain_grace_s)
        self.draining_since = time.monotonic()
        app.state.draining = True

    async def on_tick(self, counter: int) -> bool:
        if self.draining_since is not None and not self.should_exit:
            store = self.config.loaded_app.state.store
            idle = store.queued == 0 and store.running == 0
            late = time.monotonic() - self.draining_since > self.settings.drain_grace_s
            if idle or late:
                self.should_exit = True
        return await super().on_tick(counter)


def serve(settings: Settings) -> None:
    """Start the service and block until it has shut down."""
    app = create_app(settings)
    config = uvicorn.Config(
        app, host=settings.host, port=settings.port, log_level="info", timeout_graceful_shutdown=5
    )
    server = DrainingServer(config, settings)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, server.handle_exit)
    asyncio.run(server.serve())
