"""The quilting client against an in-process fake of the service (httpx.MockTransport).

The fake answers per route from scripted responses and records every request, so the tests
check both what the client sends (paths, query, headers, multipart parts) and how it reads the
answers. Most tests run twice, against ``Client`` and ``AsyncClient``, through an adapter that
runs the coroutines. The real service is exercised end to end elsewhere.
"""

from __future__ import annotations

import asyncio
import inspect
import io
import json
import struct
import time
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from quilting_client import (
    AsyncClient,
    AuthenticationError,
    Client,
    ConflictError,
    ConnectionFailedError,
    GoneError,
    JobCancelledError,
    JobFailedError,
    JobStatus,
    NotFoundError,
    PayloadTooLargeError,
    QuiltingClientError,
    ServerError,
    ServiceUnavailableError,
    SynthesisResult,
    UnsupportedMediaTypeError,
    ValidationError,
    WaitTimeoutError,
    cli,
)
from quilting_client import _flows as flows
from quilting_client import _protocol as proto
from quilting_client._protocol import ServerEvent, SSEDecoder

BASE = "http://quilting.test"
# Bytes that a sloppy multipart encoder or parser would mangle: CR LF, dashes, NUL, high bytes.
TEXTURE = b"\x89PNG\r\n\x1a\ntexture\r\n--\r\n\x00\xff"
RESULT = b"\x89PNG\r\n\x1a\nresult\r\n\r\n--x\x00"
NORMAL = b"\x89PNG\r\n\x1a\nnormal map"
NORMAL_OUT = b"\x89PNG\r\n\x1a\nquilted normal map"
ROUGH = b"\xff\xd8\xffrough jpeg"

Handler = Callable[[httpx.Request], httpx.Response]


# -- the fake service --------------------------------------------------------------------------


class FakeService:
    """Scripted answers per (method, path); the last one of a route repeats. Records requests."""

    def __init__(self) -> None:
        self.routes: dict[tuple[str, str], list[Handler]] = {}
        self.requests: list[httpx.Request] = []

    def on(self, method: str, path: str, *answers: Handler) -> FakeService:
        self.routes.setdefault((method, path), []).extend(answers)
        return self

    def __call__(self, request: httpx.Request) -> httpx.Response:
        self.requests.append(request)
        # A client that never stops polling fails the test instead of hanging it.
        assert len(self.requests) < 500, "runaway client: 500 requests"
        # Routed on the raw path, so that a percent-encoded "/" is seen as sent.
        queue = self.routes.get((request.method, self.path_of(request)))
        if not queue:
            return problem(404, "no_route", f"no route {request.method} {self.path_of(request)}")(
                request
            )
        answer = queue.pop(0) if len(queue) > 1 else queue[0]
        return answer(request)

    @staticmethod
    def path_of(request: httpx.Request) -> str:
        return request.url.raw_path.decode("ascii").split("?", 1)[0]

    def paths(self) -> list[str]:
        return [f"{r.method} {self.path_of(r)}" for r in self.requests]

    def only(self, method: str, path: str) -> httpx.Request:
        matching = [r for r in self.requests if (r.method, self.path_of(r)) == (method, path)]
        assert len(matching) == 1, self.paths()
        return matching[0]


def job_json(status: str = "queued", job_id: str = "j1", **extra: Any) -> dict[str, Any]:
    body: dict[str, Any] = {
        "id": job_id,
        "status": status,
        "progress": 1.0 if status == "done" else 0.0,
        "stage": status,
        "created": 1700000000.0,
        "started": None,
        "finished": None,
        "timings": {},
        "backend": None,
        "error": None,
        "result": f"/jobs/{job_id}/result" if status == "done" else None,
        "companions": [],
        "layout": None,
        "stats": None,
        "width": 64,
        "height": 32,
    }
    body.update(extra)
    return body


def json_answer(status: int, body: Any, headers: dict[str, str] | None = None) -> Handler:
    return lambda request: httpx.Response(status, json=body, headers=headers)


def png(content: bytes = RESULT, job_id: str | None = "j1") -> Handler:
    headers = {"Content-Type": "image/png"}
    if job_id is not None:
        headers |= {"X-Job-Id": job_id, "Location": f"/jobs/{job_id}"}
    return lambda request: httpx.Response(200, content=content, headers=headers)


def accepted(job_id: str = "j1", retry_after: str | None = "1") -> Handler:
    headers = {"Location": f"/jobs/{job_id}"}
    if retry_after is not None:
        headers["Retry-After"] = retry_after
    return json_answer(202, job_json("queued", job_id), headers)


def problem(status: int, code: str, detail: str, **members: Any) -> Handler:
    body = {
        "type": f"https://quilting.dev/problems/{code}",
        "title": code.replace("_", " "),
        "status": status,
        "detail": detail,
        "code": code,
        **members,
    }
    headers = {"Content-Type": "application/problem+json"}
    if status == 503:
        headers["Retry-After"] = "7"
    return lambda request: httpx.Response(status, content=json.dumps(body), headers=headers)


def sse(*events: tuple[str, dict[str, Any]], comment: bool = True) -> Handler:
    text = ": connected\n\n" if comment else ""
    for name, data in events:
        text += f"event: {name}\ndata: {json.dumps(data)}\n\n"
    return lambda request: httpx.Response(
        200, content=text.encode(), headers={"Content-Type": "text/event-stream"}
    )


def fails(exc: Exception) -> Handler:
    def answer(request: httpx.Request) -> httpx.Response:
        raise exc

    return answer


def multipart(request: httpx.Request) -> list[tuple[str, str | None, bytes]]:
    """The (name, filename, content) of each part, parsed by hand to check the wire format."""
    content_type = request.headers["Content-Type"]
    assert content_type.startswith("multipart/form-data; boundary=")
    boundary = content_type.split("boundary=", 1)[1].strip('"').encode()
    chunks = request.content.split(b"--" + boundary)
    assert chunks[0] == b"" and chunks[-1] == b"--\r\n"
    parts = []
    for chunk in chunks[1:-1]:
        assert chunk.startswith(b"\r\n") and chunk.endswith(b"\r\n")
        head, _, body = chunk[2:-2].partition(b"\r\n\r\n")
        disposition = next(
            line for line in head.decode().split("\r\n") if line.lower().startswith("content-disp")
        )
        fields = dict(
            item.strip().split("=", 1) for item in disposition.split(";")[1:] if "=" in item
        )
        filename = fields.get("filename")
        parts.append((fields["name"].strip('"'), filename.strip('"') if filename else None, body))
    return parts


# -- one test body for both clients --------------------------------------------------------------


class AsyncAdapter:
    """Presents an AsyncClient with the blocking API, so one test body covers both clients."""

    def __init__(self, client: AsyncClient) -> None:
        self.client = client
        self.loop = asyncio.new_event_loop()

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self.client, name)
        if name == "events":

            def collect(*args: Any, **kwargs: Any) -> Iterator[tuple[str, dict[str, Any]]]:
                async def drain() -> list[tuple[str, dict[str, Any]]]:
                    return [event async for event in attr(*args, **kwargs)]

                return iter(self.loop.run_until_complete(drain()))

            return collect
        if not inspect.iscoroutinefunction(attr):
            return attr
        return lambda *args, **kwargs: self.loop.run_until_complete(attr(*args, **kwargs))

    def close(self) -> None:
        self.loop.run_until_complete(self.client.aclose())
        self.loop.close()


@pytest.fixture(params=["sync", "async"])
def connect(request: pytest.FixtureRequest) -> Iterator[Callable[..., Any]]:
    """``connect(service, api_key=None, real_sleep=False)`` -> a client; ``.sleeps`` records."""
    opened: list[Any] = []

    def make(service: FakeService, api_key: str | None = None, real_sleep: bool = False) -> Any:
        transport = httpx.MockTransport(service)
        sleeps: list[float] = []
        client: Any
        if request.param == "sync":
            client = Client(BASE, api_key, transport=transport)
            if not real_sleep:
                client._sleep = sleeps.append
            wrapped: Any = client
        else:
            client = AsyncClient(BASE, api_key, transport=transport)
            if not real_sleep:

                async def record(seconds: float) -> None:
                    sleeps.append(seconds)

                client._sleep = record
            wrapped = AsyncAdapter(client)
        wrapped.sleeps = sleeps
        opened.append(wrapped)
        return wrapped

    yield make
    for client in opened:
        client.close()


def options_of(request: httpx.Request) -> dict[str, Any]:
    [options] = [body for name, _, body in multipart(request) if name == "options"]
    return dict(json.loads(options))


# -- synthesize --------------------------------------------------------------------------------


