"""The asyncio client: performs the shared flows' actions with ``httpx.AsyncClient``.

Same API as :class:`quilting_client.Client`, with coroutines: each public method runs the flow
of its name (:mod:`quilting_client._flows`) and takes its docstring from
:mod:`quilting_client._docs`, as the blocking client's does, so only the I/O differs.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterable, Mapping, Sequence
from contextlib import AsyncExitStack, aclosing
from types import TracebackType
from typing import Any, TypeVar, cast

import httpx

from quilting_client import _actions as actions
from quilting_client import _flows as flows
from quilting_client import _protocol as proto
from quilting_client import _responses as responses
from quilting_client._docs import shared
from quilting_client._events import EventReader, LineSplitter, ServerEvent
from quilting_client._protocol import Marks, RequestSpec
from quilting_client._uploads import ImageSource
from quilting_client._waiting import ProgressCallback
from quilting_client.models import JobStatus, SynthesisResult, WangTilesResult

T = TypeVar("T")


async def _lines(response: httpx.Response) -> AsyncIterator[str]:
    """The event stream's lines (see the sync client's ``_lines``)."""
    splitter = LineSplitter()
    async for chunk in response.aiter_text():
        for line in splitter.feed(chunk):
            yield line
    for line in splitter.close():
        yield line


class _AsyncEventStream:
    """An open ``text/event-stream`` response, read one event at a time."""

    def __init__(self, response: httpx.Response, limit: float | None) -> None:
        self._response = response
        self._lines = _lines(response)
        self._reader = EventReader(limit)

    async def next(self) -> ServerEvent | None:
        """The next event; None at the end of the stream, or when it broke or went silent."""
        try:
            while self._reader.wants(await anext(self._lines, None)):
                pass
        except httpx.TransportError:
            return None  # See _EventStream.next.
        return self._reader.pop()

    async def aclose(self) -> None:
        """Close the response (and with it the connection of an unfinished stream)."""
        # Finish the line generator first, so that it is not left for the garbage collector
        # to finalize (possibly after the event loop is gone).
        aclose = getattr(self._lines, "aclose", None)
        if aclose is not None:
            await aclose()
        await self._response.aclose()


class AsyncClient:
    """Asynchronous (asyncio) client of the quilting service.

    Parameters
    ----------
    base_url, api_key, timeout
        As for :class:`Client`.
    transport : httpx.AsyncBaseTransport or None
        A custom transport (e.g. ``httpx.MockTransport`` in tests).

    See Also
    --------
    Client : the blocking client; every method here is the coroutine of its namesake there.
    """

    def __init__(
        self,
        base_url: str,
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        self._timeout = timeout
        settings = proto.client_settings(base_url, api_key, timeout)
        self._http = httpx.AsyncClient(transport=transport, **settings)

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Close the connections. The client cannot be used afterwards."""
        await self._http.aclose()

    # -- the driver ----------------------------------------------------------------------------

    async def _sleep(self, seconds: float) -> None:
        # A method, so that tests can record the delays instead of waiting them out.
        await asyncio.sleep(seconds)

    async def _send(
        self, spec: RequestSpec, timeout: httpx.Timeout, *, stream: bool = False
    ) -> httpx.Response:
        request = self._http.build_request(**proto.request_kwargs(spec, timeout))
        with responses.transport_errors(request):
            response = await self._http.send(request, stream=stream)
            if stream and response.is_error:
                # An error is a small problem document, not a stream: read it, then raise.
                async with aclosing(response):
                    await response.aread()
        responses.raise_for_problem(response)
        return response

    async def _open(self, spec: RequestSpec, limit: float | None) -> _AsyncEventStream:
        timeout = proto.stream_timeout(self._timeout, limit)
        return _AsyncEventStream(await self._send(spec, timeout, stream=True), limit)

    async def _perform(self, action: actions.Action, streams: AsyncExitStack) -> actions.Reply:
        """Perform one action of a flow; its reply (see :mod:`quilting_client._actions`)."""
        match action:
            case actions.Send(spec):
                return await self._send(spec, proto.request_timeout(self._timeout, spec))
            case actions.Sleep(seconds):
                await self._sleep(seconds)
            case actions.OpenStream(spec, limit):
                return await streams.enter_async_context(aclosing(await self._open(spec, limit)))
            case actions.NextEvent(stream):
                return await cast(_AsyncEventStream, stream).next()
            case actions.CloseStream(stream):
                await cast(_AsyncEventStream, stream).aclose()
        return None

    async def _run(self, flow: actions.Flow[T]) -> T:
        """Drive a flow to its end, performing its actions; its result."""
        with actions.Steps(flow) as steps:
            async with AsyncExitStack() as streams:
                for action in steps:
                    with steps.catching():
                        steps.reply = await self._perform(action, streams)
        return steps.result

    # -- the API -------------------------------------------------------------------------------
    # The coroutines of the Client's methods, each running the flow of its name with its own
    # arguments (actions.start), its docstring from _docs (@shared).

    @shared
    async def synthesize(
        self,
        texture: ImageSource | Sequence[ImageSource],
        *,
        width: int,
        height: int,
        companions: Mapping[str, ImageSource | Sequence[ImageSource]] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        source_mask: ImageSource | Sequence[ImageSource] | None = None,
        trimap: Marks = None,
        scribbles: Marks = None,
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        return await self._run(actions.start(flows.synthesize, locals()))

    @shared
    async def submit(
        self,
        texture: ImageSource | Sequence[ImageSource],
        *,
        width: int,
        height: int,
        companions: Mapping[str, ImageSource | Sequence[ImageSource]] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        source_mask: ImageSource | Sequence[ImageSource] | None = None,
        trimap: Marks = None,
        scribbles: Marks = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return await self._run(actions.start(flows.submit, locals()))

    @shared
    async def transfer(
        self,
        texture: ImageSource,
        target: ImageSource,
        *,
        companions: Mapping[str, ImageSource] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        return await self._run(actions.start(flows.transfer, locals()))

    @shared
    async def submit_transfer(
        self,
        texture: ImageSource,
        target: ImageSource,
        *,
        companions: Mapping[str, ImageSource] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return await self._run(actions.start(flows.submit_transfer, locals()))

    @shared
    async def matte(
        self,
        target: ImageSource,
        silhouette: ImageSource,
        layers: Sequence[ImageSource],
        *,
        normals: ImageSource | None = None,
        trimap: Sequence[ImageSource | None] | None = None,
        scribbles: Sequence[ImageSource | None] | None = None,
        companions: Iterable[str] = (),
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        return await self._run(actions.start(flows.matte, locals()))

    @shared
    async def submit_matte(
        self,
        target: ImageSource,
        silhouette: ImageSource,
        layers: Sequence[ImageSource],
        *,
        normals: ImageSource | None = None,
        trimap: Sequence[ImageSource | None] | None = None,
        scribbles: Sequence[ImageSource | None] | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return await self._run(actions.start(flows.submit_matte, locals()))

    @shared
    async def fill(
        self,
        image: ImageSource,
        mask: ImageSource,
        *,
        texture: ImageSource | None = None,
        companions: Mapping[str, ImageSource] | None = None,
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        return await self._run(actions.start(flows.fill, locals()))

    @shared
    async def submit_fill(
        self,
        image: ImageSource,
        mask: ImageSource,
        *,
        texture: ImageSource | None = None,
        companions: Mapping[str, ImageSource] | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return await self._run(actions.start(flows.submit_fill, locals()))

    @shared
    async def extend(
        self,
        image: ImageSource,
        *,
        top: int = 0,
        bottom: int = 0,
        left: int = 0,
        right: int = 0,
        companions: Mapping[str, ImageSource] | None = None,
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        return await self._run(actions.start(flows.extend, locals()))

    @shared
    async def submit_extend(
        self,
        image: ImageSource,
        *,
        top: int = 0,
        bottom: int = 0,
        left: int = 0,
        right: int = 0,
        companions: Mapping[str, ImageSource] | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return await self._run(actions.start(flows.submit_extend, locals()))

    @shared
    async def extract_alpha(
        self,
        photo: ImageSource,
        trimap: ImageSource | None = None,
        scribbles: ImageSource | None = None,
        *,
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        return await self._run(actions.start(flows.extract_alpha, locals()))

    @shared
    async def submit_extract_alpha(
        self,
        photo: ImageSource,
        trimap: ImageSource | None = None,
        scribbles: ImageSource | None = None,
        *,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return await self._run(actions.start(flows.submit_extract_alpha, locals()))

    @shared
    async def wang_tiles(
        self,
        texture: ImageSource | Sequence[ImageSource],
        *,
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> WangTilesResult:
        return await self._run(actions.start(flows.wang_tiles, locals()))

    @shared
    async def submit_wang_tiles(
        self,
        texture: ImageSource | Sequence[ImageSource],
        *,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return await self._run(actions.start(flows.submit_wang_tiles, locals()))

    @shared
    async def tile(
        self,
        image: ImageSource,
        *,
        axes: str = "both",
        band: int | None = None,
        blend: str | None = None,
        method: str | None = None,
        seed: int | None = None,
        timeout: float | None = None,
    ) -> bytes:
        return await self._run(actions.start(flows.tile, locals()))

    @shared
    async def status(self, job_id: str) -> JobStatus:
        return await self._run(actions.fetch_job(job_id))

    @shared
    async def result(self, job_id: str, name: str | None = None) -> bytes:
        return await self._run(actions.fetch_bytes(proto.result_request(job_id, name)))

    @shared
    async def layout(self, job_id: str) -> dict[str, Any]:
        return await self._run(actions.fetch_object(proto.layout_request(job_id)))

    @shared
    async def manifest(self, job_id: str) -> dict[str, Any]:
        return await self._run(actions.fetch_object(proto.manifest_request(job_id)))

    @shared
    async def cancel(self, job_id: str) -> JobStatus:
        return await self._run(actions.call_job(proto.cancel_request(job_id)))

    @shared
    async def events(self, job_id: str) -> AsyncIterator[tuple[str, dict[str, Any]]]:
        stream = await self._open(proto.events_request(job_id), None)
        async with aclosing(stream):
            while (event := await stream.next()) is not None:
                yield event.name, event.data

    @shared
    async def wait(
        self,
        job_id: str,
        *,
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        poll_interval: float = 0.25,
    ) -> JobStatus:
        return await self._run(actions.start(flows.wait, locals()))

    @shared
    async def health(self) -> bool:
        return await self._run(flows.health())

    @shared
    async def ready(self) -> dict[str, Any]:
        return await self._run(actions.fetch_object(proto.ready_request()))
