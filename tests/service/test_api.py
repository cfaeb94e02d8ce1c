"""Every endpoint of the HTTP service against a real server: synthesis (sync and async),
companions, layout, events, cancellation, health, readiness, metrics, idempotency, API keys and
CORS."""

from __future__ import annotations

import io
import itertools
import json
import threading
import time

import httpx
import numpy as np
import pytest
from PIL import Image
from service_helpers import (
    FINAL,
    Server,
    assert_png,
    assert_problem,
    assert_status_document,
    job_id_of,
    metric_values,
    parse_sse,
    png_image,
    retry_after,
    synth,
    texture,
    wait_for,
    wait_idle,
)

from quilting.backends import auto_choice, available_backends

# --- POST /synthesize, synchronous ---------------------------------------------------------


def test_sync_synthesis_returns_png_of_the_requested_size(client: httpx.Client) -> None:
    response = synth(client, {"width": 200, "height": 120, "seed": 3})
    image = assert_png(response, 200, 120)
    job_id = job_id_of(response)
    assert image.mode == Image.open(io.BytesIO(texture("gravel"))).mode

    status = client.get(response.headers["Location"])
    assert status.status_code == 200
    body = status.json()
    assert_status_document(body)
    assert body["id"] == job_id
    assert body["status"] == "done"
    assert (body["width"], body["height"]) == (200, 120)
    assert (body["backend"], body["renderer"], body["fallback"]) == (auto_choice()[0], "cpu", None)
    # The result endpoint serves the very bytes the POST answered with.
    assert client.get(f"/jobs/{job_id}/result").content == response.content


@pytest.mark.gl
def test_job_status_names_the_gl_renderer(client: httpx.Client) -> None:
    # Asked for by name, gl runs on whatever renderer the worker's context has (llvmpipe in
    # CI); the status says so, and the bytes equal the fft result's.
    renderer = next(s for s in available_backends() if s.name == "gl").renderer
    if renderer is None:
        pytest.skip("no OpenGL 4.3 context on this machine")
    options = {"width": 96, "height": 80, "block": 24, "seed": 5}
    on_gl = synth(client, {**options, "backend": "gl"})
    body = client.get(on_gl.headers["Location"]).json()
    assert (body["backend"], body["renderer"], body["fallback"]) == ("gl", renderer, None)
    on_fft = synth(client, {**options, "backend": "fft"})
    assert png_image(on_gl.content).tobytes() == png_image(on_fft.content).tobytes()


@pytest.mark.parametrize(("name", "width", "height"), [("hubble", 97, 301), ("wood", 160, 64)])
def test_sync_synthesis_sizes_and_colour_textures(
    client: httpx.Client, name: str, width: int, height: int
) -> None:
    options = {"width": width, "height": height, "block": 32}
    image = assert_png(synth(client, options, tex=name), width, height)
    assert image.mode == "RGB"


def test_same_seed_gives_identical_pixels(client: httpx.Client) -> None:
    options = {"width": 128, "height": 96, "seed": 7}
    first = np.asarray(png_image(synth(client, options).content))
    second = np.asarray(png_image(synth(client, options).content))
    other = np.asarray(png_image(synth(client, {**options, "seed": 8}).content))
    assert np.array_equal(first, second)
    assert not np.array_equal(first, other)  # the seed is not ignored


def test_same_seed_gives_identical_bytes(client: httpx.Client) -> None:
    """Same texture, options and seed -> the same PNG, byte for byte (two different jobs)."""
    options = {"width": 128, "height": 96, "seed": 7}
    first, second = synth(client, options), synth(client, options)
    assert job_id_of(first) != job_id_of(second)
    assert first.content == second.content


def test_jpeg_texture_is_accepted(client: httpx.Client) -> None:
    buffer = io.BytesIO()
    Image.open(io.BytesIO(texture("hubble"))).save(buffer, format="JPEG", quality=90)
    assert_png(synth(client, {"width": 100, "height": 80}, tex=buffer.getvalue()), 100, 80)


# --- POST /synthesize, asynchronous --------------------------------------------------------