def test_synthesize_returns_the_png_of_a_200(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/synthesize", png())
    client = connect(service)
    result = client.synthesize(TEXTURE, width=64, height=32, block=16)
    assert result == RESULT
    assert isinstance(result, SynthesisResult) and isinstance(result, bytes)
    assert result.job_id == "j1" and result.companions == {}
    assert service.paths() == ["POST /synthesize"]
    post = service.requests[0]
    assert post.url.params["wait"] == "10"
    assert options_of(post) == {"width": 64, "height": 32, "block": 16}
    assert client.sleeps == []


@pytest.mark.parametrize(
    ("timeout", "progress", "wait"), [(3.0, False, "3"), (None, True, "1"), (0.5, True, "0.5")]
)
def test_synthesize_holds_the_post_briefly(
    connect: Callable[..., Any], timeout: float | None, progress: bool, wait: str
) -> None:
    service = FakeService().on("POST", "/synthesize", png())
    client = connect(service)
    calls: list[tuple[float, str]] = []
    callback = (lambda f, s: calls.append((f, s))) if progress else None
    client.synthesize(TEXTURE, width=64, height=32, timeout=timeout, progress=callback)
    assert service.requests[0].url.params["wait"] == wait
    # A result that came at once still completes a progress bar.
    assert calls == ([(1.0, "done")] if progress else [])


def test_synthesize_polls_honoring_retry_after(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", accepted(retry_after="2"))
        .on(
            "GET",
            "/jobs/j1",
            json_answer(200, job_json("running"), {"Retry-After": "1"}),
            json_answer(200, job_json("running")),
            json_answer(200, job_json("done")),
        )
        .on("GET", "/jobs/j1/result", png())
    )
    client = connect(service)
    result = client.synthesize(TEXTURE, width=64, height=32, poll_interval=0.05)
    assert result == RESULT and result.job_id == "j1"
    # 2 s from the 202's Retry-After, 1 s from the first poll's, then the poll interval.
    assert client.sleeps == [2.0, 1.0, 0.05]
    assert service.paths() == [
        "POST /synthesize",
        "GET /jobs/j1",
        "GET /jobs/j1",
        "GET /jobs/j1",
        "GET /jobs/j1/result",
    ]


def test_poll_interval_is_a_floor_under_retry_after(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", accepted(retry_after="0"))
        .on("GET", "/jobs/j1", json_answer(200, job_json("done")))
        .on("GET", "/jobs/j1/result", png())
    )
    client = connect(service)
    client.synthesize(TEXTURE, width=64, height=32, poll_interval=0.3)
    assert client.sleeps == [0.3]


def test_synthesize_follows_events_with_a_progress_callback(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", accepted())
        .on(
            "GET",
            "/jobs/j1/events",
            sse(
                ("progress", {"progress": 0.25, "stage": "quilting", "status": "running"}),
                ("progress", {"progress": 0.75, "stage": "seams", "status": "running"}),
                ("done", job_json("done", stage="done")),
            ),
        )
        .on("GET", "/jobs/j1/result", png())
    )
    client = connect(service)
    calls: list[tuple[float, str]] = []
    result = client.synthesize(
        TEXTURE, width=64, height=32, progress=lambda f, s: calls.append((f, s))
    )
    assert result == RESULT
    assert calls == [(0.25, "quilting"), (0.75, "seams"), (1.0, "done")]
    # The stream replaces polling, and the 202's Retry-After is not waited out.
    assert service.paths() == ["POST /synthesize", "GET /jobs/j1/events", "GET /jobs/j1/result"]
    assert service.requests[1].headers["Accept"] == "text/event-stream"
    assert client.sleeps == []


def test_an_event_stream_that_ends_early_falls_back_on_the_status(
    connect: Callable[..., Any],
) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", accepted())
        .on(
            "GET",
            "/jobs/j1/events",
            sse(("progress", {"progress": 0.5, "stage": "quilting", "status": "running"})),
        )
        .on("GET", "/jobs/j1", json_answer(200, job_json("done")))
        .on("GET", "/jobs/j1/result", png())
    )
    client = connect(service)
    calls: list[tuple[float, str]] = []
    result = client.synthesize(
        TEXTURE, width=64, height=32, progress=lambda f, s: calls.append((f, s))
    )
    assert result == RESULT
    assert calls == [(0.5, "quilting")]
    assert service.paths() == [
        "POST /synthesize",
        "GET /jobs/j1/events",
        "GET /jobs/j1",
        "GET /jobs/j1/result",
    ]


FAILED = job_json(
    "failed",
    error={
        "type": "https://quilting.dev/problems/engine_error",
        "title": "engine error",
        "status": 500,
        "detail": "the cost backend crashed",
        "code": "engine_error",
    },
)


@pytest.mark.parametrize("follow", ["poll", "events"])
def test_a_failed_job_raises_job_failed_error(connect: Callable[..., Any], follow: str) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", accepted())
        .on("GET", "/jobs/j1", json_answer(200, FAILED))
        .on("GET", "/jobs/j1/events", sse(("failed", FAILED)))
    )
    client = connect(service)
    progress = (lambda f, s: None) if follow == "events" else None
    with pytest.raises(JobFailedError) as caught:
        client.synthesize(TEXTURE, width=64, height=32, progress=progress)
    error = caught.value
    assert error.code == "engine_error"
    assert error.detail.endswith("the cost backend crashed")
    assert error.status == 500
    assert error.job.status == "failed" and error.job.id == "j1"
    assert "GET /jobs/j1/result" not in service.paths()


def test_a_cancelled_job_raises_job_cancelled_error(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", accepted())
        .on("GET", "/jobs/j1", json_answer(200, job_json("cancelled")))
    )
    client = connect(service)
    with pytest.raises(JobCancelledError) as caught:
        client.synthesize(TEXTURE, width=64, height=32)
    assert caught.value.code == "job_cancelled"
    assert not isinstance(caught.value, JobFailedError)


#: Seconds within which a client with a timeout of a fraction of a second must have given up:
#: far past its timeout, far short of the chatty stream's length.
LATE_S = 10.0


@pytest.mark.parametrize("follow", ["poll", "events"])
def test_timeout_raises_wait_timeout_error_and_leaves_the_job(
    connect: Callable[..., Any], follow: str
) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", accepted(retry_after=None))
        .on("GET", "/jobs/j1", json_answer(200, job_json("running")))
        # A stream that ends without news each time: the client must still give up in time.
        .on("GET", "/jobs/j1/events", sse())
    )
    client = connect(service, real_sleep=True)
    progress = (lambda f, s: None) if follow == "events" else None
    started = time.monotonic()
    with pytest.raises(WaitTimeoutError) as caught:
        client.synthesize(
            TEXTURE, width=64, height=32, timeout=0.05, poll_interval=0.01, progress=progress
        )
    # Gives up (a client that ignored its timeout would wait for ever); LATE_S, not a tight
    # bound, so that a busy machine's scheduling delays never count as lateness.
    assert time.monotonic() - started < LATE_S
    assert isinstance(caught.value, TimeoutError) and isinstance(caught.value, QuiltingClientError)
    assert caught.value.job_id == "j1" and caught.value.code == "wait_timeout"
    assert caught.value.job is not None and caught.value.job.status == "running"
    assert not any(r.method == "DELETE" for r in service.requests)


class ChattyStream(httpx.SyncByteStream, httpx.AsyncByteStream):
    """An event stream that does not end on its own for a minute: progress events or comments,
    100 per second."""

    LINES = 6000

    def __init__(self, line: bytes) -> None:
        self.line = line

    def __iter__(self) -> Iterator[bytes]:
        for _ in range(self.LINES):
            time.sleep(0.01)
            yield self.line

    async def __aiter__(self) -> AsyncIterator[bytes]:
        for _ in range(self.LINES):
            await asyncio.sleep(0.01)
            yield self.line


@pytest.mark.parametrize(
    "line",
    [b'event: progress\ndata: {"progress": 0.5, "stage": "quilting"}\n\n', b": heartbeat\n\n"],
)
def test_a_busy_event_stream_does_not_outlast_the_timeout(
    connect: Callable[..., Any], line: bytes
) -> None:
    def busy(request: httpx.Request) -> httpx.Response:
        return httpx.Response(
            200, stream=ChattyStream(line), headers={"Content-Type": "text/event-stream"}
        )

    service = (
        FakeService()
        .on("GET", "/jobs/j1/events", busy)
        .on("GET", "/jobs/j1", json_answer(200, job_json("running")))
    )
    client = connect(service, real_sleep=True)
    started = time.monotonic()
    with pytest.raises(WaitTimeoutError):
        client.wait("j1", timeout=0.1, progress=lambda f, s: None)
    # The stream lasts a minute: the client must leave it at its deadline.
    assert time.monotonic() - started < LATE_S


# -- errors ------------------------------------------------------------------------------------

ERRORS = [
    (401, "unauthorized", AuthenticationError, {}),
    (404, "job_not_found", NotFoundError, {}),
    (409, "idempotency_conflict", ConflictError, {}),
    (410, "result_expired", GoneError, {}),
    (413, "file_too_large", PayloadTooLargeError, {}),
    (415, "unsupported_media_type", UnsupportedMediaTypeError, {}),
    (422, "invalid_parameter", ValidationError, {"field": "block"}),
    (503, "queue_full", ServiceUnavailableError, {}),
    (500, "internal_error", ServerError, {}),
]


@pytest.mark.parametrize(("status", "code", "cls", "members"), ERRORS)
def test_error_statuses_map_to_typed_errors(
    connect: Callable[..., Any],
    status: int,
    code: str,
    cls: type[QuiltingClientError],
    members: dict[str, Any],
) -> None:
    service = FakeService().on(
        "POST", "/synthesize", problem(status, code, "it went wrong", **members)
    )
    client = connect(service)
    with pytest.raises(cls) as caught:
        client.synthesize(TEXTURE, width=64, height=32)
    error = caught.value
    assert type(error) is cls
    assert (error.status, error.code, error.detail) == (status, code, "it went wrong")
    assert error.problem["type"].endswith(code)
    assert "it went wrong" in str(error) and code in str(error)
    if cls is ValidationError:
        assert isinstance(error, ValidationError) and error.field == "block"
    if cls is ServiceUnavailableError:
        assert isinstance(error, ServiceUnavailableError) and error.retry_after == 7.0
        assert isinstance(error, ServerError)


@pytest.mark.parametrize(
    ("body", "content_type", "expected"),
    [
        (b"<html><body>502 Bad Gateway</body></html>", "text/html", "Bad Gateway"),
        (b"upstream worker died\n", "text/plain", "upstream worker died"),
        (b"", "text/plain", "Bad Gateway"),
    ],
)
def test_a_non_json_error_body_still_gives_a_useful_error(
    connect: Callable[..., Any], body: bytes, content_type: str, expected: str
) -> None:
    answer = lambda request: httpx.Response(  # noqa: E731
        502, content=body, headers={"Content-Type": content_type}
    )
    client = connect(FakeService().on("GET", "/jobs/j1", answer))
    with pytest.raises(ServerError) as caught:
        client.status("j1")
    assert caught.value.status == 502 and caught.value.code == "http_502"
    assert expected in str(caught.value)
    assert "<html>" not in str(caught.value)


