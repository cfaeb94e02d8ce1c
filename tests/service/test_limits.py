"""Every limit of the service answers its status and stable code as application/problem+json,
never a 5xx: hostile images, wrong media types, oversized bodies and files, invalid options,
a full queue, the job time limit and expired results."""

from __future__ import annotations

import io
import json
import struct
import time
import zlib
from collections.abc import Iterator

import httpx
import pytest
from PIL import Image
from service_helpers import (
    SECURED_RESULTS_TTL_S,
    Server,
    assert_png,
    assert_problem,
    assert_status_document,
    job_id_of,
    parse_sse,
    retry_after,
    synth,
    texture,
    wait_expired,
    wait_for,
    wait_idle,
)

SMALL = {"width": 64, "height": 64}


def png_chunk(kind: bytes, payload: bytes) -> bytes:
    return (
        struct.pack(">I", len(payload))
        + kind
        + payload
        + struct.pack(">I", zlib.crc32(kind + payload) & 0xFFFFFFFF)
    )


def png_claiming(width: int, height: int) -> bytes:
    """A well-formed PNG header declaring ``width x height`` with a tiny IDAT."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)  # 8-bit greyscale
    return (
        b"\x89PNG\r\n\x1a\n"
        + png_chunk(b"IHDR", ihdr)
        + png_chunk(b"IDAT", zlib.compress(b"\x00" * 64))
        + png_chunk(b"IEND", b"")
    )


# --- images --------------------------------------------------------------------------------


def test_png_declaring_huge_size_is_refused(client: httpx.Client) -> None:
    bomb = png_claiming(50_000, 50_000)
    assert len(bomb) < 200
    response = synth(client, SMALL, tex=bomb)
    assert_problem(response, 422, "image_too_large")
    response = synth(client, SMALL, companions={"normal.png": bomb})
    assert_problem(response, 422, "image_too_large")


@pytest.mark.parametrize("cut", [20, 33, 1000, 30000])
def test_truncated_png_is_invalid(client: httpx.Client, cut: int) -> None:
    response = synth(client, SMALL, tex=texture("gravel")[:cut])
    assert_problem(response, 422, "invalid_image")


def test_corrupt_png_is_invalid(client: httpx.Client) -> None:
    data = bytearray(texture("gravel"))
    data[200:400] = bytes(200)  # inside the compressed data: CRC and zlib fail
    assert_problem(synth(client, SMALL, tex=bytes(data)), 422, "invalid_image")


def _bmp() -> bytes:
    buffer = io.BytesIO()
    Image.open(io.BytesIO(texture("wood"))).save(buffer, format="BMP")
    return buffer.getvalue()


@pytest.mark.parametrize(
    "data",
    [_bmp(), b"just some text, not an image\n", b"", b"GIF89a" + bytes(64)],
    ids=["bmp", "text", "empty", "gif"],
)
def test_unsupported_media_type(client: httpx.Client, data: bytes) -> None:
    assert_problem(synth(client, SMALL, tex=data), 415, "unsupported_media_type", field="texture")
    response = synth(client, SMALL, companions={"normal.png": data})
    assert_problem(response, 415, "unsupported_media_type", field="companion")


# --- body and file size --------------------------------------------------------------------


@pytest.fixture(scope="module")
def hundred_mb() -> bytes:
    return b"\x89PNG\r\n\x1a\n" + bytes(100_000_000)


def test_body_over_default_limit(client: httpx.Client, hundred_mb: bytes) -> None:
    response = synth(client, SMALL, tex=hundred_mb)
    assert_problem(response, 413, "body_too_large")
    assert client.get("/healthz").status_code == 200


def test_body_over_limit_without_content_length(small_client: httpx.Client) -> None:
    """A chunked body (no Content-Length) past max_body_bytes (1 MB here) is 413 too."""
    boundary = "limitboundary"

    def body() -> Iterator[bytes]:
        yield (
            f'--{boundary}\r\nContent-Disposition: form-data; name="options"\r\n\r\n'
            f"{json.dumps(SMALL)}\r\n--{boundary}\r\nContent-Disposition: form-data; "
            f'name="texture"; filename="t.png"\r\nContent-Type: image/png\r\n\r\n'
        ).encode()
        yield b"\x89PNG\r\n\x1a\n"
        for _ in range(4):
            yield bytes(1 << 19)
        yield f"\r\n--{boundary}--\r\n".encode()

    response = small_client.post(
        "/synthesize",
        content=body(),
        headers={"Content-Type": f"multipart/form-data; boundary={boundary}"},
    )
    assert "content-length" not in response.request.headers
    assert_problem(response, 413, "body_too_large")


def test_body_over_small_limit(small_client: httpx.Client) -> None:
    data = b"\x89PNG\r\n\x1a\n" + bytes(1_100_000)
    assert_problem(synth(small_client, SMALL, tex=data), 413, "body_too_large")


def test_file_over_max_file_bytes(small_client: httpx.Client) -> None:
    # QUILTING_MAX_FILE_BYTES=40000: gravel.png (54 kB) is over, brick.png (30 kB) under.
    response = synth(small_client, SMALL, tex="gravel")
    assert_problem(response, 413, "file_too_large", field="texture")
    response = synth(small_client, SMALL, tex="brick", companions={"n.png": texture("gravel")})
    assert_problem(response, 413, "file_too_large", field="companion")
    assert_png(synth(small_client, SMALL, tex="brick"), 64, 64)


# --- options -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "code", "field"),
    [
        ({"width": -5, "height": 64}, "invalid_parameter", "width"),
        ({"width": 0, "height": 64}, "invalid_parameter", "width"),
        ({"width": 64, "height": -1}, "invalid_parameter", "height"),
        ({"width": 16385, "height": 64}, "invalid_parameter", "width"),  # > max_side
        ({"width": 64, "height": 10**9}, "invalid_parameter", "height"),
        ({"width": 16384, "height": 8192}, "invalid_parameter", "width"),  # > max_output_pixels
        ({"width": 64.5, "height": 64}, "invalid_parameter", "width"),
        ({"width": "wide", "height": 64}, "invalid_parameter", "width"),
        ({"width": True, "height": 64}, "invalid_parameter", "width"),
        ({**SMALL, "block": 257}, "invalid_parameter", "block"),  # texture is 256x256
        ({**SMALL, "block": 2}, "invalid_parameter", "block"),
        ({**SMALL, "block": 48, "overlap": 24}, "invalid_parameter", "overlap"),
        ({**SMALL, "block": 48, "overlap": 30}, "invalid_parameter", "overlap"),
        ({**SMALL, "overlap": 0}, "invalid_parameter", "overlap"),
        ({**SMALL, "tolerance": -0.1}, "invalid_parameter", "tolerance"),
        ({**SMALL, "tolerance": 11}, "invalid_parameter", "tolerance"),
        ({**SMALL, "mode": "zigzag"}, "invalid_parameter", "mode"),
        ({**SMALL, "seed": -1}, "invalid_parameter", "seed"),
        ({**SMALL, "seed": 2**64}, "invalid_parameter", "seed"),
        ({**SMALL, "backend": "quantum"}, "invalid_parameter", "backend"),
        ({**SMALL, "min_candidates": 0}, "invalid_parameter", "min_candidates"),
        ({**SMALL, "colour": "red"}, "invalid_options", "colour"),
        ("not json {", "invalid_options", "options"),
        ("[64, 64]", "invalid_options", "options"),
        ('"64x64"', "invalid_options", "options"),
        ("null", "invalid_options", "options"),
        ({"height": 64}, ("missing_field", "invalid_parameter"), "width"),
        ({"width": 64}, ("missing_field", "invalid_parameter"), "height"),
        ({}, ("missing_field", "invalid_parameter"), "width"),
    ],
    ids=lambda v: json.dumps(v)[:40] if not isinstance(v, str) else v[:20],
)
def test_invalid_options(
    client: httpx.Client, options: object, code: str | tuple[str, ...], field: str
) -> None:
    response = synth(client, options)  # type: ignore[arg-type]
    assert_problem(response, 422, code, field=field)


def test_missing_texture_and_options(client: httpx.Client) -> None:
    response = client.post("/synthesize", data={"options": json.dumps(SMALL)})
    assert_problem(response, 422, "missing_field", field="texture")
    response = client.post(
        "/synthesize", files={"texture": ("t.png", texture("gravel"), "image/png")}
    )
    assert_problem(response, 422, "missing_field", field="options")
    response = client.post("/synthesize")
    assert_problem(response, 422, "missing_field")


def test_not_multipart(client: httpx.Client) -> None:
    response = client.post("/synthesize", json={"options": SMALL})
    assert 400 <= response.status_code < 500
    assert response.headers["content-type"] == "application/problem+json"


@pytest.mark.parametrize("wait", ["60.5", "1000", "-1", "soon", "nan"])
def test_invalid_wait(client: httpx.Client, wait: str) -> None:
    response = client.post("/synthesize", params={"wait": wait}, **_request())
    assert_problem(response, 422, "invalid_parameter", field="wait")


def _request() -> dict[str, object]:
    return {
        "files": {"texture": ("t.png", texture("gravel"), "image/png")},
        "data": {"options": json.dumps(SMALL)},
    }


def test_max_wait_is_accepted(client: httpx.Client) -> None:
    assert_png(synth(client, SMALL, wait=60), 64, 64)


# --- queue, time limit, expiry -------------------------------------------------------------


def test_queue_full(small_client: httpx.Client) -> None:
    """One worker and a queue of two: the fourth big job is refused with 503 queue_full."""
    wait_idle(small_client)
    accepted: list[str] = []
    refused: httpx.Response | None = None
    try:
        for seed in range(6):
            response = synth(
                small_client, {"width": 2048, "height": 2048, "seed": seed}, tex="brick", wait=0
            )
            if response.status_code == 503:
                refused = response
                break
            accepted.append(job_id_of(response))
            if seed == 0:
                wait_for(small_client, accepted[0], ("running",))
        assert refused is not None, "the queue never filled"
        assert len(accepted) == 3  # one running, two queued
        assert_problem(refused, 503, "queue_full")
        retry_after(refused)
        ready = small_client.get("/readyz")
        assert_problem(ready, 503, "queue_full")
        # Reads still work while the queue is full.
        assert small_client.get(f"/jobs/{accepted[-1]}").json()["status"] == "queued"
        assert small_client.get("/healthz").status_code == 200
    finally:
        for job_id in accepted:
            small_client.delete(f"/jobs/{job_id}")
    for job_id in accepted:
        assert wait_for(small_client, job_id)["status"] == "cancelled"
    wait_idle(small_client)
    assert small_client.get("/readyz").status_code == 200


def test_job_time_limit(timeout_server: Server) -> None:
    with timeout_server.client() as client:
        response = synth(client, {"width": 1024, "height": 1024}, wait=60)
        assert response.status_code == 202, response.text  # not done: failed
        status = response.json()
        assert status["status"] == "failed", status
        assert_status_document(status)
        error = status["error"]
        assert error["code"] == "job_timeout"
        assert error["type"] == "https://quilting.dev/problems/job_timeout"
        assert isinstance(error["detail"], str) and error["detail"]
        # Stopped by the limit before its end (seconds of work), not failed after finishing.
        assert status["progress"] < 1, status
        assert_problem(client.get(f"/jobs/{status['id']}/result"), 409, "job_failed")
        assert_problem(client.delete(f"/jobs/{status['id']}"), 409, "job_finished")
        with client.stream("GET", f"/jobs/{status['id']}/events") as stream:
            events = parse_sse(list(stream.iter_lines()))
        assert [name for name, _ in events] == ["failed"]
        assert json.loads(events[0][1])["error"]["code"] == "job_timeout"


def test_results_expire_by_count(small_client: httpx.Client) -> None:
    """QUILTING_RESULTS_MAX_COUNT=2: the third finished job evicts the first's results."""
    wait_idle(small_client)
    ids = [
        job_id_of(synth(small_client, {**SMALL, "seed": s}, tex="brick", companions=None))
        for s in range(3)
    ]
    first = ids[0]
    assert_problem(small_client.get(f"/jobs/{first}/result"), 410, "result_expired")
    assert_problem(small_client.get(f"/jobs/{first}/layout"), 410, "result_expired")
    status = small_client.get(f"/jobs/{first}")
    assert status.status_code in (200, 410), status.text
    if status.status_code == 200:
        assert status.json()["result"] is None
    for job_id in ids[1:]:
        assert_png(small_client.get(f"/jobs/{job_id}/result"), 64, 64)


def test_results_expire_by_age(secured_client: httpx.Client) -> None:
    """QUILTING_RESULTS_TTL_S: a result is gone (410) once that long has passed since its job
    finished, and not before."""
    headers = {"Authorization": "Bearer k1"}
    submitted = time.monotonic()
    response = synth(secured_client, SMALL, headers=headers)
    assert_png(response, 64, 64)
    job_id = job_id_of(response)
    wait_expired(secured_client, job_id, headers=headers)  # polled: no guess at the delay
    assert time.monotonic() - submitted >= SECURED_RESULTS_TTL_S
    assert_problem(
        secured_client.get(f"/jobs/{job_id}/result", headers=headers), 410, "result_expired"
    )
    assert_problem(
        secured_client.get(f"/jobs/{job_id}/layout", headers=headers), 410, "result_expired"
    )
