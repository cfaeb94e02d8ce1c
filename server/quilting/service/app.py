"""The FastAPI application: endpoints, problem responses, body limits, CORS.

The only module that imports FastAPI/Starlette. This process parses and routes, nothing more:
requests are parsed and validated here, and uploads checked from their headers
(:func:`quilting.service.uploads.check_headers`, milliseconds); what needs pixels (decoding
and checking the uploads, ``/tile``, seam overlays) runs in the sandbox processes
(:mod:`quilting.service.sandbox`) under a time and memory limit, and synthesis in the workers
behind :mod:`quilting.service.queue` (this process's, or ``quilting worker`` processes reading
Redis). A queued job keeps its uploads as they came, compressed.
"""

import asyncio
import dataclasses
import gc
import hashlib
import hmac
import json
import logging
import re
import time
import typing
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping, MutableMapping
from contextlib import asynccontextmanager
from dataclasses import dataclass, field, fields
from typing import Annotated, Any, Literal, TypeVar

import anyio
import numpy as np
from fastapi import Depends, FastAPI, File, Form, Header, Query, Request, UploadFile
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import JSONResponse, PlainTextResponse, Response, StreamingResponse
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model
from starlette.datastructures import MutableHeaders
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match, Route

from quilting import COMPANION_KINDS, QuiltingError, __version__
from quilting.backends import BACKEND_NAMES, resolve_name
from quilting.io import image_format
from quilting.options import (
    CORRESPONDENCES,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
)
from quilting.service import apidocs
from quilting.service.budgets import job_budget, predicted, predicted_tile
from quilting.service.downloads import (
    content_disposition,
    fallback_stem,
    job_stem,
    tile_name,
)
from quilting.service.jobs import (
    HISTOGRAM_BUCKETS,
    Figures,
    Job,
    JobInput,
    PixelLimits,
    Status,
    new_job_id,
)
from quilting.service.page import page_files
from quilting.service.problems import Problem, from_engine, queue_full
from quilting.service.queue import JobQueue, make_queue
from quilting.service.sandbox import Sandbox
from quilting.service.settings import Settings
from quilting.service.uploads import check_headers, check_image_header

log = logging.getLogger("quilting.service")

PROBLEM_JSON = "application/problem+json"
COMPANION_NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
HEX_COLOR = re.compile(r"^[0-9a-fA-F]{6}$")
POLL_S = 0.02

#: How long an EventSource waits before it reconnects to a broken event stream (the ``retry:``
#: line), in milliseconds.
SSE_RETRY_MS = 1000

#: Event ids are positions in a job's life, the same on every replica (a reconnecting client
#: may reach another one): ``(phase * 10001 + progress in 1/10000) * 1000``, phase 0 queued and
#: 1 running, plus up to 999 changes that one stream saw at the same progress.
_PROGRESS_STEPS = 10_000
_CHANGES_PER_STEP = 1000
#: The id of the final event (done, failed, cancelled): above every progress event's.
END_EVENT_ID = 2 * (_PROGRESS_STEPS + 1) * _CHANGES_PER_STEP
_EVENT_ID = re.compile(r"^[0-9]{1,19}$")

OptionsT = TypeVar("OptionsT", bound=QuiltOptions)

#: Limits of the options form field, checked before it is parsed: json.loads and the schema
#: validation recurse, so a deeply nested value would exhaust Python's stack (no option
#: nests more than a few levels).
MAX_OPTIONS_CHARS = 64 * 1024
MAX_OPTIONS_DEPTH = 32
#: A JSON string (escapes included, closing quote optional) or one bracket.
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"?')
#: Steps of the nesting depth: +1 for an opening bracket, -1 for a closing one, 0 otherwise.
_DEPTH_STEP = np.zeros(256, dtype=np.int64)
_DEPTH_STEP[[ord("["), ord("{")]] = 1
_DEPTH_STEP[[ord("]"), ord("}")]] = -1

#: Parts of a submission that may be sent more than once; any other part is one value.
REPEATABLE_PARTS = frozenset({"companion", "layer"})


#: The correspondences the service offers: 'custom' needs maps given as arrays, which only
#: the Python API takes.
HTTP_CORRESPONDENCES: tuple[str, ...] = tuple(c for c in CORRESPONDENCES if c != "custom")


def options_model(
    settings: Settings,
    options: type[QuiltOptions] | type[TileOptions] | type[MatteOptions] = SynthesisOptions,
    *,
    name: str = "SynthesizeOptions",
    sized: bool = True,
    choices: Mapping[str, tuple[str, ...]] | None = None,
) -> type[BaseModel]:
    """The ``options`` JSON schema of an endpoint, derived from an options dataclass.

    Parameters
    ----------
    settings : Settings
        Limits of the output size and the service's default backend.
    options : type
        :class:`SynthesisOptions` or :class:`TransferOptions`; every field
        becomes a property with its documentation, default and limits.
    name : str
        Name of the model (the schema's component name).
    sized : bool
        Whether the output ``width`` and ``height`` are required properties (synthesis);
        a transfer's output has its target's size.
    choices : Mapping, optional
        Fields whose allowed values the service narrows, by name.
    """
    hints = typing.get_type_hints(options)
    definitions: dict[str, Any] = {}
    if sized:
        definitions["width"] = (
            int,
            Field(ge=1, le=settings.max_side, description="Output width in pixels."),
        )
        definitions["height"] = (
            int,
            Field(ge=1, le=settings.max_side, description="Output height in pixels."),
        )
    # Listed choices make the schema a menu (the web page builds its form from it).
    narrowed = {"backend": BACKEND_NAMES, **(choices or {})}
    for f in fields(options):
        limits = {k: f.metadata[k] for k in ("ge", "le") if k in f.metadata}
        default = f.default
        if f.name == "backend":
            default = settings.backend
        hint = hints[f.name]
        if f.name in narrowed:
            hint = Literal[narrowed[f.name]]
        if f.metadata.get("kind") == "color_ranges":
            # JSON has arrays, not tuples: [[low, high], ...] with colours of 1..4 numbers.
            colour = Annotated[list[float], Field(min_length=1, max_length=4)]
            hint = list[Annotated[list[colour], Field(min_length=2, max_length=2)]]
            default = []
        if f.metadata.get("kind") == "direction":
            hint = Annotated[list[float], Field(min_length=3, max_length=3)] | None
        definitions[f.name] = (
            hint,
            Field(default=default, description=str(f.metadata["doc"]), **limits),
        )
    model: type[BaseModel] = create_model(
        name,
        # Strict: JSON true is not the integer 1, and "64" is not a number.
        __config__=ConfigDict(extra="forbid", strict=True),
        **definitions,
    )
    return model