def test_async_synthesis_status_result_and_layout(client: httpx.Client) -> None:
    response = synth(client, {"width": 1024, "height": 768, "seed": 1}, wait=0)
    assert response.status_code == 202, response.text
    assert response.headers["content-type"] == "application/json"
    job_id = job_id_of(response)
    retry_after(response)
    accepted = response.json()
    assert_status_document(accepted)
    assert accepted["status"] in ("queued", "running")
    assert (accepted["width"], accepted["height"]) == (1024, 768)

    status = wait_for(client, job_id)
    assert status["status"] == "done", status
    assert_status_document(status)
    assert status["companions"] == []
    assert isinstance(status["stats"], dict)

    assert_png(client.get(status["result"]), 1024, 768)
    layout = client.get(status["layout"])
    assert layout.status_code == 200
    assert layout.headers["content-type"].startswith("application/json")
    document = layout.json()
    assert document["output_shape"] == [768, 1024]
    assert document["meta"]["seed"] == 1


def test_wait_zero_never_blocks_and_default_wait_returns_png(client: httpx.Client) -> None:
    response = synth(client, {"width": 2048, "height": 2048}, wait=0)
    assert response.status_code == 202
    # Answered before the job (seconds of work) could end: the request did not wait for it.
    assert response.json()["status"] in ("queued", "running"), response.text
    job_id = job_id_of(response)
    # No wait parameter: the default wait (10 s) is long enough for a small job.
    assert_png(synth(client, {"width": 64, "height": 64}, wait=None), 64, 64)
    client.delete(f"/jobs/{job_id}")
    wait_for(client, job_id)


def test_status_while_running_and_result_not_ready(client: httpx.Client) -> None:
    job_id = job_id_of(synth(client, {"width": 2048, "height": 2048, "seed": 5}, wait=0))
    status = wait_for(client, job_id, ("running",))
    assert_status_document(status)
    assert status["started"] is not None and status["finished"] is None
    for path in ("result", "layout", "result/normal"):
        response = client.get(f"/jobs/{job_id}/{path}")
        assert_problem(response, 409, "job_not_done")
    client.delete(f"/jobs/{job_id}")
    wait_for(client, job_id)


# --- companions ----------------------------------------------------------------------------


def test_companions_are_quilted_to_the_output_size(client: httpx.Client) -> None:
    # hubble.png is 256x256 like brick.png: it serves as a "normal map" of the brick texture.
    companions = {"normal.png": texture("hubble"), "rough-ness_2.png": texture("gravel")}
    response = synth(client, {"width": 300, "height": 200}, tex="brick", companions=companions)
    assert_png(response, 300, 200)
    job_id = job_id_of(response)
    status = client.get(f"/jobs/{job_id}").json()
    assert sorted(status["companions"]) == ["normal", "rough-ness_2"]
    normal = assert_png(client.get(f"/jobs/{job_id}/result/normal"), 300, 200)
    assert normal.mode == "RGB"
    assert_png(client.get(f"/jobs/{job_id}/result/rough-ness_2"), 300, 200)
    assert_problem(client.get(f"/jobs/{job_id}/result/albedo"), 404, "companion_not_found")


def test_companion_follows_the_same_layout(client: httpx.Client) -> None:
    """A companion equal to the texture is quilted into exactly the result image."""
    response = synth(
        client,
        {"width": 150, "height": 170, "seed": 11},
        tex="gravel",
        companions={"copy.png": texture("gravel")},
    )
    result = np.asarray(assert_png(response, 150, 170))
    copy = client.get(f"/jobs/{job_id_of(response)}/result/copy")
    assert np.array_equal(np.asarray(assert_png(copy, 150, 170)), result)


def test_companion_of_another_size_is_refused(client: httpx.Client) -> None:
    response = synth(
        client,
        {"width": 64, "height": 64},
        tex="gravel",
        companions={"normal.png": texture("wood")},
    )
    assert_problem(response, 422, "invalid_companion", field="companion")


def test_at_most_max_companions(client: httpx.Client) -> None:
    many = [(f"map{i}.png", texture("gravel")) for i in range(9)]  # max_companions is 8
    response = synth(client, {"width": 64, "height": 64}, companions=many)
    assert_problem(response, 422, "invalid_companion", field="companion")
    response = synth(client, {"width": 64, "height": 64}, companions=many[:8])
    assert_png(response, 64, 64)
    assert len(client.get(f"/jobs/{job_id_of(response)}").json()["companions"]) == 8


