"""The asyncio client: performs the shared flows' actions with ``httpx.AsyncClient``.

Same API as :class:`quilting_client.Client`, with coroutines; the logic lives in the shared
flows, so only the I/O differs.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Iterable, Mapping, Sequence
from types import TracebackType
from typing import Any, TypeVar, cast

import httpx

from quilting_client import _flows as flows
from quilting_client import _protocol as proto
from quilting_client._protocol import ImageSource, RequestSpec, ServerEvent, SSEDecoder
from quilting_client.errors import ConnectionFailedError, QuiltingClientError
from quilting_client.models import JobStatus, SynthesisResult

T = TypeVar("T")


class _AsyncEventStream:
    """An open ``text/event-stream`` response, read one event at a time."""

    def __init__(self, response: httpx.Response, limit: float | None) -> None:
        self._response = response
        self._until = None if limit is None else time.monotonic() + limit
        self._lines = response.aiter_lines()
        self._decoder = SSEDecoder()

    async def next(self) -> ServerEvent | None:
        """The next event; None at the end of the stream, or when it broke or went silent."""
        try:
            async for line in self._lines:
                event = self._decoder.feed(line)
                if event is not None:
                    return event
                if self._until is not None and time.monotonic() >= self._until:
                    return None  # Only comments for too long: let the flow check the job.
        except httpx.TransportError:
            # A read timeout or a reset: the caller falls back on the job's status.
            return None
        return self._decoder.flush()

    async def close(self) -> None:
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
    base_url : str
        Where the service is, e.g. ``"http://127.0.0.1:8000"``.
    api_key : str or None
        Sent as ``Authorization: Bearer <key>`` when the service requires keys.
    timeout : float
        Seconds allowed to connect, send, and wait for each read of a response.
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
        self._http = httpx.AsyncClient(
            base_url=base_url,
            headers=proto.default_headers(api_key),
            timeout=timeout,
            transport=transport,
        )

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
        try:
            response = await self._http.send(request, stream=stream)
            if stream and response.is_error:
                # An error is a small problem document, not a stream: read it, then raise.
                try:
                    await response.aread()
                finally:
                    await response.aclose()
        except httpx.TransportError as exc:
            raise proto.connection_error(exc, request) from exc
        proto.raise_for_problem(response)
        return response

    async def _open(self, spec: RequestSpec, limit: float | None) -> _AsyncEventStream | None:
        try:
            response = await self._send(
                spec, proto.stream_timeout(self._timeout, limit), stream=True
            )
        except ConnectionFailedError as exc:
            # No answer within the silence allowed: see Client._open.
            if limit is not None and isinstance(exc.__cause__, httpx.TimeoutException):
                return None
            raise
        return _AsyncEventStream(response, limit)

    async def _run(self, flow: flows.Flow[T]) -> T:
        """Drive a flow to its end, performing its actions (see :mod:`quilting_client._flows`)."""
        stream: _AsyncEventStream | None = None
        reply: flows.Reply = None
        try:
            while True:
                try:
                    action = flow.send(reply)
                except StopIteration as stop:
                    return cast(T, stop.value)
                reply = None
                if isinstance(action, flows.Send):
                    reply = await self._send(
                        action.request, proto.request_timeout(self._timeout, action.request)
                    )
                elif isinstance(action, flows.Sleep):
                    await self._sleep(action.seconds)
                elif isinstance(action, flows.OpenStream):
                    stream = await self._open(action.request, action.limit)
                elif isinstance(action, flows.NextEvent):
                    reply = await stream.next() if stream is not None else None
                elif stream is not None:  # CloseStream
                    await stream.close()
                    stream = None
        finally:
            if stream is not None:
                await stream.close()
            flow.close()

    # -- the API -------------------------------------------------------------------------------

    async def synthesize(
        self,
        texture: ImageSource,
        *,
        width: int,
        height: int,
        companions: Mapping[str, ImageSource] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        progress: flows.ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        """Synthesize a texture and return the result PNG; see :meth:`Client.synthesize`.

        ``timeout`` bounds the wait; when it runs out :class:`WaitTimeoutError` is raised and
        the job is NOT cancelled.
        """
        return await self._run(
            flows.synthesize(
                texture,
                width=width,
                height=height,
                companions=companions,
                companion_kinds=companion_kinds,
                options=options,
                progress=progress,
                poll_interval=poll_interval,
                timeout=timeout,
                idempotency_key=idempotency_key,
            )
        )

    async def submit(
        self,
        texture: ImageSource,
        *,
        width: int,
        height: int,
        companions: Mapping[str, ImageSource] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        """Submit a job without waiting for it; see :meth:`Client.submit`."""
        return await self._run(
            flows.submit(
                texture,
                width=width,
                height=height,
                companions=companions,
                companion_kinds=companion_kinds,
                options=options,
                idempotency_key=idempotency_key,
            )
        )

    async def transfer(
        self,
        texture: ImageSource,
        target: ImageSource,
        *,
        companions: Mapping[str, ImageSource] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        progress: flows.ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        """Render ``target`` in the texture of ``texture``; see :meth:`Client.transfer`."""
        return await self._run(
            flows.transfer(
                texture,
                target,
                companions=companions,
                companion_kinds=companion_kinds,
                options=options,
                progress=progress,
                poll_interval=poll_interval,
                timeout=timeout,
                idempotency_key=idempotency_key,
            )
        )

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
        """Submit a transfer job without waiting for it; see :meth:`Client.submit_transfer`."""
        return await self._run(
            flows.submit_transfer(
                texture,
                target,
                companions=companions,
                companion_kinds=companion_kinds,
                options=options,
                idempotency_key=idempotency_key,
            )
        )

    async def matte(
        self,
        target: ImageSource,
        silhouette: ImageSource,
        layers: Sequence[ImageSource],
        *,
        normals: ImageSource | None = None,
        companions: Iterable[str] = (),
        progress: flows.ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> SynthesisResult:
        """Lay textures on the surface of the object in ``target``; see :meth:`Client.matte`.

        ``layers`` are sent bottom first; ``companions`` names the maps to download beside
        the result (``"normals"``, ``"clusters"``).
        """
        return await self._run(
            flows.matte(
                target,
                silhouette,
                layers,
                normals=normals,
                companions=companions,
                options=options,
                progress=progress,
                poll_interval=poll_interval,
                timeout=timeout,
                idempotency_key=idempotency_key,
            )
        )

    async def submit_matte(
        self,
        target: ImageSource,
        silhouette: ImageSource,
        layers: Sequence[ImageSource],
        *,
        normals: ImageSource | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        """Submit a matte job without waiting for it; see :meth:`Client.submit_matte`."""
        return await self._run(
            flows.submit_matte(
                target,
                silhouette,
                layers,
                normals=normals,
                options=options,
                idempotency_key=idempotency_key,
            )
        )

    async def tile(
        self,
        image: ImageSource,
        *,
        axes: str = "both",
        band: int | None = None,
        blend: str | None = None,
        timeout: float | None = None,
    ) -> bytes:
        """Make an image repeat seamlessly and return the PNG; see :meth:`Client.tile`.

        Answered at once (``POST /tile``), without a job.
        """
        return await self._run(
            flows.tile(image, axes=axes, band=band, blend=blend, timeout=timeout)
        )

    async def status(self, job_id: str) -> JobStatus:
        """The status of a job; see :meth:`Client.status`."""
        return await self._run(flows.fetch_job(job_id))

    async def result(self, job_id: str, name: str | None = None) -> bytes:
        """The result PNG, or a companion's; see :meth:`Client.result`."""
        return await self._run(flows.fetch_bytes(proto.result_request(job_id, name)))

    async def layout(self, job_id: str) -> dict[str, Any]:
        """The layout document of a finished job; see :meth:`Client.layout`."""
        return await self._run(flows.fetch_object(proto.layout_request(job_id)))

    async def cancel(self, job_id: str) -> JobStatus:
        """Ask for a job to be cancelled; see :meth:`Client.cancel`."""
        return await self._run(flows.call_job(proto.cancel_request(job_id)))

    async def events(self, job_id: str) -> AsyncIterator[tuple[str, dict[str, Any]]]:
        """The job's server-sent events as ``(name, data)``; see :meth:`Client.events`."""
        stream = await self._open(proto.events_request(job_id), None)
        assert stream is not None, "only a stream with a limit can fail to open"
        try:
            while (event := await stream.next()) is not None:
                yield event.name, event.data
        finally:
            await stream.close()

    async def wait(
        self,
        job_id: str,
        *,
        progress: flows.ProgressCallback | None = None,
        timeout: float | None = None,
        poll_interval: float = 0.25,
    ) -> JobStatus:
        """Wait for a job to end; see :meth:`Client.wait`. The job is not cancelled on timeout."""
        return await self._run(
            flows.wait(job_id, progress=progress, timeout=timeout, poll_interval=poll_interval)
        )

    async def health(self) -> bool:
        """Whether the service is up; False if it cannot be reached. See :meth:`Client.health`."""
        try:
            body = await self._run(flows.fetch_object(proto.health_request()))
        except QuiltingClientError:
            return False
        return body.get("status") == "ok"

    async def ready(self) -> dict[str, Any]:
        """The service's readiness; see :meth:`Client.ready`."""
        return await self._run(flows.fetch_object(proto.ready_request()))
