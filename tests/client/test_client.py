"""``Client`` and ``AsyncClient`` against an in-process fake of the service
(httpx.MockTransport): what they send (paths, query, headers, multipart parts) and how they
read the answers. Most tests run twice, once per client, through the ``connect`` fixture. The
real service is exercised end to end in tests/service."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
from client_fakes import (
    CLUSTERS_OUT,
    ERRORS,
    FAILED,
    LATE_S,
    LAYER_0,
    LAYER_1,
    MATTE_ERRORS,
    NORMAL,
    NORMAL_OUT,
    NORMALS_IN,
    RESULT,
    ROUGH,
    SILHOUETTE,
    TARGET,
    TEXTURE,
    TILE_ERRORS,
    TILED,
    TRANSFERRED,
    ChattyStream,
    FakeService,
    accepted,
    fails,
    files_of,
    job_json,
    json_answer,
    matte_json,
    multipart,
    options_of,
    png,
    problem,
    sse,
)

from quilting_client import (
    ConflictError,
    ConnectionFailedError,
    JobCancelledError,
    JobFailedError,
    JobStatus,
    NotFoundError,
    QuiltingClientError,
    ServerError,
    ServiceUnavailableError,
    SynthesisResult,
    ValidationError,
    WaitTimeoutError,
)


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
    # The end learnt from the status still completes the bar, as a terminal event does.
    assert calls == [(0.5, "quilting"), (1.0, "done")]
    assert service.paths() == [
        "POST /synthesize",
        "GET /jobs/j1/events",
        "GET /jobs/j1",
        "GET /jobs/j1/result",
    ]


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


def _typed_error(
    connect: Callable[..., Any],
    path: str,
    call: Callable[[Any], object],
    answer: tuple[int, str, type[QuiltingClientError], dict[str, Any]],
) -> QuiltingClientError:
    """The error ``call(client)`` raises when ``POST path`` answers the problem ``answer``
    (status, code, class, members): of exactly that class, with the problem's fields, after
    one request and no sleep (a refused submission is never retried)."""
    status, code, cls, members = answer
    service = FakeService().on("POST", path, problem(status, code, "refused", **members))
    client = connect(service)
    with pytest.raises(cls) as caught:
        call(client)
    error = caught.value
    assert type(error) is cls
    assert (error.status, error.code, error.detail) == (status, code, "refused")
    if isinstance(error, ValidationError):
        assert error.field == members.get("field")
    assert service.paths() == [f"POST {path}"] and client.sleeps == []
    return error


@pytest.mark.parametrize("answer", TILE_ERRORS)
def test_tile_problems_map_to_typed_errors(
    connect: Callable[..., Any],
    answer: tuple[int, str, type[QuiltingClientError], dict[str, Any]],
) -> None:
    error = _typed_error(connect, "/tile", lambda client: client.tile(TEXTURE, band=1000), answer)
    if isinstance(error, ServiceUnavailableError):
        assert error.retry_after == 7.0


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


@pytest.mark.parametrize("answer", MATTE_ERRORS)
def test_matte_problems_map_to_typed_errors(
    connect: Callable[..., Any],
    answer: tuple[int, str, type[QuiltingClientError], dict[str, Any]],
) -> None:
    _typed_error(
        connect,
        "/matte",
        lambda client: client.matte(TARGET, SILHOUETTE, [LAYER_0], light=(1, 1, 0)),
        answer,
    )


def test_a_matte_job_has_no_layout(connect: Callable[..., Any]) -> None:
    service = FakeService().on(
        "GET", "/jobs/j1/layout", problem(404, "no_layout", "a matte job has no block layout")
    )
    with pytest.raises(NotFoundError) as caught:
        connect(service).layout("j1")
    assert caught.value.code == "no_layout"
