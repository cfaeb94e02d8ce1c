"""The fake service the client tests talk to (httpx.MockTransport), its scripted answers,
and the bytes and documents they share."""

from __future__ import annotations

import asyncio
import inspect
import json
import struct
import time
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any

import httpx

from quilting_client import (
    AsyncClient,
    AuthenticationError,
    ConflictError,
    GoneError,
    NotFoundError,
    PayloadTooLargeError,
    ServerError,
    ServiceUnavailableError,
    UnsupportedMediaTypeError,
    ValidationError,
)

BASE = "http://quilting.test"


# Bytes that a sloppy multipart encoder or parser would mangle: CR LF, dashes, NUL, high bytes.
TEXTURE = b"\x89PNG\r\n\x1a\ntexture\r\n--\r\n\x00\xff"


RESULT = b"\x89PNG\r\n\x1a\nresult\r\n\r\n--x\x00"


NORMAL = b"\x89PNG\r\n\x1a\nnormal map"


NORMAL_OUT = b"\x89PNG\r\n\x1a\nquilted normal map"


ROUGH = b"\xff\xd8\xffrough jpeg"


Handler = Callable[[httpx.Request], httpx.Response]


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


def options_of(request: httpx.Request) -> dict[str, Any]:
    [options] = [body for name, _, body in multipart(request) if name == "options"]
    return dict(json.loads(options))


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


#: Seconds within which a client with a timeout of a fraction of a second must have given up:
#: far past its timeout, far short of the chatty stream's length.
LATE_S = 10.0


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


TARGET = b"\x89PNG\r\n\x1a\ntarget\r\n--\x00"


# A PNG signature and IHDR chunk saying 48x40: enough for the CLI to report the size.
TRANSFERRED = (
    b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + struct.pack(">II", 48, 40) + b"rest"
)


# A PNG signature and IHDR chunk saying 48x40, as the tiled image of a 48x40 input would have.
TILED = (
    b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + struct.pack(">II", 48, 40) + b"tiled"
)


def tile_response(content: bytes, content_type: str = "image/png") -> httpx.Response:
    return httpx.Response(
        200,
        content=content,
        headers={"Content-Type": content_type},
        request=httpx.Request("POST", f"{BASE}/tile"),
    )


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


MATTE_ERRORS = [
    (422, "invalid_parameter", ValidationError, {"field": "light"}),
    (422, "invalid_image", ValidationError, {}),
    (422, "too_many_layers", ValidationError, {"field": "layer"}),
    (422, "missing_field", ValidationError, {"field": "layer"}),
    (415, "unsupported_media_type", UnsupportedMediaTypeError, {"field": "target"}),
    (413, "file_too_large", PayloadTooLargeError, {}),
    (503, "draining", ServiceUnavailableError, {}),
]


def matte_files(tmp_path: Path) -> dict[str, Path]:
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


class FakeClock:
    """A monotonic clock that only moves when told to (``clock.now += seconds``), patched over
    a module's ``time`` where a test needs its deadlines or limits to pass on cue."""

    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def monotonic(self) -> float:
        return self.now
