"""``POST /transfer`` against a real server: the PNG of the target's size (at once or through a
job), the same pixels as :func:`quilting.transfer`, companions, events, cancellation, the
problems of bad requests, and idempotency keys bound to the target and the operation."""

from __future__ import annotations

import io
import json
import re
from collections.abc import Callable

import httpx
import numpy as np
import pytest
from PIL import Image
from service_helpers import (
    Server,
    assert_png,
    assert_problem,
    assert_status_document,
    job_id_of,
    parse_sse,
    png_image,
    synth,
    texture,
    transfer,
    wait_for,
)

import quilting

# Small on purpose: a 48x40 target with blocks of 12 takes a few hundredths of a second.
TARGET_W, TARGET_H = 48, 40
QUICK = {"block": 12, "seed": 3}


def encode(image: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG")
    return buffer.getvalue()


@pytest.fixture(scope="module")
def target() -> bytes:
    """A 48x40 RGB crop of hubble.png: a target with structure, of another mode than gravel."""
    hubble = np.asarray(Image.open(io.BytesIO(texture("hubble"))))
    return encode(np.ascontiguousarray(hubble[100 : 100 + TARGET_H, 60 : 60 + TARGET_W]))


# --- 200 and 202 ----------------------------------------------------------------------------


def test_sync_transfer_returns_png_of_the_target_size(client: httpx.Client, target: bytes) -> None:
    response = transfer(client, QUICK, target=target)
    image = assert_png(response, TARGET_W, TARGET_H)
    # The texture's channels (gravel is gray), the target's size.
    assert image.mode == Image.open(io.BytesIO(texture("gravel"))).mode == "L"
    job_id = job_id_of(response)
    status = client.get(f"/jobs/{job_id}").json()
    assert_status_document(status)
    assert status["operation"] == "transfer" and status["status"] == "done"
    assert (status["width"], status["height"]) == (TARGET_W, TARGET_H)
    error = status["stats"]["correspondence_error"]
    assert isinstance(error, float) and 0.0 <= error < 1.0
    assert client.get(f"/jobs/{job_id}/result").content == response.content


def test_options_may_be_left_out(client: httpx.Client, target: bytes) -> None:
    # Every transfer option has a default; the output is still the target's size.
    assert_png(transfer(client, None, target=target), TARGET_W, TARGET_H)


def test_synthesis_jobs_say_their_operation(client: httpx.Client) -> None:
    response = synth(client, {"width": 32, "height": 32})
    assert client.get(f"/jobs/{job_id_of(response)}").json()["operation"] == "synthesize"


def test_async_transfer_polls_to_done_with_layout(client: httpx.Client) -> None:
    # The whole 256x256 hubble as target in two passes: long enough to answer 202 first.
    options = {"block": 16, "iterations": 2, "seed": 1}
    response = transfer(client, options, target="hubble", wait=0)
    assert response.status_code == 202, response.text
    accepted = response.json()
    assert_status_document(accepted)
    assert accepted["operation"] == "transfer"
    assert (accepted["width"], accepted["height"]) == (256, 256)

    status = wait_for(client, job_id_of(response))
    assert status["status"] == "done", status
    assert_status_document(status)
    assert status["operation"] == "transfer"
    assert isinstance(status["stats"]["correspondence_error"], float)
    assert_png(client.get(status["result"]), 256, 256)
    document = client.get(status["layout"]).json()
    assert document["output_shape"] == [256, 256]
    assert document["meta"]["operation"] == "transfer"
    # The second pass would be 11 px; the passes stop shrinking at min_block (16).
    assert [p["block"] for p in document["meta"]["passes"]] == [16, 16]
    assert len(document["passes"]) == 2


def test_same_request_same_pixels_as_the_python_api(client: httpx.Client, target: bytes) -> None:
    options = {"block": 12, "iterations": 2, "correspondence": "blurred", "sigma": 1.5, "seed": 9}
    first = transfer(client, options, target=target)
    second = transfer(client, options, target=target)
    assert job_id_of(first) != job_id_of(second)
    assert first.content == second.content
    local = quilting.transfer(
        quilting.read_image(texture("gravel")), quilting.read_image(target), **options
    )
    served = np.asarray(png_image(first.content))
    assert served.shape == local.image.shape
    assert served.tobytes() == local.image.tobytes()
    # Not vacuous: the options reach the engine (another seed, other pixels).
    other = transfer(client, {**options, "seed": 10}, target=target)
    assert np.asarray(png_image(other.content)).tobytes() != served.tobytes()


def test_no_remap_and_alpha_reach_the_engine(client: httpx.Client, target: bytes) -> None:
    options = {"block": 12, "alpha": 0.2, "remap": False, "mode": "overlap"}
    served = np.asarray(png_image(transfer(client, options, target=target).content))
    local = quilting.transfer(
        quilting.read_image(texture("gravel")), quilting.read_image(target), **options
    )
    assert served.tobytes() == local.image.tobytes()


# --- companions and events -------------------------------------------------------------------


def test_companion_follows_the_transfer_layout(client: httpx.Client, target: bytes) -> None:
    """A companion equal to the texture is quilted into exactly the result image (unshaded:
    the shading is not recorded in the layout)."""
    response = transfer(
        client,
        {**QUICK, "iterations": 2, "shade": 1},
        target=target,
        companions={"copy.png": texture("gravel"), "normal.png": texture("hubble")},
    )
    result = np.asarray(assert_png(response, TARGET_W, TARGET_H))
    job_id = job_id_of(response)
    assert sorted(client.get(f"/jobs/{job_id}").json()["companions"]) == ["copy", "normal"]
    copy = client.get(f"/jobs/{job_id}/result/copy")
    assert np.array_equal(np.asarray(assert_png(copy, TARGET_W, TARGET_H)), result)
    normal = assert_png(client.get(f"/jobs/{job_id}/result/normal"), TARGET_W, TARGET_H)
    assert normal.mode == "RGB"


def test_companion_of_another_size_is_refused(client: httpx.Client, target: bytes) -> None:
    response = transfer(client, QUICK, target=target, companions={"n.png": texture("wood")})
    assert_problem(response, 422, "invalid_companion", field="companion")


def test_events_report_the_passes_then_done(client: httpx.Client) -> None:
    response = transfer(client, {"block": 12, "iterations": 2}, target="hubble", wait=0)
    job_id = job_id_of(response)
    with client.stream("GET", f"/jobs/{job_id}/events") as stream:
        assert stream.status_code == 200
        events = parse_sse(list(stream.iter_lines()))
    *progress, (last, data) = events
    assert last == "done" and json.loads(data)["operation"] == "transfer"
    stages = [json.loads(d)["stage"] for _, d in progress]
    passes = [stage for stage in stages if stage.startswith("pass")]
    assert all(re.fullmatch(r"pass [12]/2", stage) for stage in passes), stages
    assert passes == sorted(passes)  # pass 1/2 before pass 2/2


def test_cancel_a_running_transfer(client: httpx.Client) -> None:
    hubble = np.asarray(Image.open(io.BytesIO(texture("hubble"))))
    big = encode(np.tile(hubble, (6, 6, 1)))  # 1536x1536, small blocks: many seconds of work
    # (block 16: predicted about 140 s, inside the default 300 s time budget)
    response = transfer(client, {"block": 16, "iterations": 3}, target=big, wait=0)
    job_id = job_id_of(response)
    running = wait_for(client, job_id, ("running",))
    assert running["operation"] == "transfer"
    assert client.delete(f"/jobs/{job_id}").status_code == 202
    status = wait_for(client, job_id)  # cancelled at its next progress report
    assert status["status"] == "cancelled", status
    assert status["progress"] < 1, status
    assert_problem(client.get(f"/jobs/{job_id}/result"), 409, "job_cancelled")


# --- problems ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "code", "field"),
    [
        ("{not json", "invalid_options", "options"),
        ("[1, 2]", "invalid_options", "options"),
        ({"bogus": 1}, "invalid_options", "bogus"),
        ({"width": 64, "height": 64}, "invalid_options", "width"),  # the target sets the size
        ({"alpha": 2}, "invalid_parameter", "alpha"),
        ({"alpha": -0.1}, "invalid_parameter", "alpha"),
        ({"iterations": 0}, "invalid_parameter", "iterations"),
        ({"iterations": 9}, "invalid_parameter", "iterations"),
        ({"correspondence": "custom"}, "invalid_parameter", "correspondence"),
        ({"correspondence": "edges"}, "invalid_parameter", "correspondence"),
        ({"mode": "random"}, "invalid_parameter", "mode"),  # transfer matches every block
        ({"sigma": 0}, "invalid_parameter", "sigma"),
        ({"remap": 1}, "invalid_parameter", "remap"),
        ({"block": 12, "overlap": 6}, "invalid_parameter", "overlap"),
        ({"block": 300}, "invalid_parameter", "block"),  # larger than the 256x256 texture
        ({"backend": "gpu"}, "invalid_parameter", "backend"),
    ],
)
def test_bad_options_are_problems(
    client: httpx.Client, target: bytes, options: dict[str, object] | str, code: str, field: str
) -> None:
    body = assert_problem(transfer(client, options, target=target), 422, code, field=field)
    if field == "correspondence" and options == {"correspondence": "custom"}:
        # Says why, and what to ask for instead.
        assert "Python API" in body["detail"] and "'luminance'" in body["detail"]


