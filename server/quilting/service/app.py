"""The FastAPI application, assembled: the shared parts, the routers, the middleware, the
error handlers and the OpenAPI document.

This process parses and routes, nothing more: requests are parsed and validated here, and
uploads checked from their headers (:func:`quilting.service.uploads.check_headers`,
milliseconds); what needs pixels (decoding and checking the uploads, ``/tile``, seam overlays)
runs in the sandbox processes (:mod:`quilting.service.sandbox`) under a time and memory
limit, and synthesis in the workers behind :mod:`quilting.service.jobs.queue` (this process's, or
``quilting worker`` processes reading Redis). A queued job keeps its uploads as they came,
compressed. The routes are in :mod:`quilting.service.routes`, one router per resource.
"""

import gc
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from quilting import __version__
from quilting.service.context import Service
from quilting.service.handlers import add_exception_handlers
from quilting.service.middleware import add_middleware
from quilting.service.openapi import publish_components
from quilting.service.routes import (
    docs,
    extract,
    fill,
    jobs,
    matte,
    operations,
    page,
    synthesize,
    tile,
    transfer,
    wang,
)
from quilting.service.settings import Settings


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the service: its job queue and sandbox (started with the app) and routes."""
    settings = settings or Settings.from_env()
    service = Service.build(settings)
    app = FastAPI(
        title="quilting",
        version=__version__,
        description="Texture synthesis by image quilting: send a small texture, get a large one.",
        lifespan=_lifespan,
        # FastAPI's pages load their scripts from a CDN: ours (routes.docs) serve them from here.
        docs_url=None,
        redoc_url=None,
    )
    app.state.service = service
    app.state.draining = False
    app.state.drain_deadline = None  # time.monotonic() when a drain's grace ends
    add_middleware(app, settings)
    add_exception_handlers(app)
    routers = [
        synthesize,
        transfer,
        matte,
        fill,
        wang,
        extract,
        tile,
        jobs,
        *([page] if settings.web_page else []),
    ]
    for module in [*routers, docs, operations]:
        app.include_router(module.router)
    publish_components(app, service.models)
    return app


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    service: Service = app.state.service
    await service.jobs.start()
    await service.sandbox.start()
    app.openapi()  # built now (it is cached), so that it is frozen below with the rest
    # Everything made so far lives as long as the process: a full collection would walk it
    # all (about 100 ms, the event loop stalled: the slowest /healthz under the hostile
    # battery) for nothing. Frozen, a collection walks only what requests allocate.
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        await service.sandbox.close()
        # A drain (quilting serve, SIGTERM) has already given running jobs their grace: what
        # is left of it, not a second one.
        deadline = app.state.drain_deadline
        grace = service.settings.drain_grace_s
        if deadline is not None:
            grace = max(0.0, deadline - time.monotonic())
        await service.jobs.stop(timeout=grace)