def test_a_transport_failure_raises_connection_failed_error(connect: Callable[..., Any]) -> None:
    service = FakeService().on("GET", "/jobs/j1", fails(httpx.ConnectError("connection refused")))
    client = connect(service)
    with pytest.raises(ConnectionFailedError) as caught:
        client.status("j1")
    assert caught.value.status is None and "connection refused" in str(caught.value)


def test_an_invalid_companion_name_is_rejected_before_uploading(
    connect: Callable[..., Any],
) -> None:
    service = FakeService()
    client = connect(service)
    with pytest.raises(ValidationError) as caught:
        client.submit(TEXTURE, width=64, height=32, companions={"../evil": NORMAL})
    assert caught.value.field == "companion" and caught.value.status is None
    assert service.requests == []


# -- what goes over the wire -------------------------------------------------------------------


def test_submit_sends_named_multipart_parts(connect: Callable[..., Any], tmp_path: Path) -> None:
    texture = tmp_path / "gravel.png"
    texture.write_bytes(TEXTURE)
    rough = tmp_path / "anything.jpg"
    rough.write_bytes(ROUGH)
    service = FakeService().on("POST", "/synthesize", accepted())
    client = connect(service)
    job = client.submit(
        texture,
        width=64,
        height=32,
        companions={"normal": NORMAL, "rough_1": str(rough)},
        block=16,
        mode="overlap",
        overlap=None,
    )
    assert job == JobStatus.from_json(job_json("queued"))
    post = service.only("POST", "/synthesize")
    assert post.url.params["wait"] == "0"
    # Files in order (companions keep theirs); httpx puts form fields before files.
    assert sorted(multipart(post), key=lambda part: part[0] == "options") == [
        ("texture", "gravel.png", TEXTURE),
        ("companion", "normal.png", NORMAL),
        ("companion", "rough_1.png", ROUGH),
        (
            "options",
            None,
            json.dumps({"width": 64, "height": 32, "block": 16, "mode": "overlap"}).encode(),
        ),
    ]
    # None options are left to the service's defaults.
    assert "overlap" not in options_of(post)