@pytest.mark.parametrize(
    "companions",
    [
        [("normal.png", b"x"), ("normal.png", b"y")],  # duplicate name
        [("bad name.png", b"x")],
        [(".png", b"x")],
        [("x" * 65 + ".png", b"x")],
    ],
    ids=["duplicate", "space", "empty", "too-long"],
)
def test_companion_names_are_checked(
    client: httpx.Client, companions: list[tuple[str, bytes]]
) -> None:
    files = [(name, texture("gravel")) for name, _ in companions]
    response = synth(client, {"width": 64, "height": 64}, companions=files)
    assert_problem(response, 422, "invalid_companion", field="companion")


# --- events --------------------------------------------------------------------------------


def _events(client: httpx.Client, job_id: str) -> list[tuple[str, str]]:
    with client.stream("GET", f"/jobs/{job_id}/events") as stream:
        assert stream.status_code == 200
        assert stream.headers["content-type"].startswith("text/event-stream")
        lines = list(stream.iter_lines())  # returns only once the server ends the stream
    return parse_sse(lines)


def test_events_stream_progress_then_one_done(client: httpx.Client) -> None:
    job_id = job_id_of(synth(client, {"width": 1536, "height": 1024}, wait=0))
    events = _events(client, job_id)
    assert len(events) >= 2, events
    *progress, (last, data) = events
    assert [name for name, _ in progress] == ["progress"] * len(progress)
    values = [json.loads(d) for _, d in progress]
    fractions = [v["progress"] for v in values]
    assert fractions == sorted(fractions), fractions
    assert all(0.0 <= f <= 1.0 for f in fractions)
    assert all(v["status"] in ("queued", "running") for v in values)
    # "only when changed": no two consecutive progress events are the same.
    pairs = [(v["progress"], v["stage"]) for v in values]
    assert all(a != b for a, b in itertools.pairwise(pairs)), pairs
    assert last == "done"
    final = json.loads(data)
    assert_status_document(final)
    assert final["id"] == job_id and final["status"] == "done"
    assert final == client.get(f"/jobs/{job_id}").json()


def test_events_of_a_finished_job_is_just_done(client: httpx.Client) -> None:
    job_id = job_id_of(synth(client, {"width": 64, "height": 64}))
    events = _events(client, job_id)
    assert [name for name, _ in events] == ["done"]
    assert json.loads(events[0][1])["id"] == job_id


# --- DELETE --------------------------------------------------------------------------------


def test_cancel_a_running_job(client: httpx.Client) -> None:
    job_id = job_id_of(synth(client, {"width": 3000, "height": 3000, "seed": 2}, wait=0))
    wait_for(client, job_id, ("running",))
    response = client.delete(f"/jobs/{job_id}")
    assert response.status_code == 202, response.text
    assert response.json()["id"] == job_id
    assert_status_document(response.json())
    # It stops at its next progress report, long before its end (tens of seconds of work):
    # cancelled with the progress short of 1, whatever the machine's speed.
    status = wait_for(client, job_id)
    assert status["status"] == "cancelled", status
    assert status["progress"] < 1, status
    assert_status_document(status)
    assert_problem(client.get(f"/jobs/{job_id}/result"), 409, "job_cancelled")
    assert_problem(client.get(f"/jobs/{job_id}/layout"), 409, "job_cancelled")
    events = _events(client, job_id)
    assert [name for name, _ in events] == ["cancelled"]


def test_cancel_a_queued_job_is_immediate(client: httpx.Client) -> None:
    # Two workers: two big jobs occupy them, the third waits in the queue.
    big = [
        job_id_of(synth(client, {"width": 2048, "height": 2048, "seed": s}, wait=0)) for s in (1, 2)
    ]
    queued = job_id_of(synth(client, {"width": 2048, "height": 2048, "seed": 3}, wait=0))
    for job_id in big:
        wait_for(client, job_id, ("running",))
    assert client.get(f"/jobs/{queued}").json()["status"] == "queued"
    response = client.delete(f"/jobs/{queued}")
    assert response.status_code == 202
    assert response.json()["status"] == "cancelled"
    for job_id in big:
        client.delete(f"/jobs/{job_id}")
    for job_id in [*big, queued]:
        assert wait_for(client, job_id)["status"] == "cancelled"
    wait_idle(client)