@dataclass
class Submission:
    """A ``POST /synthesize`` or ``POST /transfer`` once read, before its images are decoded.

    Attributes
    ----------
    operation : str
        ``"synthesize"``, ``"transfer"`` or ``"matte"``.
    options : SynthesisOptions or TransferOptions
        The validated engine options (a :class:`TransferOptions` for a transfer).
    texture : bytes
        The uploaded texture.
    companions : dict of str to bytes
        Companion maps by name.
    size : (int, int) or None
        Output (width, height) of a synthesis; None for a transfer (the target's size).
    target : bytes or None
        The uploaded target of a transfer.
    source_mask : bytes or None
        The uploaded mask of pixels never to use (black), of the texture's size.
    layers : list of bytes
        A matte job's textures, bottom first (``texture`` is the first).
    silhouette, normals : bytes or None
        A matte job's silhouette and optional normal map.
    companion_kinds : dict of str to str
        How companions are rendered ('blend', 'hard' or 'normal') by name; others 'blend'.
    texture_name, target_name : str or None
        The file names the client gave the texture (a matte's first layer) and the target:
        the start of the download names. Not part of :meth:`digest`: the same files under
        other names are the same request, with the same result.
    """

    operation: str
    options: QuiltOptions
    texture: bytes
    companions: dict[str, bytes]
    size: tuple[int, int] | None = None
    target: bytes | None = None
    source_mask: bytes | None = None
    layers: list[bytes] = field(default_factory=list)
    silhouette: bytes | None = None
    normals: bytes | None = None
    texture_name: str | None = None
    target_name: str | None = None
    companion_kinds: dict[str, str] = field(default_factory=dict)

    def digest(self) -> str:
        """What an Idempotency-Key is bound to: the operation, options and every file.

        The operation is part of it, so that a synthesis and a transfer never count as the
        same request, and so is the target, so that another target is another request.
        """
        files: list[tuple[str, str, bytes]] = [("texture", "", self.texture)]
        if self.target is not None:
            files.append(("target", "", self.target))
        if self.source_mask is not None:
            files.append(("source_mask", "", self.source_mask))
        files += [("layer", str(index), data) for index, data in enumerate(self.layers)]
        for role, data in (("silhouette", self.silhouette), ("normals", self.normals)):
            if data is not None:
                files.append((role, "", data))
        files += [("companion", name, data) for name, data in sorted(self.companions.items())]
        document = {
            "operation": self.operation,
            "size": self.size,
            "options": self.options.to_dict(),
            "files": [[role, name, hashlib.sha256(data).hexdigest()] for role, name, data in files],
        }
        # Only kinds other than the default: a request that names none (or only 'blend') is the
        # same request as before kinds existed, so its Idempotency-Key digest is unchanged.
        kinds = {n: k for n, k in sorted(self.companion_kinds.items()) if k != "blend"}
        if kinds:
            document["companion_kinds"] = kinds
        return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()


def event_position(status: Status, progress: float) -> int:
    """The event id of a job that is ``status`` (queued or running) at ``progress``.

    It grows as the job moves on (the engine's progress never goes back within one run), so
    an event's id tells any replica what a client that got it has seen.
    """
    phase = 0 if status is Status.QUEUED else 1
    steps = min(max(round(progress * _PROGRESS_STEPS), 0), _PROGRESS_STEPS)
    return (phase * (_PROGRESS_STEPS + 1) + steps) * _CHANGES_PER_STEP


def _last_event_id(header: str | None) -> int:
    """The ``Last-Event-ID`` request header as a number; -1 when absent (nothing seen yet).

    Raises
    ------
    Problem
        422 ``invalid_parameter`` for a value that is not an id this service sent.
    """
    if header is None or not header.strip():
        return -1
    if not _EVENT_ID.match(header.strip()):
        raise Problem(
            422,
            "invalid_parameter",
            "Last-Event-ID must be the id of an event of this stream (a whole number)",
            field="Last-Event-ID",
        )
    return int(header.strip())


def json_depth(text: str) -> int:
    """How deep arrays and objects nest in the JSON ``text``, without recursion.

    Brackets inside strings do not count; the text need not be valid JSON (a parser that
    reads it afterwards says what else is wrong).
    """
    # At C speed, on the event loop: a Python loop over 200,000 brackets held it 0.4 s. The
    # strings go first (brackets inside them are not nesting), then every character is a step.
    # Bytes past ASCII are never brackets (UTF-8 continuation and lead bytes are >= 0x80).
    outside = _JSON_STRING.sub("", text).encode("utf-8", "surrogatepass")
    if not outside:
        return 0
    steps = _DEPTH_STEP[np.frombuffer(outside, dtype=np.uint8)]
    return max(0, int(np.cumsum(steps).max()))


# Parameters both submission endpoints (/synthesize, /transfer) take.
CompanionParts = Annotated[
    list[UploadFile] | None,
    File(description="Companion maps of the texture's size, quilted with the same layout."),
]
SourceMaskPart = Annotated[
    UploadFile | None,
    File(description="Mask of the texture's size: its black pixels are never used."),
]
CompanionKindsField = Annotated[
    str | None,
    Form(
        description="JSON object {companion name: kind}: how each companion is rendered. "
        "'blend': blended like the result's pixels (the default); 'hard': never mixed, every "
        "pixel a source pixel (masks, material IDs; not with mode 'walk'); 'normal': blended, "
        "then renormalized to unit vectors (normal maps, 3 or 4 channels). Every name must be "
        "an uploaded companion's.",
    ),
]
WaitSeconds = Annotated[float | None, Query(ge=0, description="Seconds to wait for the result.")]
IdempotencyKey = Annotated[str | None, Header(max_length=256)]