def test_texture_bytes_get_a_generic_file_name(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/synthesize", accepted())
    connect(service).submit(TEXTURE, width=8, height=8)
    [texture] = [part for part in multipart(service.requests[0]) if part[0] == "texture"]
    assert texture == ("texture", "texture", TEXTURE)


@pytest.mark.parametrize("api_key", [None, "s3cret"])
def test_api_key_and_idempotency_key_headers(
    connect: Callable[..., Any], api_key: str | None
) -> None:
    service = FakeService().on("POST", "/synthesize", accepted())
    client = connect(service, api_key=api_key)
    client.submit(TEXTURE, width=64, height=32, idempotency_key="retry-42")
    post = service.requests[0]
    assert post.headers["Idempotency-Key"] == "retry-42"
    assert post.headers.get("Authorization") == (f"Bearer {api_key}" if api_key else None)
    assert post.headers["User-Agent"].startswith("quilting-client/")
    client.submit(TEXTURE, width=64, height=32)
    assert "Idempotency-Key" not in service.requests[1].headers


def test_companions_round_trip(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", png())
        .on("GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None))
        .on("GET", "/jobs/j1/result/rough", png(b"quilted rough", job_id=None))
    )
    client = connect(service)
    result = client.synthesize(
        TEXTURE, width=64, height=32, companions={"normal": NORMAL, "rough": ROUGH}
    )
    assert result == RESULT
    assert result.companions == {"normal": NORMAL_OUT, "rough": b"quilted rough"}
    sent = {filename: body for name, filename, body in multipart(service.requests[0])}
    assert sent["normal.png"] == NORMAL and sent["rough.png"] == ROUGH


def test_companion_kinds_are_sent_as_a_form_field(connect: Callable[..., Any]) -> None:
    service = (
        FakeService().on("POST", "/synthesize", accepted()).on("POST", "/transfer", accepted())
    )
    client = connect(service)
    client.submit(
        TEXTURE, width=8, height=8, companions={"mask": ROUGH}, companion_kinds={"mask": "hard"}
    )
    client.submit_transfer(
        TEXTURE, TEXTURE, companions={"n": NORMAL}, companion_kinds={"n": "normal"}
    )
    client.submit(TEXTURE, width=8, height=8, companions={"mask": ROUGH})
    fields = [
        {name: body for name, filename, body in multipart(post) if filename is None}
        for post in service.requests
    ]
    assert json.loads(fields[0]["companion_kinds"]) == {"mask": "hard"}
    assert json.loads(fields[1]["companion_kinds"]) == {"n": "normal"}
    # No kinds given: no field, every companion 'blend' (what an older service does too).
    assert "companion_kinds" not in fields[2]


@pytest.mark.parametrize(
    ("kinds", "code"),
    [({"other": "hard"}, "invalid_companion"), ({"mask": "soft"}, "invalid_parameter")],
)
def test_bad_companion_kinds_are_rejected_before_uploading(
    connect: Callable[..., Any], kinds: dict[str, str], code: str
) -> None:
    service = FakeService()
    with pytest.raises(ValidationError) as caught:
        connect(service).submit(
            TEXTURE, width=8, height=8, companions={"mask": ROUGH}, companion_kinds=kinds
        )
    assert caught.value.code == code and caught.value.field == "companion_kinds"
    assert service.requests == []


def test_submit_answered_with_a_png_returns_the_status(connect: Callable[..., Any]) -> None:
    # An idempotent repeat of a job that finished during its first request's wait.
    service = (
        FakeService()
        .on("POST", "/synthesize", png())
        .on("GET", "/jobs/j1", json_answer(200, job_json("done")))
    )
    job = connect(service).submit(TEXTURE, width=64, height=32, idempotency_key="k")
    assert job.status == "done" and job.id == "j1"


# -- transfer ----------------------------------------------------------------------------------

TARGET = b"\x89PNG\r\n\x1a\ntarget\r\n--\x00"
# A PNG signature and IHDR chunk saying 48x40: enough for the CLI to report the size.
TRANSFERRED = (
    b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + struct.pack(">II", 48, 40) + b"rest"
)


def test_transfer_posts_texture_target_and_options(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/transfer", png(TRANSFERRED))
    client = connect(service)
    result = client.transfer(
        TEXTURE, TARGET, block=16, iterations=2, remap=False, alpha=None, correspondence="blurred"
    )
    assert result == TRANSFERRED and isinstance(result, SynthesisResult)
    assert result.job_id == "j1" and result.companions == {}
    assert service.paths() == ["POST /transfer"]
    post = service.requests[0]
    assert post.url.params["wait"] == "10"
    # No size (the target sets it); None is left out, but False is a value and is sent.
    assert options_of(post) == {
        "block": 16,
        "iterations": 2,
        "remap": False,
        "correspondence": "blurred",
    }
    files = [part for part in multipart(post) if part[0] != "options"]
    assert files == [("texture", "texture", TEXTURE), ("target", "target", TARGET)]


def test_transfer_follows_the_job_and_fetches_companions(
    connect: Callable[..., Any], tmp_path: Path
) -> None:
    target = tmp_path / "photo.png"
    target.write_bytes(TARGET)
    running = job_json("running", operation="transfer")
    done = job_json("done", operation="transfer", stats={"correspondence_error": 0.02})
    service = (
        FakeService()
        .on("POST", "/transfer", accepted(retry_after="1"))
        .on("GET", "/jobs/j1", json_answer(200, running), json_answer(200, done))
        .on("GET", "/jobs/j1/result", png(TRANSFERRED))
        .on("GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None))
    )
    client = connect(service)
    result = client.transfer(
        TEXTURE, target, companions={"normal": NORMAL}, poll_interval=0.05, seed=4
    )
    assert result == TRANSFERRED and result.companions == {"normal": NORMAL_OUT}
    assert client.sleeps == [1.0, 0.05]
    post = service.only("POST", "/transfer")
    assert ("target", "photo.png", TARGET) in multipart(post)
    assert ("companion", "normal.png", NORMAL) in multipart(post)
    assert options_of(post) == {"seed": 4}


def test_submit_transfer_returns_the_status(connect: Callable[..., Any]) -> None:
    service = FakeService().on(
        "POST", "/transfer", json_answer(202, job_json("queued", operation="transfer"))
    )
    job = connect(service).submit_transfer(TEXTURE, TARGET, idempotency_key="t-1", block=12)
    assert job.operation == "transfer" and job.status == "queued"
    post = service.only("POST", "/transfer")
    assert post.url.params["wait"] == "0"
    assert post.headers["Idempotency-Key"] == "t-1"
    assert options_of(post) == {"block": 12}


def test_a_refused_transfer_raises_validation_error(connect: Callable[..., Any]) -> None:
    answer = problem(
        422, "invalid_parameter", "correspondence: 'custom' ...", field="correspondence"
    )
    service = FakeService().on("POST", "/transfer", answer)
    with pytest.raises(ValidationError) as caught:
        connect(service).transfer(TEXTURE, TARGET, correspondence="custom")
    assert caught.value.field == "correspondence" and caught.value.status == 422


# -- the other endpoints -----------------------------------------------------------------------


def test_job_endpoints(connect: Callable[..., Any]) -> None:
    layout = {"block": 16, "placements": [[0, 0, 3, 4]]}
    service = (
        FakeService()
        .on("GET", "/jobs/j1", json_answer(200, job_json("running", future_member=[1, 2])))
        .on("GET", "/jobs/j1/result", png())
        .on("GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None))
        .on("GET", "/jobs/j1/layout", json_answer(200, layout))
        .on("DELETE", "/jobs/j1", json_answer(202, job_json("running")))
        .on("GET", "/jobs/a%2Fb", json_answer(200, job_json("queued", job_id="a/b")))
    )
    client = connect(service)
    status = client.status("j1")
    assert status.status == "running" and not status.is_terminal
    assert status.raw["future_member"] == [1, 2]
    assert client.result("j1") == RESULT
    assert client.result("j1", "normal") == NORMAL_OUT
    assert client.layout("j1") == layout
    assert client.cancel("j1").id == "j1"
    # Ids are percent-encoded: a "/" cannot reach another route.
    assert client.status("a/b").id == "a/b"
    assert service.requests[-1].url.raw_path == b"/jobs/a%2Fb"


def test_result_of_an_unfinished_job_is_a_conflict(connect: Callable[..., Any]) -> None:
    service = FakeService().on("GET", "/jobs/j1/result", problem(409, "job_not_done", "running"))
    with pytest.raises(ConflictError) as caught:
        connect(service).result("j1")
    assert caught.value.code == "job_not_done"


def test_events_yields_named_events(connect: Callable[..., Any]) -> None:
    progress = {"progress": 0.5, "stage": "quilting", "status": "running"}
    service = FakeService().on(
        "GET", "/jobs/j1/events", sse(("progress", progress), ("done", job_json("done")))
    )
    events = list(connect(service).events("j1"))
    assert events == [("progress", progress), ("done", job_json("done"))]


def test_events_of_an_unknown_job_raise_not_found(connect: Callable[..., Any]) -> None:
    service = FakeService().on("GET", "/jobs/nope/events", problem(404, "job_not_found", "nope"))
    with pytest.raises(NotFoundError):
        list(connect(service).events("nope"))


@pytest.mark.parametrize("follow", ["poll", "events"])
def test_wait_returns_the_final_status(connect: Callable[..., Any], follow: str) -> None:
    service = (
        FakeService()
        .on(
            "GET",
            "/jobs/j1",
            json_answer(200, job_json("running")),
            json_answer(200, job_json("done")),
        )
        .on("GET", "/jobs/j1/events", sse(("done", job_json("done"))))
    )
    client = connect(service)
    progress = (lambda f, s: None) if follow == "events" else None
    job = client.wait("j1", progress=progress, poll_interval=0.05)
    assert job.status == "done" and job.is_terminal
    if follow == "poll":
        assert client.sleeps == [0.05]


def test_health_and_ready(connect: Callable[..., Any]) -> None:
    ready = {
        "status": "ready",
        "backend": "fft",
        "renderer": None,
        "queue_depth": 0,
        "running": 0,
        "workers": 2,
    }
    service = (
        FakeService()
        .on("GET", "/healthz", json_answer(200, {"status": "ok"}))
        .on("GET", "/readyz", json_answer(200, ready), problem(503, "draining", "shutting down"))
    )
    client = connect(service)
    assert client.health() is True
    assert client.ready() == ready
    with pytest.raises(ServiceUnavailableError) as caught:
        client.ready()
    assert caught.value.code == "draining" and caught.value.retry_after == 7.0


def test_health_is_false_when_unreachable(connect: Callable[..., Any]) -> None:
    service = FakeService().on("GET", "/healthz", fails(httpx.ConnectError("refused")))
    assert connect(service).health() is False


# -- pure parts --------------------------------------------------------------------------------


def test_job_status_ignores_unknown_keys_and_tolerates_missing_ones() -> None:
    job = JobStatus.from_json({"id": "x", "status": "done", "progress": 1, "brand_new": True})
    assert job.progress == 1.0 and job.companions == () and job.error is None
    # A service from before transfer does not say the operation: it only synthesized.
    assert job.operation == "synthesize"
    assert JobStatus.from_json(
        {"id": "x", "status": "done", "operation": "transfer"}
    ).operation == ("transfer")
    assert job.is_terminal and hash(job) == hash(JobStatus.from_json(dict(job.raw)))
    full = JobStatus.from_json(job_json("done", companions=["normal"], timings={"total": 1.5}))
    assert full.companions == ("normal",) and full.timings == {"total": 1.5}
    assert full.result == "/jobs/j1/result" and full.width == 64
    with pytest.raises(ValueError):
        JobStatus.from_json({"status": "done"})


def test_sse_decoder_follows_the_event_stream_format() -> None:
    decoder = SSEDecoder()
    lines = [": comment", "event: progress", 'data: {"progress":', "data:0.5}", "", "", "data: 3"]
    events = [event for line in lines if (event := decoder.feed(line)) is not None]
    assert events == [ServerEvent("progress", {"progress": 0.5})]
    # A last event without its blank line is kept; non-object data is wrapped.
    assert decoder.flush() == ServerEvent("message", {"data": 3})
    assert decoder.flush() is None


# -- the command line --------------------------------------------------------------------------


@pytest.fixture
def fake_cli(monkeypatch: pytest.MonkeyPatch) -> FakeService:
    """The CLI's client talks to a fake service; the factory's arguments are recorded."""
    service = FakeService()
    service.factory_calls = []  # type: ignore[attr-defined]

    def make_client(server: str, api_key: str | None) -> Client:
        service.factory_calls.append((server, api_key))  # type: ignore[attr-defined]
        return Client(server, api_key, transport=httpx.MockTransport(service))

    monkeypatch.setattr(cli, "make_client", make_client)
    monkeypatch.delenv("QUILTING_SERVER", raising=False)
    monkeypatch.delenv("QUILTING_URL", raising=False)
    monkeypatch.delenv("QUILTING_API_KEY", raising=False)
    return service


def test_cli_writes_the_result_and_the_companions(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    fake_cli.on("POST", "/synthesize", png()).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    )
    out = tmp_path / "out.png"
    status = cli.main(
        [
            "synth",
            str(tmp_path / "in.png"),
            "-o",
            str(out),
            "--server",
            BASE,
            "--size",
            "64x32",
            "--block",
            "16",
            "--seed",
            "3",
            "--with",
            f"normal={tmp_path / 'n.png'}",
        ]
    )
    assert status == 0
    assert out.read_bytes() == RESULT
    assert (tmp_path / "out_normal.png").read_bytes() == NORMAL_OUT
    post = fake_cli.only("POST", "/synthesize")
    assert options_of(post) == {"width": 64, "height": 32, "block": 16, "seed": 3}
    assert ("companion", "normal.png", NORMAL) in multipart(post)
    captured = capsys.readouterr()
    assert "out.png" in captured.out and captured.err == ""  # stderr is no terminal: no bar


def test_cli_with_name_kind_sends_the_kind(fake_cli: FakeService, tmp_path: Path) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "m.png").write_bytes(ROUGH)
    (tmp_path / "n.png").write_bytes(NORMAL)
    fake_cli.on("POST", "/synthesize", png()).on(
        "GET", "/jobs/j1/result/mask", png(b"mask out", job_id=None)
    ).on("GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None))
    argv = ["synth", str(tmp_path / "in.png"), "-o", str(tmp_path / "out.png"), "--server", BASE]
    argv += ["--size", "64x32", "--with", f"mask:hard={tmp_path / 'm.png'}"]
    assert cli.main([*argv, "--with", f"normal={tmp_path / 'n.png'}"]) == 0
    post = fake_cli.only("POST", "/synthesize")
    fields = {name: body for name, filename, body in multipart(post) if filename is None}
    assert json.loads(fields["companion_kinds"]) == {"mask": "hard"}
    assert ("companion", "mask.png", ROUGH) in multipart(post)
    assert (tmp_path / "out_mask.png").read_bytes() == b"mask out"
    # An unknown kind is a usage error, before anything is sent.
    bad = [*argv[:-1], f"mask:soft={tmp_path / 'm.png'}"]
    assert cli.main(bad) != 0


def test_cli_transfer_writes_the_result_and_sends_only_given_options(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "target.png").write_bytes(TARGET)
    (tmp_path / "n.png").write_bytes(NORMAL)
    fake_cli.on("POST", "/transfer", png(TRANSFERRED)).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    )
    out = tmp_path / "out.png"
    argv = ["transfer", str(tmp_path / "in.png"), str(tmp_path / "target.png"), "-o", str(out)]
    options = ["--block", "16", "--iterations", "2", "--no-remap", "--correspondence", "blurred"]
    extra = ["--alpha", "0.25", "--min-block", "8", "--shade", "1.25"]
    extra += ["--with", f"normal={tmp_path / 'n.png'}"]
    assert cli.main([*argv, "--server", BASE, *options, *extra]) == 0
    assert out.read_bytes() == TRANSFERRED
    assert (tmp_path / "out_normal.png").read_bytes() == NORMAL_OUT
    post = fake_cli.only("POST", "/transfer")
    assert options_of(post) == {
        "block": 16,
        "iterations": 2,
        "remap": False,
        "correspondence": "blurred",
        "alpha": 0.25,
        "min_block": 8,
        "shade": 1.25,
    }
    parts = multipart(post)
    assert ("target", "target.png", TARGET) in parts and ("texture", "in.png", TEXTURE) in parts
    captured = capsys.readouterr()
    # The size is the target's, read from the PNG that came back.
    assert "(48x40, job j1)" in captured.out and captured.err == ""


@pytest.mark.parametrize(
    "args",
    [
        ["transfer", "{in}", "-o", "{out}", "--server", BASE],  # no target
        ["transfer", "{in}", "{missing}", "-o", "{out}", "--server", BASE],
        ["transfer", "{in}", "{in}", "-o", "{out}", "--server", BASE, "--alpha", "half"],
    ],
)
def test_cli_transfer_user_errors_exit_2(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    paths = {"in": tmp_path / "in.png", "out": tmp_path / "o.png", "missing": tmp_path / "no.png"}
    assert cli.main([a.format(**paths) for a in args]) == 2
    assert "error:" in capsys.readouterr().err
    assert fake_cli.requests == []


def test_cli_transfer_refused_by_the_service_exits_2(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    answer = problem(422, "invalid_parameter", "alpha: must be at most 1", field="alpha")
    fake_cli.on("POST", "/transfer", answer)
    argv = ["transfer", str(tmp_path / "in.png"), str(tmp_path / "in.png"), "-o"]
    assert cli.main([*argv, str(tmp_path / "o.png"), "--server", BASE, "--alpha", "2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1
    assert "alpha" in err and not (tmp_path / "o.png").exists()


def test_cli_reads_server_and_key_from_the_environment(
    fake_cli: FakeService, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    monkeypatch.setenv("QUILTING_SERVER", BASE)
    monkeypatch.setenv("QUILTING_API_KEY", "from-env")
    fake_cli.on("POST", "/synthesize", png())
    args = ["synth", str(tmp_path / "in.png"), "-o", str(tmp_path / "o.png"), "--size", "8"]
    assert cli.main(args) == 0
    assert fake_cli.factory_calls == [(BASE, "from-env")]  # type: ignore[attr-defined]
    assert fake_cli.requests[0].headers["Authorization"] == "Bearer from-env"


@pytest.mark.parametrize(
    ("answer", "expected", "text"),
    [
        (problem(422, "invalid_parameter", "block must be at least 2", field="block"), 2, "block"),
        (problem(401, "unauthorized", "missing API key"), 2, "missing API key"),
        (problem(500, "internal_error", "worker crashed"), 1, "worker crashed"),
        (problem(503, "queue_full", "queue is full"), 1, "queue is full"),
        (fails(httpx.ConnectError("connection refused")), 1, "connection refused"),
    ],
)
def test_cli_errors_are_one_line_with_exit_status(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    answer: Handler,
    expected: int,
    text: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    fake_cli.on("POST", "/synthesize", answer)
    out = tmp_path / "out.png"
    args = ["synth", str(tmp_path / "in.png"), "-o", str(out), "--server", BASE, "--size", "8x8"]
    assert cli.main(args) == expected
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1
    assert text in err
    assert not out.exists()


def test_cli_failed_job_exits_1(fake_cli: FakeService, tmp_path: Path) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    engine_failure = {**FAILED, "error": {**FAILED["error"], "status": None}}
    fake_cli.on("POST", "/synthesize", json_answer(202, engine_failure))
    args = [
        "synth",
        str(tmp_path / "in.png"),
        "-o",
        str(tmp_path / "o.png"),
        "--server",
        BASE,
        "--size",
        "8x8",
    ]
    assert cli.main(args) == 1


@pytest.mark.parametrize(
    "args",
    [
        ["synth", "{missing}", "-o", "{out}", "--size", "8x8", "--server", BASE],
        ["synth", "{in}", "-o", "{out}", "--size", "8x8", "--server", BASE, "--with", "normal"],
        ["synth", "{in}", "-o", "{out}", "--size", "eight", "--server", BASE],
        [
            "synth",
            "{in}",
            "-o",
            "{out}",
            "--size",
            "8",
            "--server",
            BASE,
            "--with",
            "a=x",
            "--with",
            "a=y",
        ],
    ],
)
def test_cli_user_errors_exit_2(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    paths = {"in": tmp_path / "in.png", "out": tmp_path / "o.png", "missing": tmp_path / "no.png"}
    argv = [a.format(**paths) for a in args]
    assert cli.main(argv) == 2
    assert "error:" in capsys.readouterr().err
    assert fake_cli.requests == []


def test_cli_progress_bar_draws_only_on_a_terminal() -> None:
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    terminal, pipe = Terminal(), io.StringIO()
    for stream in (terminal, pipe):
        bar = cli.ProgressBar(stream)
        bar(0.5, "quilting")
        bar(1.0, "done")
    assert pipe.getvalue() == ""
    drawn = terminal.getvalue()
    assert drawn.count("\r") == 2 and drawn.endswith("\n") and drawn.count("\n") == 1
    assert "50.0%" in drawn and "100.0%" in drawn


@pytest.mark.parametrize("command", ["synth", "transfer"])
@pytest.mark.parametrize(
    ("given", "sent"),
    [
        ([], {}),
        (["--error", "luminance"], {"error": "luminance"}),
        (["--discard", "0.25"], {"discard": 0.25}),
        (["--discard", "0", "--error", "rgb"], {"discard": 0.0, "error": "rgb"}),
    ],
)
def test_cli_sends_error_and_discard_only_when_given(
    fake_cli: FakeService,
    tmp_path: Path,
    command: str,
    given: list[str],
    sent: dict[str, Any],
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    fake_cli.on("POST", "/synthesize", png()).on("POST", "/transfer", png(TRANSFERRED))
    texture, out = str(tmp_path / "in.png"), str(tmp_path / "o.png")
    if command == "synth":
        argv = ["synth", texture, "-o", out, "--size", "64x32", "--block", "16"]
        expected = {"width": 64, "height": 32, "block": 16, **sent}
    else:
        argv = ["transfer", texture, texture, "-o", out, "--block", "16"]
        expected = {"block": 16, **sent}
    assert cli.main([*argv, "--server", BASE, *given]) == 0
    post = fake_cli.only("POST", "/synthesize" if command == "synth" else "/transfer")
    assert options_of(post) == expected


def test_cli_with_companions_sends_each_and_writes_each_beside_the_output(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    (tmp_path / "r.jpg").write_bytes(ROUGH)
    fake_cli.on("POST", "/synthesize", png()).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    ).on("GET", "/jobs/j1/result/rough-2", png(b"quilted rough", job_id=None))
    folder = tmp_path / "out"
    folder.mkdir()
    out = folder / "brick.png"
    argv = ["synth", str(tmp_path / "in.png"), "-o", str(out), "--size", "64x32"]
    extra = ["--with", f"normal={tmp_path / 'n.png'}", "--with", f"rough-2={tmp_path / 'r.jpg'}"]
    assert cli.main([*argv, "--server", BASE, *extra]) == 0
    parts = multipart(fake_cli.only("POST", "/synthesize"))
    companions = [(filename, body) for name, filename, body in parts if name == "companion"]
    assert sorted(companions) == [("normal.png", NORMAL), ("rough-2.png", ROUGH)]
    assert sorted(p.name for p in folder.iterdir()) == [
        "brick.png",
        "brick_normal.png",
        "brick_rough-2.png",
    ]
    assert out.read_bytes() == RESULT
    assert (folder / "brick_normal.png").read_bytes() == NORMAL_OUT
    assert (folder / "brick_rough-2.png").read_bytes() == b"quilted rough"
    [line] = capsys.readouterr().out.splitlines()
    assert "brick_normal.png" in line and "brick_rough-2.png" in line


@pytest.mark.parametrize(
    ("with_args", "fragment"),
    [
        (["normal"], "is not NAME[:KIND]=PATH"),
        (["normal="], "is not NAME[:KIND]=PATH"),
        (["={n}"], "the name '' is not"),
        (["../evil={n}"], "the name '../evil'"),
        (["a b={n}"], "the name 'a b'"),
        ([f"{'n' * 65}={{n}}"], "is not 1 to 64"),
        (["n={n}", "n={n}"], "'n' is given twice"),
        (["n={n}", "m={missing}"], "no.png"),
    ],
)
@pytest.mark.parametrize("command", ["synth", "transfer"])
def test_cli_bad_companions_are_one_line_and_send_nothing(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    with_args: list[str],
    fragment: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    paths = {"n": tmp_path / "n.png", "missing": tmp_path / "no.png"}
    texture, out = str(tmp_path / "in.png"), tmp_path / "o.png"
    if command == "synth":
        argv = ["synth", texture, "-o", str(out), "--size", "8"]
    else:
        argv = ["transfer", texture, texture, "-o", str(out)]
    for spec in with_args:
        argv += ["--with", spec.format(**paths)]
    assert cli.main([*argv, "--server", BASE]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert fragment in err
    assert fake_cli.requests == [] and not out.exists()


@pytest.mark.parametrize("command", ["synth", "transfer"])
def test_cli_companion_of_the_wrong_size_is_refused_by_the_service(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    # Only the service decodes images: it checks the size and answers 422 invalid_companion.
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    answer = problem(
        422,
        "invalid_companion",
        "companion 'normal' is 32x32; it must be the texture's size, 64x64",
        field="companion",
    )
    fake_cli.on("POST", "/synthesize", answer).on("POST", "/transfer", answer)
    texture, out = str(tmp_path / "in.png"), tmp_path / "o.png"
    if command == "synth":
        argv = ["synth", texture, "-o", str(out), "--size", "8"]
    else:
        argv = ["transfer", texture, texture, "-o", str(out)]
    argv += ["--server", BASE, "--with", f"normal={tmp_path / 'n.png'}"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert "32x32" in err and "64x64" in err
    assert len(fake_cli.requests) == 1 and list(tmp_path.glob("o*.png")) == []


# -- tile --------------------------------------------------------------------------------------

# A PNG signature and IHDR chunk saying 48x40, as the tiled image of a 48x40 input would have.
TILED = (
    b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + struct.pack(">II", 48, 40) + b"tiled"
)


def test_tile_request_is_one_multipart_post_without_a_job(tmp_path: Path) -> None:
    spec = proto.tile_request(TEXTURE, axes="x", band=None)
    assert (spec.method, spec.path) == ("POST", "/tile")
    # Answered at once: no ?wait=, nothing held, no Idempotency-Key; band None is left out.
    assert spec.params == {} and spec.hold == 0.0 and spec.timeout is None
    assert dict(spec.headers) == {"Accept": "image/png"}
    assert spec.files == (("image", ("image", TEXTURE, "image/png")),)
    assert json.loads(spec.data["options"]) == {"axes": "x"}
    photo = tmp_path / "photo.jpg"
    photo.write_bytes(ROUGH)
    spec = proto.tile_request(photo, axes="both", band=6, timeout=2.5)
    assert spec.files == (("image", ("photo.jpg", ROUGH, "image/jpeg")),)
    assert json.loads(spec.data["options"]) == {"axes": "both", "band": 6}
    assert spec.timeout == 2.5
    spec = proto.tile_request(TEXTURE, axes="x", band=None, blend="poisson")
    assert json.loads(spec.data["options"]) == {"axes": "x", "blend": "poisson"}


def test_a_request_s_own_timeout_replaces_the_client_s() -> None:
    assert proto.request_timeout(60.0, proto.tile_request(TEXTURE, axes="both", band=None)) == (
        httpx.Timeout(60.0)
    )
    spec = proto.tile_request(TEXTURE, axes="both", band=None, timeout=2.5)
    assert proto.request_timeout(60.0, spec) == httpx.Timeout(2.5)


def _tile_response(content: bytes, content_type: str = "image/png") -> httpx.Response:
    return httpx.Response(
        200,
        content=content,
        headers={"Content-Type": content_type},
        request=httpx.Request("POST", f"{BASE}/tile"),
    )


def test_tile_flow_sends_once_and_returns_the_png() -> None:
    flow = flows.tile(TEXTURE, axes="y", band=3, timeout=None, blend="poisson")
    action = next(flow)
    assert action == flows.Send(proto.tile_request(TEXTURE, axes="y", band=3, blend="poisson"))
    with pytest.raises(StopIteration) as stop:
        flow.send(_tile_response(TILED))
    assert stop.value.value == TILED


def test_tile_flow_rejects_an_answer_that_is_not_a_png() -> None:
    flow = flows.tile(TEXTURE, axes="both", band=None, timeout=None)
    next(flow)
    with pytest.raises(QuiltingClientError) as caught:
        flow.send(_tile_response(b'{"status": "queued"}', "application/json"))
    assert caught.value.code == "invalid_response" and "/tile" in str(caught.value)


@pytest.mark.parametrize("timeout", [0.0, -1.0])
def test_tile_flow_rejects_a_timeout_that_is_not_positive(timeout: float) -> None:
    with pytest.raises(ValueError, match="timeout must be positive"):
        next(flows.tile(TEXTURE, axes="both", band=None, timeout=timeout))


def test_tile_posts_the_image_and_returns_the_png(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/tile", png(TILED, job_id=None))
    client = connect(service)
    result = client.tile(TEXTURE, axes="x", band=5)
    assert result == TILED and type(result) is bytes
    assert service.paths() == ["POST /tile"]
    post = service.requests[0]
    assert "wait" not in post.url.params and "Idempotency-Key" not in post.headers
    assert sorted(multipart(post), key=lambda part: part[0] == "options") == [
        ("image", "image", TEXTURE),
        ("options", None, json.dumps({"axes": "x", "band": 5}).encode()),
    ]
    assert client.sleeps == []


def test_tile_defaults_send_only_the_axes(connect: Callable[..., Any], tmp_path: Path) -> None:
    path = tmp_path / "wall.png"
    path.write_bytes(TEXTURE)
    service = FakeService().on("POST", "/tile", png(TILED, job_id=None))
    assert connect(service, api_key="s3cret").tile(path) == TILED
    post = service.only("POST", "/tile")
    assert options_of(post) == {"axes": "both"}
    assert ("image", "wall.png", TEXTURE) in multipart(post)
    assert post.headers["Authorization"] == "Bearer s3cret"


@pytest.mark.parametrize(("timeout", "seconds"), [(None, 60.0), (2.5, 2.5)])
def test_tile_timeout_bounds_its_request(
    connect: Callable[..., Any], timeout: float | None, seconds: float
) -> None:
    service = FakeService().on("POST", "/tile", png(TILED, job_id=None))
    connect(service).tile(TEXTURE, timeout=timeout)
    sent = service.requests[0].extensions["timeout"]
    assert sent == {"connect": seconds, "read": seconds, "write": seconds, "pool": seconds}


TILE_ERRORS = [
    (422, "invalid_parameter", ValidationError, {"field": "band"}),
    (422, "invalid_options", ValidationError, {"field": "options"}),
    (422, "invalid_image", ValidationError, {"field": "image"}),
    (422, "image_too_large", ValidationError, {"field": "image"}),
    (415, "unsupported_media_type", UnsupportedMediaTypeError, {"field": "image"}),
    (413, "body_too_large", PayloadTooLargeError, {}),
    (401, "unauthorized", AuthenticationError, {}),
    (503, "draining", ServiceUnavailableError, {}),
    (500, "internal_error", ServerError, {}),
]


@pytest.mark.parametrize(("status", "code", "cls", "members"), TILE_ERRORS)
def test_tile_problems_map_to_typed_errors(
    connect: Callable[..., Any],
    status: int,
    code: str,
    cls: type[QuiltingClientError],
    members: dict[str, Any],
) -> None:
    service = FakeService().on("POST", "/tile", problem(status, code, "no tiling", **members))
    client = connect(service)
    with pytest.raises(cls) as caught:
        client.tile(TEXTURE, band=1000)
    error = caught.value
    assert type(error) is cls
    assert (error.status, error.code, error.detail) == (status, code, "no tiling")
    if isinstance(error, ValidationError):
        assert error.field == members["field"]
    if isinstance(error, ServiceUnavailableError):
        assert error.retry_after == 7.0
    # Like a submission, nothing is retried or slept on: one request, then the error.
    assert service.paths() == ["POST /tile"] and client.sleeps == []


def test_cli_tile_writes_the_png_and_sends_the_options(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    fake_cli.on("POST", "/tile", png(TILED, job_id=None))
    out = tmp_path / "out.png"
    argv = ["tile", str(tmp_path / "in.png"), "-o", str(out), "--server", BASE]
    assert cli.main([*argv, "--api-key", "k1", "--axes", "x", "--band", "6"]) == 0
    assert out.read_bytes() == TILED
    post = fake_cli.only("POST", "/tile")
    assert options_of(post) == {"axes": "x", "band": 6}
    assert ("image", "in.png", TEXTURE) in multipart(post)
    assert fake_cli.factory_calls == [(BASE, "k1")]  # type: ignore[attr-defined]
    captured = capsys.readouterr()
    assert captured.out == f"wrote {out} (48x40, tileable along x)\n" and captured.err == ""


@pytest.mark.parametrize(
    ("environment", "flag", "expected"),
    [
        ({}, [], cli.DEFAULT_URL),
        ({"QUILTING_URL": "http://a:1"}, [], "http://a:1"),
        ({"QUILTING_SERVER": "http://b:2"}, [], "http://b:2"),
        ({"QUILTING_URL": "http://a:1", "QUILTING_SERVER": "http://b:2"}, [], "http://a:1"),
        ({"QUILTING_URL": "http://a:1"}, ["--url", "http://c:3"], "http://c:3"),
        ({}, ["--server", "http://c:3"], "http://c:3"),
    ],
)
def test_cli_finds_the_service_from_flag_environment_or_default(
    fake_cli: FakeService,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    environment: dict[str, str],
    flag: list[str],
    expected: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    fake_cli.on("POST", "/synthesize", png())
    args = ["synth", str(tmp_path / "in.png"), "-o", str(tmp_path / "o.png"), "--size", "8"]
    assert cli.main([*args, *flag]) == 0
    assert fake_cli.factory_calls == [(expected, None)]  # type: ignore[attr-defined]
    assert cli.DEFAULT_URL == "http://127.0.0.1:8000"  # where `quilting serve` listens


@pytest.mark.parametrize(
    "command",
    [
        ["synth", "{in}", "--size", "8"],
        ["tile", "{in}"],
        ["transfer", "{in}", "{in}"],
    ],
)
@pytest.mark.parametrize("name", ["o.jpg", "o.webp", "o", "o.png.tmp"])
def test_cli_refuses_an_output_that_is_not_png_before_sending(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: list[str],
    name: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    args = [part.replace("{in}", str(tmp_path / "in.png")) for part in command]
    assert cli.main([*args, "-o", str(tmp_path / name), "--server", BASE]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and "must end in .png" in err
    assert fake_cli.requests == [] and not (tmp_path / name).exists()


def test_cli_tile_reads_server_and_key_from_the_environment(
    fake_cli: FakeService, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    monkeypatch.setenv("QUILTING_SERVER", BASE)
    monkeypatch.setenv("QUILTING_API_KEY", "from-env")
    fake_cli.on("POST", "/tile", png(TILED, job_id=None))
    assert cli.main(["tile", str(tmp_path / "in.png"), "-o", str(tmp_path / "o.png")]) == 0
    assert fake_cli.factory_calls == [(BASE, "from-env")]  # type: ignore[attr-defined]
    assert options_of(fake_cli.requests[0]) == {"axes": "both"}


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["tile", "{missing}", "-o", "{out}", "--server", BASE], "no.png"),
        (["tile", "{in}", "-o", "{out}", "--server", BASE, "--axes", "z"], "'z' is not one of"),
    ],
)
def test_cli_tile_user_errors_are_one_line_and_send_nothing(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    fragment: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    paths = {"in": tmp_path / "in.png", "out": tmp_path / "o.png", "missing": tmp_path / "no.png"}
    assert cli.main([a.format(**paths) for a in args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert fragment in err
    assert fake_cli.requests == [] and not (tmp_path / "o.png").exists()


@pytest.mark.parametrize(
    ("answer", "expected", "text"),
    [
        (problem(422, "invalid_parameter", "band=1000 is not allowed", field="band"), 2, "band"),
        (problem(401, "unauthorized", "missing API key"), 2, "missing API key"),
        (problem(503, "draining", "the service is shutting down"), 1, "shutting down"),
        (fails(httpx.ConnectError("connection refused")), 1, "connection refused"),
        (fails(httpx.ReadTimeout("timed out")), 1, "timed out"),
    ],
)
def test_cli_tile_errors_are_one_line_with_exit_status(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    answer: Handler,
    expected: int,
    text: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    fake_cli.on("POST", "/tile", answer)
    out = tmp_path / "out.png"
    args = ["tile", str(tmp_path / "in.png"), "-o", str(out), "--server", BASE, "--band", "1000"]
    assert cli.main(args) == expected
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert text in err
    assert not out.exists()


# -- matte -------------------------------------------------------------------------------------

SILHOUETTE = b"\x89PNG\r\n\x1a\nsilhouette\r\n--\x00"
LAYER_0 = b"\x89PNG\r\n\x1a\nbrick layer"
LAYER_1 = b"\x89PNG\r\n\x1a\ncloud layer\r\n--"
NORMALS_IN = b"\x89PNG\r\n\x1a\ngiven normals"
CLUSTERS_OUT = b"\x89PNG\r\n\x1a\npatches"
MATTE_STATS = {
    "light": [0.408, 0.408, 0.816],
    "albedo": 0.77,
    "ambient_fit": 0.01,
    "clusters": 4,
    "patches": 5,
    "layer_size": [52, 40],
}


def matte_json(status: str = "queued", **extra: Any) -> dict[str, Any]:
    """A matte job's status as the service writes it: no layout, normals and clusters beside."""
    stats = MATTE_STATS if status == "done" else None
    body = {"operation": "matte", "companions": ["normals", "clusters"], "stats": stats}
    return job_json(status, **{**body, **extra})


def files_of(request: httpx.Request) -> list[tuple[str, str | None, bytes]]:
    """The file parts in the order sent (httpx puts the form fields first)."""
    return [part for part in multipart(request) if part[0] != "options"]


def test_matte_request_puts_the_parts_in_order(tmp_path: Path) -> None:
    mask = tmp_path / "mask.png"
    mask.write_bytes(SILHOUETTE)
    cloud = tmp_path / "cloud.png"
    cloud.write_bytes(LAYER_1)
    spec = proto.matte_request(
        TARGET,
        mask,
        [LAYER_0, str(cloud), ROUGH],
        normals=NORMALS_IN,
        options={"clusters": 8, "light": (1, 1, 2), "block": 32, "seed": 0, "scale": None},
        wait=2.5,
        idempotency_key="m-1",
    )
    assert (spec.method, spec.path) == ("POST", "/matte")
    assert spec.params == {"wait": "2.5"} and spec.hold == 2.5
    assert dict(spec.headers) == {"Idempotency-Key": "m-1"}
    # Target, silhouette, the layers bottom first, normals; bytes are named after their field.
    assert spec.files == (
        ("target", ("target", TARGET, "image/png")),
        ("silhouette", ("mask.png", SILHOUETTE, "image/png")),
        ("layer", ("layer", LAYER_0, "image/png")),
        ("layer", ("cloud.png", LAYER_1, "image/png")),
        ("layer", ("layer", ROUGH, "image/jpeg")),
        ("normals", ("normals", NORMALS_IN, "image/png")),
    )
    # The light goes as a JSON array; None is left to the service.
    assert json.loads(spec.data["options"]) == {
        "clusters": 8,
        "light": [1, 1, 2],
        "block": 32,
        "seed": 0,
    }
    bare = proto.matte_request(
        TARGET, SILHOUETTE, (LAYER_0,), normals=None, options={}, wait=0, idempotency_key=None
    )
    assert [part[0] for part in bare.files] == ["target", "silhouette", "layer"]
    assert dict(bare.headers) == {} and json.loads(bare.data["options"]) == {}


def test_matte_posts_the_layers_repeated_in_order(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/matte", png(TRANSFERRED))
    client = connect(service)
    result = client.matte(
        TARGET, SILHOUETTE, [LAYER_0, LAYER_1], clusters=8, light=(1, 1, 2), block=32, seed=0
    )
    assert result == TRANSFERRED and isinstance(result, SynthesisResult)
    assert result.job_id == "j1" and result.companions == {}
    # Answered at once: no poll, no download, and no companion asked for.
    assert service.paths() == ["POST /matte"] and client.sleeps == []
    post = service.requests[0]
    assert post.url.params["wait"] == "10" and "Idempotency-Key" not in post.headers
    assert files_of(post) == [
        ("target", "target", TARGET),
        ("silhouette", "silhouette", SILHOUETTE),
        ("layer", "layer", LAYER_0),
        ("layer", "layer", LAYER_1),
    ]
    assert options_of(post) == {"clusters": 8, "light": [1, 1, 2], "block": 32, "seed": 0}


def test_matte_follows_the_job_and_fetches_the_companions_asked_for(
    connect: Callable[..., Any], tmp_path: Path
) -> None:
    paths = {}
    for name, content in [("photo", TARGET), ("mask", SILHOUETTE), ("n", NORMALS_IN)]:
        paths[name] = tmp_path / f"{name}.png"
        paths[name].write_bytes(content)
    service = (
        FakeService()
        .on("POST", "/matte", json_answer(202, matte_json(), {"Retry-After": "1"}))
        .on("GET", "/jobs/j1", json_answer(200, matte_json("running")))
        .on("GET", "/jobs/j1", json_answer(200, matte_json("done")))
        .on("GET", "/jobs/j1/result", png(TRANSFERRED))
        .on("GET", "/jobs/j1/result/normals", png(NORMAL_OUT, job_id=None))
        .on("GET", "/jobs/j1/result/clusters", png(CLUSTERS_OUT, job_id=None))
    )
    client = connect(service)
    result = client.matte(
        paths["photo"],
        paths["mask"],
        [LAYER_1],
        normals=paths["n"],
        companions=["clusters", "normals"],
        poll_interval=0.05,
        idempotency_key="m-2",
        light=None,
        ambient=0.1,
    )
    assert result == TRANSFERRED and result.job_id == "j1"
    assert result.companions == {"clusters": CLUSTERS_OUT, "normals": NORMAL_OUT}
    assert client.sleeps == [1.0, 0.05]
    assert service.paths() == [
        "POST /matte",
        "GET /jobs/j1",
        "GET /jobs/j1",
        "GET /jobs/j1/result",
        "GET /jobs/j1/result/clusters",
        "GET /jobs/j1/result/normals",
    ]
    post = service.only("POST", "/matte")
    assert post.headers["Idempotency-Key"] == "m-2"
    assert files_of(post) == [
        ("target", "photo.png", TARGET),
        ("silhouette", "mask.png", SILHOUETTE),
        ("layer", "layer", LAYER_1),
        ("normals", "n.png", NORMALS_IN),
    ]
    assert options_of(post) == {"ambient": 0.1}


def test_matte_with_progress_follows_the_events(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/matte", json_answer(202, matte_json()))
        .on(
            "GET",
            "/jobs/j1/events",
            sse(
                ("progress", {"progress": 0.4, "stage": "layers", "status": "running"}),
                ("done", matte_json("done")),
            ),
        )
        .on("GET", "/jobs/j1/result", png(TRANSFERRED))
    )
    client = connect(service)
    calls: list[tuple[float, str]] = []
    result = client.matte(TARGET, SILHOUETTE, [LAYER_0], progress=lambda f, s: calls.append((f, s)))
    assert result == TRANSFERRED
    assert calls == [(0.4, "layers"), (1.0, "done")]
    assert service.requests[0].url.params["wait"] == "1"
    assert service.paths() == ["POST /matte", "GET /jobs/j1/events", "GET /jobs/j1/result"]


def test_submit_matte_returns_the_status(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/matte", json_answer(202, matte_json()))
    job = connect(service).submit_matte(
        TARGET, SILHOUETTE, (LAYER_0, LAYER_1), normals=NORMALS_IN, idempotency_key="m-3", seed=7
    )
    assert job == JobStatus.from_json(matte_json())
    assert (job.operation, job.status, job.layout) == ("matte", "queued", None)
    assert job.companions == ("normals", "clusters")
    post = service.only("POST", "/matte")
    assert post.url.params["wait"] == "0" and post.headers["Idempotency-Key"] == "m-3"
    assert [name for name, _, _ in files_of(post)] == [
        "target",
        "silhouette",
        "layer",
        "layer",
        "normals",
    ]
    assert options_of(post) == {"seed": 7}


def test_submit_matte_answered_with_a_png_returns_the_status(connect: Callable[..., Any]) -> None:
    # An idempotent repeat of a matte that finished during its first request's wait.
    service = (
        FakeService()
        .on("POST", "/matte", png(TRANSFERRED))
        .on("GET", "/jobs/j1", json_answer(200, matte_json("done")))
    )
    job = connect(service).submit_matte(TARGET, SILHOUETTE, [LAYER_0], idempotency_key="k")
    assert (job.status, job.operation) == ("done", "matte")
    assert job.stats is not None and job.stats["layer_size"] == [52, 40]


@pytest.mark.parametrize("method", ["matte", "submit_matte"])
@pytest.mark.parametrize(
    ("layers", "error", "fragment"),
    [
        ([], ValidationError, "at least one"),
        ((), ValidationError, "at least one"),
        (LAYER_0, TypeError, "in a list"),
        ("brick.png", TypeError, "in a list"),
        (Path("brick.png"), TypeError, "in a list"),
    ],
)
def test_matte_layers_are_checked_before_uploading(
    connect: Callable[..., Any],
    method: str,
    layers: Any,
    error: type[Exception],
    fragment: str,
) -> None:
    service = FakeService()
    with pytest.raises(error, match=fragment) as caught:
        getattr(connect(service), method)(TARGET, SILHOUETTE, layers)
    if isinstance(caught.value, ValidationError):
        assert (caught.value.code, caught.value.field) == ("missing_field", "layer")
        assert caught.value.status is None
    assert service.requests == []


@pytest.mark.parametrize(
    ("companions", "error"),
    [(["normals", "../evil"], ValidationError), ("normals", TypeError), ([""], ValidationError)],
)
def test_matte_companion_names_are_checked_before_uploading(
    connect: Callable[..., Any], companions: Any, error: type[Exception]
) -> None:
    service = FakeService()
    with pytest.raises(error):
        connect(service).matte(TARGET, SILHOUETTE, [LAYER_0], companions=companions)
    assert service.requests == []


def test_matte_companions_asked_twice_are_fetched_once(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/matte", png(TRANSFERRED))
        .on("GET", "/jobs/j1/result/normals", png(NORMAL_OUT, job_id=None))
    )
    result = connect(service).matte(
        TARGET, SILHOUETTE, [LAYER_0], companions=("normals", "normals")
    )
    assert result.companions == {"normals": NORMAL_OUT}
    assert service.paths() == ["POST /matte", "GET /jobs/j1/result/normals"]


MATTE_ERRORS = [
    (422, "invalid_parameter", ValidationError, {"field": "light"}),
    (422, "invalid_image", ValidationError, {}),
    (422, "too_many_layers", ValidationError, {"field": "layer"}),
    (422, "missing_field", ValidationError, {"field": "layer"}),
    (415, "unsupported_media_type", UnsupportedMediaTypeError, {"field": "target"}),
    (413, "file_too_large", PayloadTooLargeError, {}),
    (503, "draining", ServiceUnavailableError, {}),
]


@pytest.mark.parametrize(("status", "code", "cls", "members"), MATTE_ERRORS)
def test_matte_problems_map_to_typed_errors(
    connect: Callable[..., Any],
    status: int,
    code: str,
    cls: type[QuiltingClientError],
    members: dict[str, Any],
) -> None:
    service = FakeService().on("POST", "/matte", problem(status, code, "no matte", **members))
    client = connect(service)
    with pytest.raises(cls) as caught:
        client.matte(TARGET, SILHOUETTE, [LAYER_0], light=(1, 1, 0))
    error = caught.value
    assert type(error) is cls
    assert (error.status, error.code, error.detail) == (status, code, "no matte")
    if isinstance(error, ValidationError):
        assert error.field == members.get("field")
    assert service.paths() == ["POST /matte"] and client.sleeps == []


def test_a_matte_job_has_no_layout(connect: Callable[..., Any]) -> None:
    service = FakeService().on(
        "GET", "/jobs/j1/layout", problem(404, "no_layout", "a matte job has no block layout")
    )
    with pytest.raises(NotFoundError) as caught:
        connect(service).layout("j1")
    assert caught.value.code == "no_layout"


def test_job_status_parses_a_matte_status() -> None:
    done = matte_json("done", timings={"layers": 0.1, "surface": 0.01, "total": 0.2})
    job = JobStatus.from_json(done)
    assert (job.operation, job.status, job.is_terminal) == ("matte", "done", True)
    assert job.layout is None and job.result == "/jobs/j1/result"
    assert job.companions == ("normals", "clusters")
    assert job.stats == MATTE_STATS and job.timings["surface"] == 0.01
    assert hash(job) == hash(JobStatus.from_json(dict(job.raw)))
    queued = JobStatus.from_json(matte_json("queued"))
    assert queued.stats is None and queued.operation == "matte"


def _matte_files(tmp_path: Path) -> dict[str, Path]:
    files = {
        "target": TARGET,
        "mask": SILHOUETTE,
        "brick": LAYER_0,
        "cloud": LAYER_1,
        "n": NORMALS_IN,
    }
    paths = {}
    for name, content in files.items():
        paths[name] = tmp_path / f"{name}.png"
        paths[name].write_bytes(content)
    paths["missing"] = tmp_path / "no.png"
    return paths


def test_cli_matte_writes_the_result_and_the_maps_asked_for(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _matte_files(tmp_path)
    fake_cli.on("POST", "/matte", png(TRANSFERRED)).on(
        "GET", "/jobs/j1/result/normals", png(NORMAL_OUT, job_id=None)
    ).on("GET", "/jobs/j1/result/clusters", png(CLUSTERS_OUT, job_id=None))
    out, normals_out, clusters_out = tmp_path / "o.png", tmp_path / "nm.png", tmp_path / "c.png"
    argv = ["matte", str(paths["target"]), "--silhouette", str(paths["mask"])]
    argv += ["--layer", str(paths["brick"]), "--layer", str(paths["cloud"]), "-o", str(out)]
    argv += ["--server", BASE, "--normals", str(paths["n"]), "--light", "1,1,2"]
    argv += ["--clusters", "8", "--block", "32", "--seed", "0", "--min-z", "0.2"]
    argv += ["--normals-out", str(normals_out), "--clusters-out", str(clusters_out)]
    assert cli.main(argv) == 0
    assert out.read_bytes() == TRANSFERRED
    assert normals_out.read_bytes() == NORMAL_OUT and clusters_out.read_bytes() == CLUSTERS_OUT
    post = fake_cli.only("POST", "/matte")
    assert files_of(post) == [
        ("target", "target.png", TARGET),
        ("silhouette", "mask.png", SILHOUETTE),
        ("layer", "brick.png", LAYER_0),
        ("layer", "cloud.png", LAYER_1),
        ("normals", "n.png", NORMALS_IN),
    ]
    # Only what was given; the light as three numbers.
    assert options_of(post) == {
        "block": 32,
        "seed": 0,
        "clusters": 8,
        "light": [1.0, 1.0, 2.0],
        "min_z": 0.2,
    }
    captured = capsys.readouterr()
    assert captured.out == f"wrote {out}, {normals_out}, {clusters_out} (48x40, job j1)\n"
    assert captured.err == ""


def test_cli_matte_fetches_only_the_maps_asked_for(fake_cli: FakeService, tmp_path: Path) -> None:
    paths = _matte_files(tmp_path)
    fake_cli.on("POST", "/matte", png(TRANSFERRED)).on(
        "GET", "/jobs/j1/result/clusters", png(CLUSTERS_OUT, job_id=None)
    )
    out = tmp_path / "o.png"
    argv = ["matte", str(paths["target"]), "--silhouette", str(paths["mask"]), "-o", str(out)]
    argv += ["--layer", str(paths["brick"]), "--server", BASE]
    assert cli.main(argv) == 0
    assert fake_cli.paths() == ["POST /matte"] and options_of(fake_cli.requests[0]) == {}
    assert sorted(p.name for p in tmp_path.glob("o*.png")) == ["o.png"]
    assert cli.main([*argv, "--clusters-out", str(tmp_path / "c.png")]) == 0
    assert fake_cli.paths()[1:] == ["POST /matte", "GET /jobs/j1/result/clusters"]
    assert (tmp_path / "c.png").read_bytes() == CLUSTERS_OUT


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["matte", "{target}", "--layer", "{brick}", "-o", "{out}", "--server", BASE], "silh"),
        (["matte", "{target}", "--silhouette", "{mask}", "-o", "{out}", "--server", BASE], "lay"),
        (
            [
                *["matte", "{target}", "--silhouette", "{mask}", "--layer", "{brick}"],
                *["-o", "{out}", "--server", BASE, "--light", "1,1"],
            ],
            "X,Y,Z",
        ),
        (
            [
                *["matte", "{target}", "--silhouette", "{mask}", "--layer", "{brick}"],
                *["--layer", "{missing}", "-o", "{out}", "--server", BASE],
            ],
            "no.png",
        ),
        (
            [
                *["matte", "{target}", "--silhouette", "{mask}", "--layer", "{brick}"],
                *["--normals", "{missing}", "-o", "{out}", "--server", BASE],
            ],
            "no.png",
        ),
    ],
)
def test_cli_matte_user_errors_exit_2_and_send_nothing(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    fragment: str,
) -> None:
    paths = _matte_files(tmp_path)
    paths["out"] = tmp_path / "o.png"
    assert cli.main([a.format(**paths) for a in args]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and fragment in err
    assert fake_cli.requests == [] and not paths["out"].exists()


@pytest.mark.parametrize(
    ("answer", "expected", "text"),
    [
        (
            problem(422, "invalid_parameter", "light=(1, 1, 0) is not allowed", field="light"),
            2,
            "light",
        ),
        (
            problem(422, "invalid_image", "silhouette is 10x10; it must be the target's size"),
            2,
            "10x10",
        ),
        (problem(503, "queue_full", "queue is full"), 1, "queue is full"),
    ],
)
def test_cli_matte_refused_by_the_service_is_one_line(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    answer: Handler,
    expected: int,
    text: str,
) -> None:
    paths = _matte_files(tmp_path)
    fake_cli.on("POST", "/matte", answer)
    out = tmp_path / "o.png"
    argv = ["matte", str(paths["target"]), "--silhouette", str(paths["mask"]), "-o", str(out)]
    argv += ["--layer", str(paths["brick"]), "--server", BASE, "--light", "1,1,0"]
    argv += ["--normals-out", str(tmp_path / "nm.png")]
    assert cli.main(argv) == expected
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert text in err
    assert not out.exists() and not (tmp_path / "nm.png").exists()