def test_missing_target_is_a_missing_field(client: httpx.Client) -> None:
    response = transfer(client, QUICK, target=None)
    assert_problem(response, 422, "missing_field", field="target")


def test_target_that_is_not_an_image_is_415(client: httpx.Client) -> None:
    response = transfer(client, QUICK, target=b"just some text, not a picture")
    assert_problem(response, 415, "unsupported_media_type", field="target")


def test_undecodable_target_is_invalid_image(client: httpx.Client) -> None:
    response = transfer(client, QUICK, target=b"\x89PNG\r\n\x1a\n" + b"\x00" * 64)
    body = assert_problem(response, 422, "invalid_image", field="target")
    assert body["detail"].startswith("target")


def test_target_over_the_input_pixel_limit(client: httpx.Client) -> None:
    # 6000x5000 declares 30 M pixels, over the default max_input_pixels (25 M); the header
    # alone is read, so the refusal is quick.
    huge = encode(np.zeros((5000, 6000), dtype=np.uint8))
    body = assert_problem(transfer(client, QUICK, target=huge), 422, "image_too_large", "target")
    assert "6000x5000" in body["detail"] and "max_input_pixels" in body["detail"]


def test_target_over_the_output_pixel_limit(
    start_server: Callable[[str, dict[str, str]], Server], target: bytes
) -> None:
    server = start_server("small-output", {"QUILTING_MAX_OUTPUT_PIXELS": "1000"})
    with server.client() as client:
        response = transfer(client, QUICK, target=target)  # 48x40 = 1920 pixels
        body = assert_problem(response, 422, "image_too_large", field="target")
        assert "max_output_pixels" in body["detail"]
        hubble = np.asarray(Image.open(io.BytesIO(texture("hubble"))))
        assert_png(transfer(client, QUICK, target=encode(hubble[:30, :30])), 30, 30)