def test_cancel_a_finished_job_is_a_conflict(client: httpx.Client) -> None:
    job_id = job_id_of(synth(client, {"width": 64, "height": 64}))
    assert_problem(client.delete(f"/jobs/{job_id}"), 409, "job_finished")
    assert client.get(f"/jobs/{job_id}").json()["status"] == "done"


# --- unknown jobs and routes ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("method", "path"),
    [
        ("GET", "/jobs/{id}"),
        ("GET", "/jobs/{id}/result"),
        ("GET", "/jobs/{id}/result/normal"),
        ("GET", "/jobs/{id}/layout"),
        ("GET", "/jobs/{id}/events"),
        ("DELETE", "/jobs/{id}"),
    ],
)
def test_unknown_job_is_404(client: httpx.Client, method: str, path: str) -> None:
    job_id = "0123456789abcdef0123456789abcdef"
    response = client.request(method, path.format(id=job_id))
    body = assert_problem(response, 404, "job_not_found")
    assert body.get("job_id") == job_id


def test_unknown_route_and_method_are_problems(client: httpx.Client) -> None:
    response = client.get("/nowhere")
    assert response.status_code == 404
    assert response.headers["content-type"] == "application/problem+json"
    response = client.put("/healthz")
    assert response.status_code == 405
    assert response.headers["content-type"] == "application/problem+json"


# --- health, readiness, metrics ------------------------------------------------------------


def test_healthz(client: httpx.Client) -> None:
    response = client.get("/healthz")
    assert response.status_code == 200
    assert response.json() == {"status": "ok"}


def test_readyz_fields(client: httpx.Client) -> None:
    wait_idle(client)
    response = client.get("/readyz")
    assert response.status_code == 200
    body = response.json()
    assert body == {
        "status": "ready",
        "queue": "memory",
        "backend": "fft",
        "renderer": "cpu",
        "backend_reason": auto_choice()[1],
        "queue_depth": 0,
        "running": 0,
        "workers": 2,
        "matting": True,
    }


def test_readyz_counts_running_and_queued_jobs(client: httpx.Client) -> None:
    ids = [
        job_id_of(synth(client, {"width": 2048, "height": 2048, "seed": s}, wait=0))
        for s in range(3)
    ]
    for job_id in ids[:2]:
        wait_for(client, job_id, ("running",))
    body = client.get("/readyz").json()
    assert (body["running"], body["queue_depth"]) == (2, 1), body
    for job_id in ids:
        client.delete(f"/jobs/{job_id}")
    wait_idle(client)


def test_metrics_count_a_finished_job(client: httpx.Client) -> None:
    wait_idle(client)
    before_response = client.get("/metrics")
    assert before_response.status_code == 200
    assert before_response.headers["content-type"].startswith("text/plain")
    before = metric_values(before_response.text)
    for status in ("queued", "running", *FINAL):
        assert f'quilting_jobs{{status="{status}"}}' in before
    assert before["quilting_queue_depth"] == 0
    assert 'quilting_job_seconds_bucket{le="+Inf"}' in before

    assert_png(synth(client, {"width": 100, "height": 50}), 100, 50)
    after = metric_values(client.get("/metrics").text)

    def delta(name: str) -> float:
        return after[name] - before.get(name, 0.0)

    assert delta("quilting_pixels_produced_total") == 100 * 50
    assert delta('quilting_jobs{status="done"}') == 1
    assert delta('quilting_jobs_finished_total{status="done"}') == 1
    assert delta("quilting_job_seconds_count") == 1
    assert delta('quilting_job_seconds_bucket{le="+Inf"}') == 1
    assert delta("quilting_job_seconds_sum") > 0
    buckets = [v for k, v in after.items() if k.startswith("quilting_job_seconds_bucket")]
    assert buckets == sorted(buckets)  # cumulative
    assert buckets[-1] == after["quilting_job_seconds_count"]


# --- Idempotency-Key -----------------------------------------------------------------------


