"""The blocking client: performs the shared flows' actions with ``httpx.Client``.

Everything but the I/O is shared with :class:`~quilting_client.AsyncClient`: each public method
runs the flow of its name (:mod:`quilting_client._flows`) and takes its docstring from
:mod:`quilting_client._docs`; this module only sends, sleeps and reads event streams.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import ExitStack, closing
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


def _lines(response: httpx.Response) -> Iterator[str]:
    """The event stream's lines (see :class:`LineSplitter`: not httpx's ``iter_lines``, which
    also cuts at U+2028 and the other breaks ``str.splitlines`` knows)."""
    splitter = LineSplitter()
    for chunk in response.iter_text():
        yield from splitter.feed(chunk)
    yield from splitter.close()


class _EventStream:
    """An open ``text/event-stream`` response, read one event at a time."""

    def __init__(self, response: httpx.Response, limit: float | None) -> None:
        self._response = response
        self._lines = _lines(response)
        self._reader = EventReader(limit)

    def next(self) -> ServerEvent | None:
        """The next event; None at the end of the stream, or when it broke or went silent."""
        try:
            while self._reader.wants(next(self._lines, None)):
                pass
        except httpx.TransportError:
            return None  # A read timeout or a reset: the flow falls back on the job's status.
        return self._reader.pop()

    def close(self) -> None:
        """Close the response (and with it the connection of an unfinished stream)."""
        self._response.close()


class Client:
    """Blocking client of the quilting service.

    Parameters
    ----------
    base_url : str
        Where the service is, e.g. ``"http://127.0.0.1:8000"``.
    api_key : str or None
        Sent as ``Authorization: Bearer <key>`` when the service requires keys.
    timeout : float
        Seconds allowed to connect, send, and wait for each read of a response. Waiting for a
        job is bounded separately, by the ``timeout`` of :meth:`synthesize` and :meth:`wait`;
        :meth:`tile` may replace it for its one request.
    transport : httpx.BaseTransport or None
        A custom transport (e.g. ``httpx.MockTransport`` in tests).

    Examples
    --------
    >>> with Client("http://127.0.0.1:8000") as client:  # doctest: +SKIP
    ...     png = client.synthesize("gravel.png", width=512, height=512, block=32)
    """

    def __init__(
        self,
        base_url: str,
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        self._timeout = timeout
        settings = proto.client_settings(base_url, api_key, timeout)
        self._http = httpx.Client(transport=transport, **settings)

    def __enter__(self) -> Client:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Close the connections. The client cannot be used afterwards."""
        self._http.close()

    # -- the driver ----------------------------------------------------------------------------

    def _sleep(self, seconds: float) -> None:
        # A method, so that tests can record the delays instead of waiting them out.
        time.sleep(seconds)

    def _send(
        self, spec: RequestSpec, timeout: httpx.Timeout, *, stream: bool = False
    ) -> httpx.Response:
        request = self._http.build_request(**proto.request_kwargs(spec, timeout))
        with responses.transport_errors(request):
            response = self._http.send(request, stream=stream)
            if stream and response.is_error:
                # An error is a small problem document, not a stream: read it, then raise.
                with closing(response):
                    response.read()
        responses.raise_for_problem(response)
        return response

    def _open(self, spec: RequestSpec, limit: float | None) -> _EventStream:
        response = self._send(spec, proto.stream_timeout(self._timeout, limit), stream=True)
        return _EventStream(response, limit)

    def _perform(self, action: actions.Action, streams: ExitStack) -> actions.Reply:
        """Perform one action of a flow; its reply (see :mod:`quilting_client._actions`)."""
        match action:
            case actions.Send(spec):
                return self._send(spec, proto.request_timeout(self._timeout, spec))
            case actions.Sleep(seconds):
                self._sleep(seconds)
            case actions.OpenStream(spec, limit):
                return streams.enter_context(closing(self._open(spec, limit)))
            case actions.NextEvent(stream):
                return cast(_EventStream, stream).next()
            case actions.CloseStream(stream):
                cast(_EventStream, stream).close()
        return None

    def _run(self, flow: actions.Flow[T]) -> T:
        """Drive a flow to its end, performing its actions; its result."""
        with actions.Steps(flow) as steps, ExitStack() as streams:
            for action in steps:
                with steps.catching():
                    steps.reply = self._perform(action, streams)
        return steps.result

    # -- the API -------------------------------------------------------------------------------
    # Each method runs the flow of its name, handing it its own arguments (actions.start), and
    # takes its docstring from _docs (@shared), as the AsyncClient's namesake does.

    @shared
    def synthesize(
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
        return self._run(actions.start(flows.synthesize, locals()))

    @shared
    def submit(
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
        return self._run(actions.start(flows.submit, locals()))

    @shared
    def transfer(
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
        return self._run(actions.start(flows.transfer, locals()))

    @shared
    def submit_transfer(
        self,
        texture: ImageSource,
        target: ImageSource,
        *,
        companions: Mapping[str, ImageSource] | None = None,
        companion_kinds: Mapping[str, str] | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return self._run(actions.start(flows.submit_transfer, locals()))

    @shared
    def matte(
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
        return self._run(actions.start(flows.matte, locals()))

    @shared
    def submit_matte(
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
        return self._run(actions.start(flows.submit_matte, locals()))

    @shared
    def fill(
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
        return self._run(actions.start(flows.fill, locals()))

    @shared
    def submit_fill(
        self,
        image: ImageSource,
        mask: ImageSource,
        *,
        texture: ImageSource | None = None,
        companions: Mapping[str, ImageSource] | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return self._run(actions.start(flows.submit_fill, locals()))

    @shared
    def extend(
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
        return self._run(actions.start(flows.extend, locals()))

    @shared
    def submit_extend(
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
        return self._run(actions.start(flows.submit_extend, locals()))

    @shared
    def extract_alpha(
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
        return self._run(actions.start(flows.extract_alpha, locals()))

    @shared
    def submit_extract_alpha(
        self,
        photo: ImageSource,
        trimap: ImageSource | None = None,
        scribbles: ImageSource | None = None,
        *,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return self._run(actions.start(flows.submit_extract_alpha, locals()))

    @shared
    def wang_tiles(
        self,
        texture: ImageSource | Sequence[ImageSource],
        *,
        progress: ProgressCallback | None = None,
        poll_interval: float = 0.25,
        timeout: float | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> WangTilesResult:
        return self._run(actions.start(flows.wang_tiles, locals()))

    @shared
    def submit_wang_tiles(
        self,
        texture: ImageSource | Sequence[ImageSource],
        *,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        return self._run(actions.start(flows.submit_wang_tiles, locals()))

    @shared
    def tile(
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
        return self._run(actions.start(flows.tile, locals()))

    @shared
    def status(self, job_id: str) -> JobStatus:
        return self._run(actions.fetch_job(job_id))

    @shared
    def result(self, job_id: str, name: str | None = None) -> bytes:
        return self._run(actions.fetch_bytes(proto.result_request(job_id, name)))

    @shared
    def layout(self, job_id: str) -> dict[str, Any]:
        return self._run(actions.fetch_object(proto.layout_request(job_id)))

    @shared
    def manifest(self, job_id: str) -> dict[str, Any]:
        return self._run(actions.fetch_object(proto.manifest_request(job_id)))

    @shared
    def cancel(self, job_id: str) -> JobStatus:
        return self._run(actions.call_job(proto.cancel_request(job_id)))

    @shared
    def events(self, job_id: str) -> Iterator[tuple[str, dict[str, Any]]]:
        with closing(self._open(proto.events_request(job_id), None)) as stream:
            while (event := stream.next()) is not None:
                yield event.name, event.data

    @shared
    def wait(
        self,
        job_id: str,
        *,
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        poll_interval: float = 0.25,
    ) -> JobStatus:
        return self._run(actions.start(flows.wait, locals()))

    @shared
    def health(self) -> bool:
        return self._run(flows.health())

    @shared
    def ready(self) -> dict[str, Any]:
        return self._run(actions.fetch_object(proto.ready_request()))