def test_texture_errors_name_the_texture(client: httpx.Client, target: bytes) -> None:
    response = transfer(client, QUICK, tex=b"GIF89a not accepted", target=target)
    assert_problem(response, 415, "unsupported_media_type", field="texture")


# --- Idempotency-Key ----------------------------------------------------------------------------


def test_idempotency_key_binds_the_target(client: httpx.Client, target: bytes) -> None:
    key = {"Idempotency-Key": "transfer-target"}
    first = transfer(client, QUICK, target=target, headers=key)
    again = transfer(client, QUICK, target=target, headers=key)
    assert job_id_of(first) == job_id_of(again)
    assert first.content == again.content
    # The same key with another target is another request: not the first job.
    other_target = encode(np.asarray(png_image(target))[::-1].copy())
    response = transfer(client, QUICK, target=other_target, headers=key)
    assert_problem(response, 409, "idempotency_conflict")


def test_a_synthesis_and_a_transfer_never_share_a_key(client: httpx.Client, target: bytes) -> None:
    key = {"Idempotency-Key": "synthesize-then-transfer"}
    first = synth(client, {"width": TARGET_W, "height": TARGET_H, **QUICK}, headers=key)
    job_id_of(first)
    response = transfer(client, QUICK, target=target, headers=key)
    assert_problem(response, 409, "idempotency_conflict")