def test_idempotency_key_same_body_same_job(client: httpx.Client) -> None:
    options = {"width": 96, "height": 96, "seed": 21}
    key = {"Idempotency-Key": "test-same-body"}
    first = synth(client, options, headers=key)
    second = synth(client, options, headers=key)
    assert job_id_of(first) == job_id_of(second)
    assert first.status_code == second.status_code == 200
    assert first.content == second.content
    # Without the key, or with another, the same body makes a new job.
    assert job_id_of(synth(client, options)) != job_id_of(first)
    other = synth(client, options, headers={"Idempotency-Key": "test-other"})
    assert job_id_of(other) != job_id_of(first)


def test_idempotency_key_async_repeat(client: httpx.Client) -> None:
    options = {"width": 1024, "height": 1024, "seed": 22}
    key = {"Idempotency-Key": "test-async"}
    first = synth(client, options, headers=key, wait=0)
    second = synth(client, options, headers=key, wait=0)
    assert first.status_code == 202
    assert second.status_code in (200, 202)
    assert job_id_of(first) == job_id_of(second)
    assert wait_for(client, job_id_of(first))["status"] == "done"


def test_idempotency_key_different_body_conflicts(client: httpx.Client) -> None:
    key = {"Idempotency-Key": "test-conflict"}
    first = synth(client, {"width": 64, "height": 64, "seed": 1}, headers=key)
    job_id_of(first)
    response = synth(client, {"width": 64, "height": 64, "seed": 2}, headers=key)
    assert_problem(response, 409, "idempotency_conflict")
    response = synth(client, {"width": 64, "height": 64, "seed": 1}, tex="brick", headers=key)
    assert_problem(response, 409, "idempotency_conflict")


# --- API keys ------------------------------------------------------------------------------

K1 = {"Authorization": "Bearer k1"}
K1_HEADER = {"X-API-Key": "k1"}
K2 = {"Authorization": "Bearer k2"}


@pytest.mark.parametrize(
    "headers",
    [{}, {"Authorization": "Bearer nope"}, {"X-API-Key": "k3"}, {"Authorization": "k1"}],
    ids=["none", "wrong-bearer", "wrong-x-api-key", "no-bearer-prefix"],
)
def test_api_key_required(secured_client: httpx.Client, headers: dict[str, str]) -> None:
    response = synth(secured_client, {"width": 64, "height": 64}, headers=headers)
    assert_problem(response, 401, "unauthorized")
    assert "WWW-Authenticate" in response.headers
    assert_problem(secured_client.get("/jobs/abc", headers=headers), 401, "unauthorized")
    # Probes stay open.
    assert secured_client.get("/healthz", headers=headers).status_code == 200


def test_jobs_are_private_to_their_key(secured_client: httpx.Client) -> None:
    response = synth(secured_client, {"width": 80, "height": 60}, headers=K1, wait=0)
    job_id = job_id_of(response)
    assert wait_for(secured_client, job_id, headers=K1)["status"] == "done"
    # The same key by the other header sees it too.
    assert secured_client.get(f"/jobs/{job_id}", headers=K1_HEADER).status_code == 200
    for method, path in [
        ("GET", f"/jobs/{job_id}"),
        ("GET", f"/jobs/{job_id}/result"),
        ("GET", f"/jobs/{job_id}/layout"),
        ("GET", f"/jobs/{job_id}/events"),
        ("DELETE", f"/jobs/{job_id}"),
    ]:
        for other in (K2, {"X-API-Key": "k2"}):
            response = secured_client.request(method, path, headers=other)
            assert_problem(response, 404, "job_not_found")
    assert secured_client.get(f"/jobs/{job_id}", headers=K1).json()["status"] == "done"


def test_x_api_key_header_submits(secured_client: httpx.Client) -> None:
    response = synth(secured_client, {"width": 64, "height": 48}, headers={"X-API-Key": "k2"})
    assert_png(response, 64, 48)
    job_id = job_id_of(response)
    assert secured_client.get(f"/jobs/{job_id}", headers=K2).status_code == 200
    assert_problem(secured_client.get(f"/jobs/{job_id}", headers=K1), 404, "job_not_found")


def test_idempotency_keys_are_per_api_key(secured_client: httpx.Client) -> None:
    idem = {"Idempotency-Key": "shared"}
    first = synth(secured_client, {"width": 64, "height": 64, "seed": 1}, headers={**K1, **idem})
    second = synth(secured_client, {"width": 64, "height": 64, "seed": 2}, headers={**K2, **idem})
    assert job_id_of(first) != job_id_of(second)


