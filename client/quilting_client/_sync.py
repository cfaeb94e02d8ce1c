"""The blocking client: performs the shared flows' actions with ``httpx.Client``."""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from types import TracebackType
from typing import Any, TypeVar, cast

import httpx

from quilting_client import _flows as flows
from quilting_client import _protocol as proto
from quilting_client._protocol import ImageSource, RequestSpec, ServerEvent, SSEDecoder
from quilting_client.errors import ConnectionFailedError, QuiltingClientError
from quilting_client.models import JobStatus, SynthesisResult

T = TypeVar("T")


class _EventStream:
    """An open ``text/event-stream`` response, read one event at a time."""

    def __init__(self, response: httpx.Response, limit: float | None) -> None:
        self._response = response
        self._until = None if limit is None else time.monotonic() + limit
        self._lines = response.iter_lines()
        self._decoder = SSEDecoder()

    def next(self) -> ServerEvent | None:
        """The next event; None at the end of the stream, or when it broke or went silent."""
        try:
            for line in self._lines:
                event = self._decoder.feed(line)
                if event is not None:
                    return event
                if self._until is not None and time.monotonic() >= self._until:
                    return None  # Only comments for too long: let the flow check the job.
        except httpx.TransportError:
            # A read timeout or a reset: the caller falls back on the job's status.
            return None
        return self._decoder.flush()

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
        self._http = httpx.Client(
            base_url=base_url,
            headers=proto.default_headers(api_key),
            timeout=timeout,
            transport=transport,
        )

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
        try:
            response = self._http.send(request, stream=stream)
            if stream and response.is_error:
                # An error is a small problem document, not a stream: read it, then raise.
                try:
                    response.read()
                finally:
                    response.close()
        except httpx.TransportError as exc:
            raise proto.connection_error(exc, request) from exc
        proto.raise_for_problem(response)
        return response

    def _open(self, spec: RequestSpec, limit: float | None) -> _EventStream | None:
        try:
            response = self._send(spec, proto.stream_timeout(self._timeout, limit), stream=True)
        except ConnectionFailedError as exc:
            # No answer within the silence allowed: report no stream, so that the flow sees it
            # end and checks the job and the deadline, as for a stream that went silent.
            if limit is not None and isinstance(exc.__cause__, httpx.TimeoutException):
                return None
            raise
        return _EventStream(response, limit)

    def _run(self, flow: flows.Flow[T]) -> T:
        """Drive a flow to its end, performing its actions (see :mod:`quilting_client._flows`)."""
        stream: _EventStream | None = None
        reply: flows.Reply = None
        try:
            while True:
                try:
                    action = flow.send(reply)
                except StopIteration as stop:
                    return cast(T, stop.value)
                reply = None
                if isinstance(action, flows.Send):
                    reply = self._send(
                        action.request, proto.request_timeout(self._timeout, action.request)
                    )
                elif isinstance(action, flows.Sleep):
                    self._sleep(action.seconds)
                elif isinstance(action, flows.OpenStream):
                    stream = self._open(action.request, action.limit)
                elif isinstance(action, flows.NextEvent):
                    reply = stream.next() if stream is not None else None
                elif stream is not None:  # CloseStream
                    stream.close()
                    stream = None
        finally:
            if stream is not None:
                stream.close()
            flow.close()

    # -- the API -------------------------------------------------------------------------------

    def synthesize(
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
        """Synthesize a texture and return the result PNG.

        Submits the job asking the service to hold the answer a little (up to 10 s, 1 s with a
        progress callback); a job that finishes in that time comes back at once. Otherwise the
        job is followed, through its event stream when ``progress`` is given (which is then
        called on each progress event) or else by polling its status, honoring the service's
        ``Retry-After``; then the result is downloaded.

        Parameters
        ----------
        texture : str, os.PathLike or bytes
            The sample texture: a path to a PNG or JPEG file, or its bytes.
        width, height : int
            Output size in pixels.
        companions : Mapping[str, str | os.PathLike | bytes] or None
            Maps of the same size as the texture (normal, roughness...) to quilt with the same
            layout, by name (1 to 64 of ``A-Z a-z 0-9 _ -``).
        companion_kinds : Mapping[str, str] or None
            How companions are rendered, by name: 'blend' (the default: blended like the
            result), 'hard' (never mixed: masks, material IDs; not with ``mode='walk'``) or
            'normal' (blended, then renormalized to unit vectors; 3 or 4 channels). Sent as the
            ``companion_kinds`` form field; every name must be one of ``companions``.
        progress : callable or None
            ``progress(fraction, stage)``, called as the job advances.
        poll_interval : float
            Seconds between status polls, at least.
        timeout : float or None
            Seconds to wait for the job in all; None waits as long as it takes. When it runs
            out, :class:`WaitTimeoutError` is raised and the job is NOT cancelled: it keeps
            running on the service (cancel it with :meth:`cancel` if it is no longer wanted).
        idempotency_key : str or None
            Sent as ``Idempotency-Key``: retrying with the same key and body gives the same job.
        **options
            Any option of the service's ``SynthesizeOptions`` schema (its ``/openapi.json``;
            the client's copy, ``quilting_client/options.json``, lists them all: ``block``,
            ``blend``, ``tileable``, ``feather``, ``exclude_colors``...). None values are left
            to the service's defaults; the service refuses an unknown name.

        Returns
        -------
        SynthesisResult
            The result PNG (a ``bytes``), with ``job_id`` and the ``companions`` PNGs by name.

        Raises
        ------
        ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
            The service rejected the request (see :mod:`quilting_client.errors`).
        JobFailedError, JobCancelledError
            The job ended without a result; ``code`` and ``detail`` say why.
        WaitTimeoutError
            ``timeout`` ran out first.
        ConnectionFailedError
            The service could not be reached.
        """
        return self._run(
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

    def submit(
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
        """Submit a job without waiting for it.

        Parameters
        ----------
        texture, width, height, companions, idempotency_key, **options
            As for :meth:`synthesize`.

        Returns
        -------
        JobStatus
            The new job's status (usually ``queued``).
        """
        return self._run(
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

    def transfer(
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
        """Render ``target`` in the texture of ``texture`` and return the result PNG.

        Texture transfer (Efros & Freeman 2001, section 3): blocks of the texture are chosen
        to match both their neighbours and the target under them. The output has the
        target's size and the texture's channels. The job is submitted, followed and
        downloaded as in :meth:`synthesize`.

        Parameters
        ----------
        texture : str, os.PathLike or bytes
            The texture to render with: a path to a PNG or JPEG file, or its bytes.
        target : str, os.PathLike or bytes
            The image to render, likewise.
        companions, progress, poll_interval, timeout, idempotency_key
            As for :meth:`synthesize`; companions have the texture's size.
        **options
            Any option of the service's ``TransferOptions`` schema (``alpha``,
            ``iterations``, ``correspondence``, ``shade``... with the synthesis options they
            share; all in ``quilting_client/options.json``). None values are left to the
            service's defaults.

        Returns
        -------
        SynthesisResult
            The result PNG (a ``bytes``), with ``job_id`` and the ``companions`` PNGs by name.

        Raises
        ------
        ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
            The service rejected the request (see :mod:`quilting_client.errors`).
        JobFailedError, JobCancelledError
            The job ended without a result.
        WaitTimeoutError
            ``timeout`` ran out first (the job keeps running).
        ConnectionFailedError
            The service could not be reached.
        """
        return self._run(
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
        """Submit a transfer job without waiting for it.

        Parameters
        ----------
        texture, target, companions, idempotency_key, **options
            As for :meth:`transfer`.

        Returns
        -------
        JobStatus
            The new job's status (usually ``queued``; its ``operation`` is ``"transfer"``).
        """
        return self._run(
            flows.submit_transfer(
                texture,
                target,
                companions=companions,
                companion_kinds=companion_kinds,
                options=options,
                idempotency_key=idempotency_key,
            )
        )

    def matte(
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
        """Lay textures on the surface of the object in ``target`` and return the result PNG.

        Texture matting (the alpha quilting and texture matting paper, section 3): the
        surface's normals and the light are read from the target's shading inside the
        silhouette (or given), the surface is cut into patches, and each layer is quilted and
        laid on every patch's plane, shaded by the light, bottom layer first. The output has
        the target's size. The job is submitted, followed and downloaded as in
        :meth:`synthesize`.

        Parameters
        ----------
        target : str, os.PathLike or bytes
            The image with the object: a path to a PNG or JPEG file, or its bytes.
        silhouette : str, os.PathLike or bytes
            The target's size: white (or opaque) where the surface is, black elsewhere.
        layers : sequence of str, os.PathLike or bytes
            The textures to lay on the surface, bottom first (opaque ones first, then RGBA
            ones, which are alpha-quilted); at least one. A single image goes in a list.
        normals : str, os.PathLike, bytes or None
            A normal map of the target's size (``(n + 1) / 2`` colours, +y up) to use instead
            of the one read from the shading.
        companions : iterable of str
            The maps made beside the result to download into the result's ``companions``:
            ``"normals"`` (the normals used, as a normal map) and ``"clusters"`` (the patches
            in distinct colours). None by default; :meth:`result` fetches them later too.
        progress, poll_interval, timeout, idempotency_key
            As for :meth:`synthesize`.
        **options
            Matte options: ``clusters``, ``light`` (``(x, y, z)`` with z > 0, towards the
            light: x right, y up, z towards the viewer), ``smoothing``, ``min_z``,
            ``spatial_weight``, ``scale``, ``ambient``, and the quilting options applied to
            every layer: ``block``, ``overlap``, ``tolerance``, ``mode``, ``seed``,
            ``backend``, ``min_candidates``, ``error``, ``discard``, ``exclude_colors``,
            ``histogram_weight``, ``epsilon``, ``eta``. None values are left to the service's
            defaults (``light=None``: estimated from the shading).

        Returns
        -------
        SynthesisResult
            The result PNG (a ``bytes``), with ``job_id`` and the ``companions`` asked for by
            name. The job's status (:meth:`status`) has ``operation`` ``"matte"`` and, in its
            ``stats``, the ``light`` used, ``albedo``, ``ambient_fit``, ``clusters``,
            ``patches`` and ``layer_size``.

        Raises
        ------
        ValidationError, PayloadTooLargeError, UnsupportedMediaTypeError, ...
            The service rejected the request (HTTP 422: code ``invalid_parameter`` with the
            option in ``field``, ``invalid_image`` for a silhouette or normal map not of the
            target's size, ``too_many_layers``...); or, before anything is sent, no layer
            (code ``missing_field``) or a companion name the service cannot have.
        JobFailedError, JobCancelledError
            The job ended without a result.
        WaitTimeoutError
            ``timeout`` ran out first (the job keeps running).
        ConnectionFailedError
            The service could not be reached.
        TypeError
            ``layers`` is a single image, or ``companions`` a single name, not a collection.
        """
        return self._run(
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

    def submit_matte(
        self,
        target: ImageSource,
        silhouette: ImageSource,
        layers: Sequence[ImageSource],
        *,
        normals: ImageSource | None = None,
        idempotency_key: str | None = None,
        **options: object,
    ) -> JobStatus:
        """Submit a matte job without waiting for it.

        Parameters
        ----------
        target, silhouette, layers, normals, idempotency_key, **options
            As for :meth:`matte`.

        Returns
        -------
        JobStatus
            The new job's status (usually ``queued``; its ``operation`` is ``"matte"`` and its
            ``companions`` are ``("normals", "clusters")``, fetched with :meth:`result`).
        """
        return self._run(
            flows.submit_matte(
                target,
                silhouette,
                layers,
                normals=normals,
                options=options,
                idempotency_key=idempotency_key,
            )
        )

    def tile(
        self,
        image: ImageSource,
        *,
        axes: str = "both",
        band: int | None = None,
        blend: str | None = None,
        timeout: float | None = None,
    ) -> bytes:
        """Make an existing image repeat seamlessly and return the tileable PNG.

        The image keeps its size, bit depth and centre: only bands along its borders are
        replaced, inside minimum-error cuts, by the image rolled by half its size. The service
        answers at once with the PNG (``POST /tile``); no job is created, so there is no job id,
        progress or companion.

        Parameters
        ----------
        image : str, os.PathLike or bytes
            The image: a path to a PNG or JPEG file, or its bytes. Each tiled side at least 4
            pixels.
        axes : str
            Which wraps must be seamless: ``"both"``, ``"x"`` (the last column joins the first)
            or ``"y"`` (the last row joins the first).
        band : int or None
            Width in pixels of each border band the cuts may wander in, 1..side / 2 - 1; None
            leaves the service's default, a quarter of each side.
        blend : str or None
            How the cuts are joined: ``"none"``, as they are (every pixel an input pixel), or
            ``"poisson"``, blended in the gradient domain so that a brightness gradient across
            the photo does not show as steps along them; None leaves the service's default
            (``"none"``).
        timeout : float or None
            Seconds allowed to connect, send and wait for each read of the answer, in place of
            the client's ``timeout``; None keeps the client's. When it runs out,
            :class:`ConnectionFailedError` is raised.

        Returns
        -------
        bytes
            The tileable PNG, of the image's size.

        Raises
        ------
        ValidationError
            An option or the image was rejected (HTTP 422; ``code`` ``invalid_parameter`` and
            ``field`` ``"band"`` for a band too wide, ``invalid_image``, ``image_too_large``...).
        PayloadTooLargeError, UnsupportedMediaTypeError, AuthenticationError
            The service refused the upload (HTTP 413, 415, 401).
        ServiceUnavailableError
            The service is draining (HTTP 503); ``retry_after`` says when to try again.
        ConnectionFailedError
            The service could not be reached, or ``timeout`` ran out.
        ValueError
            ``timeout`` is not positive.
        """
        return self._run(flows.tile(image, axes=axes, band=band, blend=blend, timeout=timeout))

    def status(self, job_id: str) -> JobStatus:
        """The status of a job.

        Parameters
        ----------
        job_id : str
            The job.

        Returns
        -------
        JobStatus
        """
        return self._run(flows.fetch_job(job_id))

    def result(self, job_id: str, name: str | None = None) -> bytes:
        """The result PNG of a finished job, or one of its quilted companions.

        Parameters
        ----------
        job_id : str
            The job.
        name : str or None
            A companion's name (those of the job's status: a matte job's are ``"normals"``
            and ``"clusters"``); None for the result itself.

        Returns
        -------
        bytes
            The PNG.

        Raises
        ------
        ConflictError
            The job is not done (code ``job_not_done``, ``job_failed``, ``job_cancelled``).
        GoneError
            The results were evicted.
        """
        return self._run(flows.fetch_bytes(proto.result_request(job_id, name)))

    def layout(self, job_id: str) -> dict[str, Any]:
        """The layout document of a finished job (which block went where).

        Parameters
        ----------
        job_id : str
            The job.

        Returns
        -------
        dict

        Raises
        ------
        NotFoundError
            The job has no layout: a matte job's layers are quilted apart (code
            ``no_layout``).
        """
        return self._run(flows.fetch_object(proto.layout_request(job_id)))

    def cancel(self, job_id: str) -> JobStatus:
        """Ask for a job to be cancelled.

        Parameters
        ----------
        job_id : str
            The job.

        Returns
        -------
        JobStatus
            Its status; ``cancelled`` at once for a queued job, later for a running one.

        Raises
        ------
        ConflictError
            The job had already ended (code ``job_finished``).
        """
        return self._run(flows.call_job(proto.cancel_request(job_id)))

    def events(self, job_id: str) -> Iterator[tuple[str, dict[str, Any]]]:
        """The job's server-sent events, as they come, until the service ends the stream.

        Parameters
        ----------
        job_id : str
            The job.

        Yields
        ------
        tuple of (str, dict)
            ``("progress", {"progress", "stage", "status"})`` events, then one terminal
            ``("done" | "failed" | "cancelled", <job status JSON>)``.
        """
        stream = self._open(proto.events_request(job_id), None)
        assert stream is not None, "only a stream with a limit can fail to open"
        try:
            while (event := stream.next()) is not None:
                yield event.name, event.data
        finally:
            stream.close()

    def wait(
        self,
        job_id: str,
        *,
        progress: flows.ProgressCallback | None = None,
        timeout: float | None = None,
        poll_interval: float = 0.25,
    ) -> JobStatus:
        """Wait for a job to end.

        Parameters
        ----------
        job_id : str
            The job.
        progress : callable or None
            ``progress(fraction, stage)``; given, the event stream is followed instead of
            polling.
        timeout : float or None
            Seconds to wait; None waits as long as it takes. The job is NOT cancelled when
            it runs out.
        poll_interval : float
            Seconds between status polls, at least.

        Returns
        -------
        JobStatus
            The final status of the job, which is ``done``.

        Raises
        ------
        JobFailedError, JobCancelledError
            The job ended without a result (the error's ``job`` is its final status).
        WaitTimeoutError
            ``timeout`` ran out first.
        """
        return self._run(
            flows.wait(job_id, progress=progress, timeout=timeout, poll_interval=poll_interval)
        )

    def health(self) -> bool:
        """Whether the service is up (``GET /healthz``); False if it cannot be reached.

        Returns
        -------
        bool
        """
        try:
            return self._run(flows.fetch_object(proto.health_request())).get("status") == "ok"
        except QuiltingClientError:
            return False

    def ready(self) -> dict[str, Any]:
        """The service's readiness (``GET /readyz``): backend, queue depth, workers.

        Returns
        -------
        dict

        Raises
        ------
        ServiceUnavailableError
            The service is draining or its queue is full (code ``draining`` / ``queue_full``).
        """
        return self._run(flows.fetch_object(proto.ready_request()))