PROBLEM_SCHEMA: dict[str, Any] = {
    "type": "object",
    "required": ["type", "title", "status", "detail", "code"],
    "properties": {
        "type": {"type": "string"},
        "title": {"type": "string"},
        "status": {"type": "integer"},
        "detail": {"type": "string"},
        "code": {"type": "string"},
        "field": {"type": "string"},
        "job_id": {"type": "string"},
    },
}


def problems(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries: these statuses answer ``application/problem+json``."""
    ref = {"$ref": "#/components/schemas/Problem"}
    return {
        status: {"description": "Problem", "content": {PROBLEM_JSON: {"schema": ref}}}
        for status in statuses
    }


def _problem_response(problem: Problem) -> JSONResponse:
    return JSONResponse(
        problem.body(), status_code=problem.status, headers=problem.headers, media_type=PROBLEM_JSON
    )


Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]


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
            await _problem_response(problem)(scope, receive, send)


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
        started = False

        async def counted() -> MutableMapping[str, Any]:
            # Past the limit the app is told the client left, so whatever parses the body
            # stops; the 413 is sent below, after the app has returned.
            nonlocal seen, exceeded
            if exceeded:
                return {"type": "http.disconnect"}
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > self.limit:
                exceeded = True
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
            await self._refuse(receive, send, seen)

    def _detail(self, size: int) -> str:
        return (
            f"the request body is {size} bytes or more; the limit is {self.limit} (max_body_bytes)"
        )

    async def _refuse(
        self,
        receive: Callable[[], Awaitable[MutableMapping[str, Any]]],
        send: Callable[[MutableMapping[str, Any]], Awaitable[None]],
        size: int,
    ) -> None:
        drained = 0
        while drained < self.drain:
            message = await receive()
            drained += len(message.get("body", b""))
            if not message.get("more_body", False):
                break
        response = _problem_response(Problem(413, "body_too_large", self._detail(size)))
        await response({"type": "http"}, receive, send)


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the service: its job queue (started with the app) and routes."""
    settings = settings or Settings.from_env()
    jobs: JobQueue = make_queue(settings)
    SynthesizeOptions = options_model(settings)
    TransferOptionsModel = options_model(
        settings,
        TransferOptions,
        name="TransferOptions",
        sized=False,
        choices={"correspondence": HTTP_CORRESPONDENCES},
    )
    TileOptionsModel = options_model(settings, TileOptions, name="TileOptions", sized=False)
    MatteOptionsModel = options_model(settings, MatteOptions, name="MatteOptions", sized=False)
    # Pixel work answered at once (checking uploads, tiling, seam overlays): in the sandbox's
    # processes, under a time and memory limit, never here.
    # Read once: the derived budget follows the memory available when the service starts.
    memory_budget = settings.memory_budget
    sandbox = Sandbox(settings.sandbox_workers, settings.sandbox_timeout_s, memory_budget)
    job_budget_now = job_budget(memory_budget, settings.job_timeout_s)
    tile_budget = job_budget(memory_budget, settings.sandbox_timeout_s)
    limits = PixelLimits.of(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        await jobs.start()
        await sandbox.start()
        app.openapi()  # built now (it is cached), so that it is frozen below with the rest
        # Everything made so far lives as long as the process: a full collection would walk
        # it all (about 100 ms, the event loop stalled: the slowest /healthz under the hostile
        # battery) for nothing. Frozen, a collection walks only what requests allocate.
        gc.collect()
        gc.freeze()
        try:
            yield
        finally:
            await sandbox.close()
            # A drain (quilting serve, SIGTERM) has already given running jobs their grace:
            # what is left of it, not a second one.
            deadline = app.state.drain_deadline
            grace = settings.drain_grace_s
            if deadline is not None:
                grace = max(0.0, deadline - time.monotonic())
            await jobs.stop(timeout=grace)

    app = FastAPI(
        title="quilting",
        version=__version__,
        description="Texture synthesis by image quilting: send a small texture, get a large one.",
        lifespan=lifespan,
        # FastAPI's pages load their scripts from a CDN: ours (below) serve them from here.
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.jobs = jobs
    app.state.sandbox = sandbox
    app.state.draining = False
    app.state.drain_deadline = None  # time.monotonic() when a drain's grace ends
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["Authorization", "X-API-Key", "Idempotency-Key", "Content-Type"],
            # Content-Disposition: a page on another origin can save a result under its name.
            expose_headers=["Location", "Retry-After", "X-Job-Id", "Content-Disposition"],
        )
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    # Outside the body limit, so that its reads are timed too; the headers outermost, so
    # that every answer (a 413 or a 408 among them) carries them.
    app.add_middleware(RequestTimeout, seconds=settings.request_timeout_s)
    app.add_middleware(ResponseHeaders)

    # --- errors ----------------------------------------------------------------------------

    @app.exception_handler(Problem)
    async def on_problem(request: Request, exc: Problem) -> JSONResponse:
        return _problem_response(exc)

    @app.exception_handler(RequestValidationError)
    async def on_invalid_request(request: Request, exc: RequestValidationError) -> JSONResponse:
        first = exc.errors()[0] if exc.errors() else {}
        location = [str(part) for part in first.get("loc", ()) if part not in ("body", "query")]
        field = ".".join(location) or "request"
        code = "missing_field" if first.get("type") == "missing" else "invalid_parameter"
        detail = f"{field}: {first.get('msg', 'invalid value')}"
        return _problem_response(Problem(422, code, detail, field=field))

    @app.exception_handler(StarletteHTTPException)
    async def on_http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = {404: "not_found", 405: "method_not_allowed"}.get(exc.status_code, "http_error")
        headers = dict(exc.headers or {})
        detail = str(exc.detail)
        if exc.status_code == 405:
            # Every route of the path, not only the first that matched (GET and DELETE of
            # /jobs/{id} are two routes).
            allowed = _allowed_methods(request.scope)
            headers["Allow"] = allowed
            detail = f"{request.method} is not allowed on {request.url.path}; allowed: {allowed}"
        return _problem_response(Problem(exc.status_code, code, detail, headers=headers))

    def _allowed_methods(scope: MutableMapping[str, Any]) -> str:
        methods: set[str] = set()
        for route in app.router.routes:
            if isinstance(route, Route) and route.methods:
                match, _ = route.matches(scope)
                if match is not Match.NONE:
                    methods |= route.methods
        return ", ".join(sorted(methods))

    @app.exception_handler(Exception)
    async def on_unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return _problem_response(Problem(500, "internal_error", "unexpected server error"))

    # --- dependencies ----------------------------------------------------------------------

    def owner(
        authorization: Annotated[str | None, Header()] = None,
        x_api_key: Annotated[str | None, Header()] = None,
    ) -> str | None:
        """The API key of the caller (None when the service has no keys)."""
        if not settings.api_keys:
            return None
        key = x_api_key
        if authorization and authorization.lower().startswith("bearer "):
            key = authorization[7:].strip()
        # Constant-time comparison against every key: no timing hint of how much matched.
        matches = [hmac.compare_digest((key or "").encode(), k.encode()) for k in settings.api_keys]
        if not any(matches):
            raise Problem(
                401,
                "unauthorized",
                "a valid API key is required (Authorization: Bearer KEY or X-API-Key)",
                headers={"WWW-Authenticate": "Bearer"},
            )
        return key

    Owner = Annotated[str | None, Depends(owner)]

    def metrics_reader(
        authorization: Annotated[str | None, Header()] = None,
        x_api_key: Annotated[str | None, Header()] = None,
    ) -> None:
        """401 unless the caller has a key, when the service has keys and metrics_public is
        off: the figures tell outsiders how busy the service is and what it has made."""
        if not settings.metrics_public:
            owner(authorization, x_api_key)

    async def single_parts(request: Request) -> None:
        """422 ``duplicate_part`` for a part sent twice that is one value (a second
        ``texture`` would otherwise silently replace the first)."""
        seen: set[str] = set()
        for name, _ in (await request.form()).multi_items():
            if name in seen and name not in REPEATABLE_PARTS:
                raise Problem(
                    422,
                    "duplicate_part",
                    f"the part {name!r} was sent more than once; only "
                    + " and ".join(sorted(REPEATABLE_PARTS))
                    + " may repeat",
                    field=name,
                )
            seen.add(name)

    SingleParts = [Depends(single_parts)]

    async def job_of(job_id: str, key: Owner) -> Job:
        return await jobs.get(job_id, key)

    JobOf = Annotated[Job, Depends(job_of)]

    # --- synthesis and transfer ----------------------------------------------------------

    submit_responses: dict[int | str, dict[str, Any]] = {
        200: {"content": {"image/png": {}}, "description": "The result (job done in time)"},
        202: {"description": "Job accepted; follow Location"},
        **problems(401, 409, 413, 415, 422, 503),
    }

    @app.post(
        "/synthesize",
        operation_id="synthesize",
        dependencies=SingleParts,
        summary="Synthesize a texture of any size from a sample",
        responses=submit_responses,
    )
    async def synthesize_endpoint(
        request: Request,
        key: Owner,
        texture: Annotated[UploadFile, File(description="The sample texture, PNG or JPEG.")],
        options: Annotated[
            str,
            Form(description="JSON object, schema SynthesizeOptions (width and height required)."),
        ],
        companion: CompanionParts = None,
        companion_kinds: CompanionKindsField = None,
        source_mask: SourceMaskPart = None,
        wait: WaitSeconds = None,
        idempotency_key: IdempotencyKey = None,
    ) -> Response:
        wait_s = _accepting(wait)
        width, height, parsed = _synthesis_options(options)
        submission = Submission(
            "synthesize",
            parsed,
            texture=await _read_upload(texture, "texture"),
            companions=(companions := await _read_companions(companion)),
            source_mask=await _read_optional(source_mask, "source_mask"),
            size=(width, height),
            texture_name=texture.filename,
            companion_kinds=_companion_kinds(companion_kinds, companions),
        )
        return await _submit(submission, key, idempotency_key, wait_s)

    @app.post(
        "/transfer",
        operation_id="transfer",
        dependencies=SingleParts,
        summary="Render a target image in the texture of a sample (texture transfer)",
        responses=submit_responses,
    )
    async def transfer_endpoint(
        request: Request,
        key: Owner,
        texture: Annotated[
            UploadFile, File(description="The texture to render with, PNG or JPEG.")
        ],
        target: Annotated[
            UploadFile,
            File(description="The image to render, PNG or JPEG; the output has its size."),
        ],
        options: Annotated[
            str,
            Form(description="JSON object, schema TransferOptions (every member optional)."),
        ] = "{}",
        companion: CompanionParts = None,
        companion_kinds: CompanionKindsField = None,
        source_mask: SourceMaskPart = None,
        wait: WaitSeconds = None,
        idempotency_key: IdempotencyKey = None,
    ) -> Response:
        wait_s = _accepting(wait)
        parsed = _transfer_options(options)
        submission = Submission(
            "transfer",
            parsed,
            texture=await _read_upload(texture, "texture"),
            target=await _read_upload(target, "target"),
            companions=(companions := await _read_companions(companion)),
            source_mask=await _read_optional(source_mask, "source_mask"),
            texture_name=texture.filename,
            target_name=target.filename,
            companion_kinds=_companion_kinds(companion_kinds, companions),
        )
        return await _submit(submission, key, idempotency_key, wait_s)

    @app.post(
        "/matte",
        operation_id="matte",
        dependencies=SingleParts,
        summary="Lay textures on the surface of an object in an image (texture matting)",
        responses=submit_responses,
    )
    async def matte_endpoint(
        request: Request,
        key: Owner,
        target: Annotated[
            UploadFile,
            File(description="The image with the object, PNG or JPEG; the output has its size."),
        ],
        silhouette: Annotated[
            UploadFile,
            File(
                description="The target's size: white (or opaque) where the surface is, black "
                "(or transparent) elsewhere."
            ),
        ],
        layer: Annotated[
            list[UploadFile],
            File(
                description="The textures to lay on the surface, bottom first (repeat the "
                "part); RGBA ones are alpha-quilted."
            ),
        ],
        options: Annotated[
            str,
            Form(description="JSON object, schema MatteOptions (every member optional)."),
        ] = "{}",
        normals: Annotated[
            UploadFile | None,
            File(
                description="A normal map of the target's size ((n + 1) / 2 colours, +y up) "
                "used instead of the one read from the shading."
            ),
        ] = None,
        wait: WaitSeconds = None,
        idempotency_key: IdempotencyKey = None,
    ) -> Response:
        wait_s = _accepting(wait)
        parsed = _engine_options(
            _validate(_options_object(options), MatteOptionsModel), MatteOptions
        )
        if len(layer) > settings.max_layers:
            raise Problem(
                422,
                "too_many_layers",
                f"{len(layer)} layers; at most {settings.max_layers} (max_layers)",
                field="layer",
            )
        layers = [await _read_upload(part, "layer") for part in layer]
        submission = Submission(
            "matte",
            parsed,
            texture=layers[0],
            companions={},
            target=await _read_upload(target, "target"),
            layers=layers,
            silhouette=await _read_upload(silhouette, "silhouette"),
            normals=await _read_optional(normals, "normals"),
            texture_name=layer[0].filename,
            target_name=target.filename,
        )
        return await _submit(submission, key, idempotency_key, wait_s)

    @app.post(
        "/tile",
        operation_id="tile",
        dependencies=SingleParts,
        summary="Make an existing image repeat seamlessly (same size, centre kept)",
        responses={
            200: {"content": {"image/png": {}}, "description": "The tileable image"},
            **problems(401, 413, 415, 422, 503),
        },
    )
    async def tile_endpoint(
        request: Request,
        key: Owner,
        image: Annotated[UploadFile, File(description="The image to make tileable, PNG or JPEG.")],
        options: Annotated[
            str,
            Form(description="JSON object, schema TileOptions (every member optional)."),
        ] = "{}",
    ) -> Response:
        _refuse_while_draining()
        values = _validate(_options_object(options), TileOptionsModel)
        try:
            parsed = TileOptions(**values)
        except QuiltingError as exc:
            raise from_engine(exc) from None
        data = await _read_upload(image, "image")
        # The header first (milliseconds, here): a bomb or a broken file is refused at once.
        await anyio.to_thread.run_sync(check_image_header, data, "image", limits)
        # ... and its cost: an image the sandbox could not tile in its budget is refused here.
        await anyio.to_thread.run_sync(predicted_tile, data, tile_budget, parsed.blend)
        png = await sandbox.run("tile", data, parsed, limits, doing="making the image tileable")
        return Response(png, media_type="image/png", headers=_attachment(tile_name(image.filename)))

    def _refuse_while_draining() -> None:
        """503 ``draining`` once shutdown has begun: no new work is taken."""
        if app.state.draining:
            raise Problem(
                503, "draining", "the service is shutting down", headers={"Retry-After": "10"}
            )

    def _accepting(wait: float | None) -> float:
        """The seconds to hold the request, once the service is known to take new jobs."""
        _refuse_while_draining()
        wait_s = settings.default_wait_s if wait is None else wait
        if wait_s > settings.max_wait_s:
            raise Problem(
                422, "invalid_parameter", f"wait must be 0..{settings.max_wait_s:g}", field="wait"
            )
        return wait_s

    async def _submit(
        submission: Submission, key: str | None, idempotency_key: str | None, wait_s: float
    ) -> Response:
        """Check, queue (or find the idempotent twin), wait up to ``wait_s`` and answer."""
        digest = submission.digest()
        spec = await _checked_input(submission)
        stem = job_stem(
            submission.operation,
            submission.texture_name,
            submission.target_name,
            spec.width,
            spec.height,
            submission.options.seed,
        )
        job = Job(
            id=new_job_id(),
            owner=key,
            width=spec.width,
            height=spec.height,
            companion_names=spec.outputs,
            input=spec,
            operation=submission.operation,
            download_stem=stem,
        )
        job, _ = await jobs.submit(job, (idempotency_key, digest) if idempotency_key else None)
        if wait_s > 0:
            job = await jobs.wait(job, wait_s)
        location = {"Location": f"/jobs/{job.id}", "X-Job-Id": job.id}
        if job.status is Status.DONE and (png := await jobs.result(job)) is not None:
            headers = {**location, **_attachment(_download_name(job, ".png"))}
            return Response(png, media_type="image/png", headers=headers)
        return JSONResponse(
            job.snapshot(), status_code=202, headers={**location, "Retry-After": "1"}
        )

    def _json_object(text: str, field: str, code: str, what: str) -> dict[str, Any]:
        """A form field holding a JSON object; ``code`` for every refusal (422), ``what``
        the shape the message asks for. Its length and depth are checked before it is parsed:
        a deep nesting would exhaust the parser's recursion."""
        depth = json_depth(text)
        if depth > MAX_OPTIONS_DEPTH:
            raise Problem(
                422,
                code,
                f"{field} nests arrays and objects {depth} levels deep; at most "
                f"{MAX_OPTIONS_DEPTH}",
                field=field,
            )
        if len(text) > MAX_OPTIONS_CHARS:
            raise Problem(
                422,
                code,
                f"{field} is {len(text)} characters; at most {MAX_OPTIONS_CHARS}",
                field=field,
            )
        try:
            raw = json.loads(text)
        except ValueError as exc:
            raise Problem(422, code, f"{field} is not JSON: {exc}", field=field) from None
        if not isinstance(raw, dict):
            raise Problem(422, code, f"{field} must be a JSON object{what}", field=field)
        return raw

    def _options_object(text: str) -> dict[str, Any]:
        """The options form field as a JSON object."""
        return _json_object(text, "options", "invalid_options", "")

    def _validate(raw: dict[str, Any], model: type[BaseModel]) -> dict[str, Any]:
        """The options checked against the endpoint's schema, as plain values."""
        try:
            values: dict[str, Any] = model.model_validate(raw).model_dump()
        except ValidationError as exc:
            first = exc.errors()[0]
            field = ".".join(str(p) for p in first["loc"]) or "options"
            code = "invalid_options" if first["type"] == "extra_forbidden" else "invalid_parameter"
            raise Problem(422, code, f"{field}: {first['msg']}", field=field) from None
        return values

    def _engine_options(values: dict[str, Any], options: type[OptionsT]) -> OptionsT:
        """The engine's options from schema-checked values (the engine checks the rest)."""
        try:
            resolve_name(values["backend"])
            return options(**values)
        except QuiltingError as exc:
            raise from_engine(exc) from None

    def _synthesis_options(text: str) -> tuple[int, int, SynthesisOptions]:
        """Output width, height and the engine options, validated, from the options JSON."""
        values = _validate(_options_object(text), SynthesizeOptions)
        if values["width"] * values["height"] > settings.max_output_pixels:
            raise Problem(
                422,
                "invalid_parameter",
                f"output {values['width']}x{values['height']} is more than "
                f"{settings.max_output_pixels} pixels (max_output_pixels)",
                field="width",
            )
        width, height = values.pop("width"), values.pop("height")
        return width, height, _engine_options(values, SynthesisOptions)

    def _transfer_options(text: str) -> TransferOptions:
        """The transfer options, validated, from the options JSON."""
        raw = _options_object(text)
        if raw.get("correspondence") == "custom":
            # The schema would refuse it too; this says why and what to do instead.
            raise Problem(
                422,
                "invalid_parameter",
                "correspondence: 'custom' needs correspondence maps given as arrays, which only "
                "the Python API (quilting.transfer) takes; the service offers "
                + ", ".join(repr(c) for c in HTTP_CORRESPONDENCES),
                field="correspondence",
            )
        return _engine_options(_validate(raw, TransferOptionsModel), TransferOptions)

    async def _read_optional(upload: UploadFile | None, field: str) -> bytes | None:
        return None if upload is None else await _read_upload(upload, field)

    async def _read_upload(upload: UploadFile, field: str) -> bytes:
        if upload.size is not None and upload.size > settings.max_file_bytes:
            raise Problem(
                413,
                "file_too_large",
                f"{field} is {upload.size} bytes; the limit is {settings.max_file_bytes} "
                "(max_file_bytes)",
                field=field,
            )
        data = await upload.read()
        if image_format(data[:8]) is None:
            raise Problem(
                415,
                "unsupported_media_type",
                f"{field} must be a PNG or JPEG image (recognized from its bytes)",
                field=field,
            )
        return data

    async def _read_companions(parts: list[UploadFile] | None) -> dict[str, bytes]:
        """Companion uploads by name (their file name's stem), checked and read."""
        companions: dict[str, bytes] = {}
        for part in parts or []:
            name = (part.filename or "").rsplit("/", 1)[-1].rsplit(".", 1)[0]
            if not COMPANION_NAME.match(name) or name in companions:
                raise Problem(
                    422,
                    "invalid_companion",
                    "companion file names must be unique stems of [A-Za-z0-9_-], got "
                    f"{part.filename!r}",
                    field="companion",
                )
            companions[name] = await _read_upload(part, "companion")
        if len(companions) > settings.max_companions:
            raise Problem(
                422,
                "invalid_companion",
                f"at most {settings.max_companions} companions (max_companions)",
                field="companion",
            )
        return companions

    def _companion_kinds(text: str | None, companions: Mapping[str, bytes]) -> dict[str, str]:
        """The ``companion_kinds`` form field: {name: kind} of uploaded companions.

        Raises
        ------
        Problem
            422 ``invalid_parameter`` for a field that is not a JSON object of strings or names
            an unknown kind; 422 ``invalid_companion`` for a name no companion has.
        """
        if text is None or not text.strip():
            return {}
        raw = _json_object(text, "companion_kinds", "invalid_parameter", " {companion name: kind}")
        allowed = ", ".join(repr(k) for k in COMPANION_KINDS)
        for name, kind in raw.items():
            if name not in companions:
                raise Problem(
                    422,
                    "invalid_companion",
                    f"companion_kinds names {name!r}, which is not an uploaded companion"
                    + (f" (uploaded: {', '.join(sorted(companions))})" if companions else ""),
                    field="companion_kinds",
                )
            if kind not in COMPANION_KINDS:
                raise Problem(
                    422,
                    "invalid_parameter",
                    f"companion_kinds: {name!r} has kind {kind!r}; one of {allowed}",
                    field="companion_kinds",
                )
        return {str(name): str(kind) for name, kind in raw.items()}

    async def _checked_input(submission: Submission) -> JobInput:
        """The job's input: the uploads as they came, checked from their headers here and from
        their pixels in the sandbox, with the output's size."""
        size = submission.size or (0, 0)  # a transfer's and a matte's: its target's
        spec = JobInput(
            submission.texture,
            dict(submission.companions),
            submission.options.to_dict(),
            size[0],
            size[1],
            target=submission.target,
            operation=submission.operation,
            source_mask=submission.source_mask,
            layers=list(submission.layers),
            silhouette=submission.silhouette,
            normals=submission.normals,
            limits=limits,
            companion_kinds=dict(submission.companion_kinds),
        )
        # Milliseconds, the 422s of most bad uploads; in a thread all the same, so that the
        # chunk walk of a large file never holds the event loop for more than a GIL switch.
        width, height = await anyio.to_thread.run_sync(check_headers, spec)
        spec = dataclasses.replace(spec, width=width, height=height)
        # The cost model needs the shapes only: a job over budget never reaches a process.
        await anyio.to_thread.run_sync(predicted, spec, submission.options, job_budget_now)
        width, height = await sandbox.run(
            "check", spec, submission.options, doing="reading the uploads"
        )
        return dataclasses.replace(spec, width=width, height=height)

    # --- jobs ------------------------------------------------------------------------------

    @app.get(
        "/jobs/{job_id}",
        operation_id="get_job",
        summary="Status of a job",
        responses=problems(401, 404, 422),
    )
    async def get_job(job: JobOf) -> JSONResponse:
        return JSONResponse(job.snapshot())

    def _expired() -> Problem:
        return Problem(410, "result_expired", "the results of this job are no longer kept")

    def _finished_result(job: Job) -> None:
        if job.expired:
            raise _expired()
        if not job.status.final:
            raise Problem(
                409, "job_not_done", f"the job is {job.status.value}", headers={"Retry-After": "1"}
            )
        if job.status is not Status.DONE:
            raise Problem(409, f"job_{job.status.value}", f"the job {job.status.value}: no result")

    def _has_layout(job: Job) -> None:
        if not job.has_layout:
            raise Problem(
                404,
                "no_layout",
                f"a {job.operation} job has no block layout of its result (each layer is "
                "quilted on its own, then mapped onto the surface)",
            )

    @app.get(
        "/jobs/{job_id}/result",
        operation_id="get_result",
        summary="The result PNG",
        responses={200: {"content": {"image/png": {}}}, **problems(401, 404, 409, 410, 422)},
    )
    async def get_result(job: JobOf) -> Response:
        _finished_result(job)
        data = _kept(await jobs.result(job))
        return Response(data, media_type="image/png", headers=_file_headers(job, ".png"))

    def _download_name(job: Job, suffix: str) -> str:
        """The file name of one of the job's downloads: its stem, then ``suffix``."""
        stem = job.download_stem or fallback_stem(job.operation, job.width, job.height)
        return stem + suffix

    def _attachment(filename: str) -> dict[str, str]:
        return {"Content-Disposition": content_disposition(filename)}

    # A finished job's files never change under their URL (a job id is never reused) and
    # are kept results_ttl_s: a browser may keep them that long; private, as they may
    # belong to an API key.
    file_cache = f"private, max-age={int(settings.results_ttl_s)}, immutable"

    def _file_headers(job: Job, suffix: str) -> dict[str, str]:
        """The headers of a finished job's file: its download name, and how long to keep it."""
        return {**_attachment(_download_name(job, suffix)), "Cache-Control": file_cache}

    def _kept(data: bytes | None) -> bytes:
        """A finished job's output, or 410 when it expired since the job was read."""
        if data is None:
            raise _expired()
        return data

    @app.get(
        "/jobs/{job_id}/result/{name}",
        operation_id="get_companion",
        summary="A quilted companion map",
        responses={200: {"content": {"image/png": {}}}, **problems(401, 404, 409, 410, 422)},
    )
    async def get_companion(job: JobOf, name: str) -> Response:
        _finished_result(job)
        if name not in job.companion_names:
            raise Problem(404, "companion_not_found", f"job has no companion {name!r}")
        data = _kept(await jobs.result(job, name))
        return Response(data, media_type="image/png", headers=_file_headers(job, f"-{name}.png"))

    @app.get(
        "/jobs/{job_id}/layout",
        operation_id="get_layout",
        summary="The block layout (JSON)",
        responses=problems(401, 404, 409, 410, 422),
    )
    async def get_layout(job: JobOf) -> Response:
        _finished_result(job)
        _has_layout(job)
        data = _kept(await jobs.layout(job))
        headers = _file_headers(job, "-layout.json")
        return Response(data, media_type="application/json", headers=headers)

    @app.get(
        "/jobs/{job_id}/seams",
        operation_id="get_seams",
        summary="The seams between blocks, as a transparent PNG to lay over the result",
        responses={200: {"content": {"image/png": {}}}, **problems(401, 404, 409, 410, 422, 503)},
    )
    async def get_seams(
        job: JobOf,
        color: Annotated[
            str, Query(description="Seam colour as six hex digits (RRGGBB).")
        ] = "ff0000",
    ) -> Response:
        if not HEX_COLOR.match(color):
            raise Problem(
                422, "invalid_parameter", "color must be six hex digits (RRGGBB)", field="color"
            )
        _finished_result(job)
        _has_layout(job)
        layout = _kept(await jobs.layout(job))
        png = await sandbox.run("seams", layout, color, doing="drawing the seams")
        return Response(png, media_type="image/png", headers=_file_headers(job, "-seams.png"))

    @app.get(
        "/jobs/{job_id}/events",
        operation_id="job_events",
        summary="Progress as server-sent events",
        description=(
            "A `progress` event whenever the job's progress or stage changes, then one event "
            "named after its final status (`done`, `failed`, `cancelled`) with the status "
            "document, and the stream ends. Every event has an `id:`, increasing over the "
            "job's life; a client that reconnects with `Last-Event-ID` gets only what came "
            "after it (and 204 No Content once it has had the final event)."
        ),
        responses={
            200: {"content": {"text/event-stream": {}}},
            204: {"description": "The final event was already sent (Last-Event-ID)"},
            **problems(401, 404, 422),
        },
    )
    async def job_events(
        job: JobOf,
        last_event_id: Annotated[
            str | None,
            Header(description="The id of the last event received: resume after it."),
        ] = None,
    ) -> Response:
        after = _last_event_id(last_event_id)
        if job.status.final and after >= END_EVENT_ID:
            # The client has the end: 204 also tells an EventSource not to reconnect.
            return Response(status_code=204)

        async def stream() -> AsyncIterator[str]:
            yield f"retry: {SSE_RETRY_MS}\n\n"
            last = after
            seen: tuple[float, str, Status] | None = None
            current = job
            while True:
                status = current.status
                if status.final:
                    event_id = max(END_EVENT_ID, last + 1)
                    data = json.dumps(current.snapshot())
                    yield f"id: {event_id}\nevent: {status.value}\ndata: {data}\n\n"
                    return
                now = (current.progress, current.stage, status)
                if now != seen:
                    first_look, seen = seen is None, now
                    event_id = event_position(status, now[0])
                    if event_id <= last and not first_look:
                        # A change this stream saw at a position it already used (a new stage
                        # at the same progress, or a job run again from 0): the next id.
                        event_id = last + 1
                    # Ids below the end event's stay below it, so that an id at or past it
                    # always means "had the end"; on a first look, a position at or before
                    # Last-Event-ID is what the client has already seen.
                    if last < event_id < END_EVENT_ID:
                        last = event_id
                        body = {"progress": now[0], "stage": now[1], "status": status.value}
                        yield f"id: {event_id}\nevent: progress\ndata: {json.dumps(body)}\n\n"
                await asyncio.sleep(POLL_S * 2)
                current = await jobs.refresh(current)

        return StreamingResponse(
            stream(), media_type="text/event-stream", headers={"Cache-Control": "no-cache"}
        )

    @app.delete(
        "/jobs/{job_id}", operation_id="cancel_job", summary="Cancel a job", status_code=202
    )
    async def cancel_job(job: JobOf) -> JSONResponse:
        if job.status in (Status.DONE, Status.FAILED):
            raise Problem(409, "job_finished", f"the job is already {job.status.value}")
        job = await jobs.cancel(job)
        return JSONResponse(job.snapshot(), status_code=202)

    # --- the browser page ------------------------------------------------------------------

    if settings.web_page:

        @app.get("/", include_in_schema=False)
        async def page_index() -> Response:
            return _page_file("index.html")

        @app.get("/web/{name}", include_in_schema=False)
        async def page_asset(name: str) -> Response:
            return _page_file(name)

    def _page_file(name: str) -> Response:
        page = page_files().get(name)
        if page is None:
            raise Problem(404, "not_found", f"the page has no file {name!r}")
        return Response(page.body, media_type=page.media_type, headers=page.headers)

    # --- the API docs (offline: quilting.service.apidocs) ----------------------------------

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui(request: Request) -> Response:
        root = str(request.scope.get("root_path", ""))
        apidocs.require("swagger-ui-bundle.js", "swagger-ui.css", "favicon.png")
        html = get_swagger_ui_html(
            openapi_url=root + str(app.openapi_url),
            title=f"{app.title} - Swagger UI",
            swagger_js_url=apidocs.asset_url(root, "swagger-ui-bundle.js"),
            swagger_css_url=apidocs.asset_url(root, "swagger-ui.css"),
            swagger_favicon_url=apidocs.asset_url(root, "favicon.png"),
            # On top of FastAPI's defaults: no validator badge (an image from swagger.io).
            swagger_ui_parameters={"validatorUrl": None},
        )
        return _docs_response(apidocs.page(bytes(html.body).decode()))

    @app.get("/redoc", include_in_schema=False)
    async def redoc(request: Request) -> Response:
        root = str(request.scope.get("root_path", ""))
        apidocs.require("redoc.standalone.js", "favicon.png")
        html = get_redoc_html(
            openapi_url=root + str(app.openapi_url),
            title=f"{app.title} - ReDoc",
            redoc_js_url=apidocs.asset_url(root, "redoc.standalone.js"),
            redoc_favicon_url=apidocs.asset_url(root, "favicon.png"),
            with_google_fonts=False,  # the system's fonts: nothing from Google
        )
        # ReDoc's styled-components add style elements at run time.
        return _docs_response(apidocs.page(bytes(html.body).decode(), inline_styles=True))

    @app.get(apidocs.STATIC_PATH + "/{name}", include_in_schema=False)
    async def docs_asset(
        name: str, if_none_match: Annotated[str | None, Header()] = None
    ) -> Response:
        found = apidocs.asset(name)
        if found is None:
            raise Problem(404, "not_found", f"the API docs have no file {name!r}")
        if if_none_match is not None and found.headers["ETag"] in if_none_match:
            return Response(status_code=304, headers=found.headers)
        return _docs_response(found)

    @app.exception_handler(apidocs.DocsUnavailableError)
    async def on_docs_unavailable(request: Request, exc: Exception) -> JSONResponse:
        # 503 docs_unavailable rather than a blank page when a bundle is missing.
        return _problem_response(Problem(503, "docs_unavailable", str(exc)))

    def _docs_response(found: apidocs.DocsFile) -> Response:
        return Response(found.body, media_type=found.media_type, headers=found.headers)

    # --- operations ------------------------------------------------------------------------

    @app.get("/healthz", operation_id="healthz", summary="Liveness")
    async def healthz() -> dict[str, str]:
        return {"status": "ok"}

    @app.get("/readyz", operation_id="readyz", summary="Readiness", responses=problems(503))
    async def readyz() -> JSONResponse:
        if app.state.draining:
            raise Problem(503, "draining", "the service is shutting down")
        fields = await jobs.readiness()
        if fields["queue_depth"] >= settings.max_queued:
            raise queue_full(fields["queue_depth"])
        return JSONResponse({"status": "ready", **fields})

    @app.get(
        "/metrics",
        operation_id="metrics",
        summary="Prometheus metrics",
        response_class=PlainTextResponse,
        dependencies=[Depends(metrics_reader)],
        responses=problems(401),
    )
    async def metrics() -> PlainTextResponse:
        text = _metrics_text(await jobs.figures())
        return PlainTextResponse(text, media_type="text/plain; version=0.0.4")

    original_openapi = app.openapi

    def openapi() -> dict[str, Any]:
        # The options field is JSON text in a form; publish its schema as a component.
        if app.openapi_schema is None:
            schema = original_openapi()
            components = schema.setdefault("components", {}).setdefault("schemas", {})
            components["SynthesizeOptions"] = SynthesizeOptions.model_json_schema()
            components["TransferOptions"] = TransferOptionsModel.model_json_schema()
            components["TileOptions"] = TileOptionsModel.model_json_schema()
            components["MatteOptions"] = MatteOptionsModel.model_json_schema()
            components["Problem"] = PROBLEM_SCHEMA
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app


def _metrics_text(figures: Figures) -> str:
    lines = [
        "# HELP quilting_jobs Jobs known to the service, by status.",
        "# TYPE quilting_jobs gauge",
    ]
    lines += [f'quilting_jobs{{status="{s}"}} {n}' for s, n in figures.counts.items()]
    lines += [
        "# HELP quilting_jobs_finished_total Jobs finished, by final status.",
        "# TYPE quilting_jobs_finished_total counter",
    ]
    lines += [
        f'quilting_jobs_finished_total{{status="{s}"}} {n}'
        for s, n in figures.finished_total.items()
    ]
    lines += [
        "# HELP quilting_queue_depth Jobs waiting for a worker.",
        "# TYPE quilting_queue_depth gauge",
        f"quilting_queue_depth {figures.queued}",
        "# HELP quilting_jobs_running Jobs being computed.",
        "# TYPE quilting_jobs_running gauge",
        f"quilting_jobs_running {figures.running}",
        "# HELP quilting_job_seconds Time from start to end of a job.",
        "# TYPE quilting_job_seconds histogram",
    ]
    cumulative = 0
    for bound, count in zip(HISTOGRAM_BUCKETS, figures.seconds_buckets, strict=False):
        cumulative += count
        lines.append(f'quilting_job_seconds_bucket{{le="{bound}"}} {cumulative}')
    total = sum(figures.seconds_buckets)
    lines += [
        f'quilting_job_seconds_bucket{{le="+Inf"}} {total}',
        f"quilting_job_seconds_sum {figures.seconds_sum}",
        f"quilting_job_seconds_count {total}",
        "# HELP quilting_pixels_produced_total Output pixels of finished jobs.",
        "# TYPE quilting_pixels_produced_total counter",
        f"quilting_pixels_produced_total {figures.pixels_total}",
        "# HELP quilting_results_bytes Bytes of results kept.",
        "# TYPE quilting_results_bytes gauge",
        f"quilting_results_bytes {figures.kept_bytes}",
    ]
    return "\n".join(lines) + "\n"