# --- CORS ----------------------------------------------------------------------------------

ORIGIN = "https://app.example"


def test_cors_preflight_for_the_allowed_origin(secured_client: httpx.Client) -> None:
    response = secured_client.options(
        "/synthesize",
        headers={
            "Origin": ORIGIN,
            "Access-Control-Request-Method": "POST",
            "Access-Control-Request-Headers": "authorization, idempotency-key",
        },
    )
    assert response.status_code == 200
    assert response.headers["Access-Control-Allow-Origin"] == ORIGIN
    assert "POST" in response.headers["Access-Control-Allow-Methods"]
    allowed = response.headers["Access-Control-Allow-Headers"].lower()
    assert "authorization" in allowed and "idempotency-key" in allowed


def test_cors_simple_requests(secured_client: httpx.Client) -> None:
    response = secured_client.get("/healthz", headers={"Origin": ORIGIN})
    assert response.headers["Access-Control-Allow-Origin"] == ORIGIN
    response = synth(secured_client, {"width": 64, "height": 64}, headers={**K1, "Origin": ORIGIN})
    assert response.status_code == 200
    assert response.headers["Access-Control-Allow-Origin"] == ORIGIN
    exposed = response.headers["Access-Control-Expose-Headers"].lower()
    assert "x-job-id" in exposed and "location" in exposed


def test_cors_other_origin_gets_no_grant(secured_client: httpx.Client) -> None:
    evil = "https://evil.example"
    response = secured_client.get("/healthz", headers={"Origin": evil})
    assert "Access-Control-Allow-Origin" not in response.headers
    response = secured_client.options(
        "/synthesize", headers={"Origin": evil, "Access-Control-Request-Method": "POST"}
    )
    assert response.status_code < 500
    assert "Access-Control-Allow-Origin" not in response.headers


def test_no_cors_headers_by_default(client: httpx.Client) -> None:
    response = client.get("/healthz", headers={"Origin": ORIGIN})
    assert response.status_code == 200
    assert not [h for h in response.headers if h.lower().startswith("access-control-")]
    response = client.options(
        "/synthesize", headers={"Origin": ORIGIN, "Access-Control-Request-Method": "POST"}
    )
    assert response.status_code < 500
    assert not [h for h in response.headers if h.lower().startswith("access-control-")]


# --- waiting requests are served concurrently ----------------------------------------------


def test_a_waiting_request_does_not_block_others(client: httpx.Client, server: Server) -> None:
    """While one request waits for a big job, another client is answered at once."""
    results: list[httpx.Response] = []

    def slow() -> None:
        with server.client() as other:
            results.append(synth(other, {"width": 2048, "height": 2048, "seed": 9}, wait=60))

    wait_idle(client)
    thread = threading.Thread(target=slow)
    thread.start()
    try:
        # The big job runs, so its request is waiting in the server.
        deadline = time.monotonic() + 60
        while client.get("/readyz").json()["running"] < 1:
            assert time.monotonic() < deadline, "the big job never started"
            time.sleep(0.02)
        assert client.get("/healthz").status_code == 200
        assert_png(synth(client, {"width": 32, "height": 32}), 32, 32)
        # Answered while the waiting request still waits (its job takes seconds).
        assert not results, "the small request was answered only after the waiting one"
    finally:
        thread.join(120)
    assert_png(results[0], 2048, 2048)


def test_a_gl_service_without_a_context_is_not_ready(start_server) -> None:
    # QUILTING_BACKEND=gl asks for gl by name: no silent fallback, a clear 503 instead.
    server = start_server("no-gl", {"QUILTING_BACKEND": "gl", "QUILTING_GL_DEVICE": "7"})
    with server.client() as client:
        ready = client.get("/readyz")
        assert_problem(ready, 503, "backend_unavailable")
        assert "device 7" in ready.json()["detail"]
        # The job is accepted (the request is valid) and fails with the reason in its status.
        body = synth(client, {"width": 64, "height": 64, "block": 24}).json()
        assert body["status"] == "failed"
        assert body["error"]["code"] == "backend_unavailable"
        assert "device 7" in body["error"]["detail"]
