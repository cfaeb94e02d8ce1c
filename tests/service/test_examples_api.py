"""Several examples of one texture over ``POST /synthesize`` (the ``texture`` part repeated):
they reach the engine as a list (the result is the Python API's with the same list and
options), their source masks and companion maps go one per texture, ``weights`` must be one per
texture, and every bad submission of them is a 4xx problem before anything is queued."""

from __future__ import annotations

import json
from typing import Any

import httpx
import numpy as np
import pytest
from service_helpers import (
    assert_png,
    assert_problem,
    job_id_of,
    png_image,
    texture,
    wait_for,
)

import quilting
from quilting.io import encode_png

#: Two examples of one gray texture, of different sizes (gravel.png crops).
GRAVEL = quilting.read_image(texture("gravel"))
FIRST = np.ascontiguousarray(GRAVEL[:64, :64])
SECOND = np.ascontiguousarray(GRAVEL[120:168, 100:156])
OPTIONS = {"block": 12, "seed": 4, "backend": "fft"}
SIZE = (56, 72)  # (height, width)


def _part(name: str, image: np.ndarray, filename: str | None = None) -> tuple[str, Any]:
    return (name, (filename or f"{name}.png", encode_png(image), "image/png"))


def _post(
    client: httpx.Client,
    files: list[tuple[str, Any]],
    options: dict[str, Any],
    *,
    wait: float = 60,
    path: str = "/synthesize",
) -> httpx.Response:
    document = {"width": SIZE[1], "height": SIZE[0], **OPTIONS, **options}
    return client.post(
        path, params={"wait": wait}, files=files, data={"options": json.dumps(document)}
    )


def _pixels(response: httpx.Response) -> np.ndarray:
    return quilting.read_image(response.content)


def test_several_textures_are_quilted_as_the_python_api_quilts_the_list(
    client: httpx.Client,
) -> None:
    options = {"weights": [1, 3], "transforms": "flips"}
    files = [_part("texture", FIRST, "a.png"), _part("texture", SECOND, "b.png")]
    response = _post(client, files, options)
    assert_png(response, SIZE[1], SIZE[0])
    local = quilting.synthesize([FIRST, SECOND], SIZE, **OPTIONS, **options)
    assert np.array_equal(_pixels(response), local.image)
    # The download is named after the first texture.
    assert 'filename="a-synth-72x56-seed4.png"' in response.headers["Content-Disposition"]

    # The layout records both examples and the transforms (version 3, sources).
    job_id = job_id_of(response)
    layout = client.get(f"/jobs/{job_id}/layout").json()
    assert layout["version"] == 3
    assert layout["sources"]["examples"] == [[64, 64], [48, 56]]
    placed = {(p["example"], p["transform"]) for p in layout["sources"]["placements"]}
    assert placed == {(e, t) for e in (0, 1) for t in ("identity", "flip_x", "flip_y", "rot180")}
    # The order of the parts is the order of the examples (and of the weights).
    swapped = _post(client, files[::-1], {**options, "weights": [3, 1]})
    local_swapped = quilting.synthesize(
        [SECOND, FIRST], SIZE, **OPTIONS, **options | {"weights": [3, 1]}
    )
    assert np.array_equal(_pixels(swapped), local_swapped.image)
    assert client.get(f"/jobs/{job_id_of(swapped)}/layout").json()["sources"]["examples"] == [
        [48, 56],
        [64, 64],
    ]


def test_one_texture_is_computed_exactly_as_before(client: httpx.Client) -> None:
    response = _post(client, [_part("texture", FIRST)], {})
    local = quilting.synthesize(FIRST, SIZE, **OPTIONS)
    assert np.array_equal(_pixels(response), local.image)
    status = client.get(f"/jobs/{job_id_of(response)}").json()
    assert status["manifest"] is None
    # One weight for one texture is accepted, and changes nothing.
    weighted = _post(client, [_part("texture", FIRST)], {"weights": [2]})
    assert np.array_equal(_pixels(weighted), local.image)


def test_masks_and_companions_go_one_per_texture(client: httpx.Client) -> None:
    mask_a = np.full(FIRST.shape, 255, dtype=np.uint8)
    mask_a[:, :20] = 0  # the left third of the first example is never used
    mask_b = np.full(SECOND.shape, 255, dtype=np.uint8)
    files = [
        _part("texture", FIRST, "a.png"),
        _part("texture", SECOND, "b.png"),
        # A companion per texture: the textures themselves, so it must come back as the result.
        _part("companion", FIRST, "copy.png"),
        _part("companion", SECOND, "copy.png"),
        _part("source_mask", mask_a),
        _part("source_mask", mask_b),
    ]
    response = _post(client, files, {"blend": "none"})
    assert_png(response, SIZE[1], SIZE[0])
    local = quilting.synthesize(
        [FIRST, SECOND], SIZE, **OPTIONS, blend="none", source_mask=[mask_a, mask_b]
    )
    image = _pixels(response)
    assert np.array_equal(image, local.image)
    job_id = job_id_of(response)
    companion = client.get(f"/jobs/{job_id}/result/copy")
    assert companion.status_code == 200
    assert np.array_equal(quilting.read_image(companion.content), image)
    assert client.get(f"/jobs/{job_id}").json()["companions"] == ["copy"]


def test_weights_must_be_one_per_texture(client: httpx.Client) -> None:
    two = [_part("texture", FIRST), _part("texture", SECOND)]
    for weights in ([1], [1, 2, 3]):
        body = assert_problem(_post(client, two, {"weights": weights}), 422, "invalid_parameter")
        assert body["field"] == "weights" and "2 textures" in body["detail"], body
    one = [_part("texture", FIRST)]
    assert_problem(_post(client, one, {"weights": [1, 1]}), 422, "invalid_parameter", "weights")
    # Each weight a number > 0 (the schema says so too; its errors name the item).
    for weights, field in (([1, 0], "weights.1"), ([1, -2], "weights.1"), ([], "weights")):
        response = _post(client, two, {"weights": weights})
        assert_problem(response, 422, "invalid_parameter", field)
    assert_problem(_post(client, two, {"weights": ["1", 2]}), 422, "invalid_parameter")
    schema = client.get("/openapi.json").json()["components"]["schemas"]["SynthesizeOptions"]
    weights = schema["properties"]["weights"]["anyOf"][0]
    assert weights["items"]["exclusiveMinimum"] == 0 and weights["minItems"] == 1


def test_bad_submissions_of_several_textures_are_problems(client: httpx.Client) -> None:
    two = [_part("texture", FIRST), _part("texture", SECOND)]
    mask = np.full(FIRST.shape, 255, dtype=np.uint8)
    # A source mask for one of two textures.
    response = _post(client, [*two, _part("source_mask", mask)], {})
    assert_problem(response, 422, "invalid_source_mask", "source_mask")
    # A companion sent once for two textures, or three times.
    once = [*two, _part("companion", FIRST, "n.png")]
    assert_problem(_post(client, once, {}), 422, "invalid_companion", "companion")
    thrice = [*two, *[_part("companion", FIRST, "n.png")] * 3]
    assert_problem(_post(client, thrice, {}), 422, "invalid_companion", "companion")
    # A companion of the second texture not of its size.
    wrong = [*two, _part("companion", FIRST, "n.png"), _part("companion", FIRST, "n.png")]
    body = assert_problem(_post(client, wrong, {}), 422, "invalid_companion", "companion")
    assert "texture 1" in body["detail"], body
    # Examples of different kinds: gray and RGB.
    colour = quilting.read_image(texture("hubble"))[:64, :64]
    mixed = [_part("texture", FIRST), _part("texture", colour)]
    body = assert_problem(_post(client, mixed, {}), 422, "invalid_image", "texture")
    assert "texture 1" in body["detail"], body
    # A block larger than the smaller example.
    assert_problem(_post(client, two, {"block": 50}), 422, "invalid_parameter", "block")
    # A texture part that is no image.
    bad = [_part("texture", FIRST), ("texture", ("x.png", b"not an image", "image/png"))]
    assert_problem(_post(client, bad, {}), 415, "unsupported_media_type", "texture")
    # A mask not of its texture's size.
    masks = [_part("source_mask", mask), _part("source_mask", mask)]
    assert_problem(_post(client, [*two, *masks], {}), 422, "invalid_image")
    # Nothing was queued by any of these.
    assert client.get("/readyz").json()["queue_depth"] == 0


def test_at_most_max_textures(client: httpx.Client) -> None:
    files = [_part("texture", FIRST)] * 9
    body = assert_problem(_post(client, files, {}), 422, "too_many_textures", "texture")
    assert "max_textures" in body["detail"], body


def test_other_operations_still_take_one_texture(client: httpx.Client) -> None:
    target = quilting.read_image(texture("hubble"))[:40, :48]
    files = [_part("texture", FIRST), _part("texture", SECOND), _part("target", target)]
    response = client.post("/transfer", files=files, data={"options": '{"block": 12}'})
    assert_problem(response, 422, "duplicate_part", "texture")


def test_several_textures_asynchronously_and_idempotently(client: httpx.Client) -> None:
    files = [_part("texture", FIRST), _part("texture", SECOND)]
    headers = {"Idempotency-Key": "examples-1"}
    first = client.post(
        "/synthesize",
        params={"wait": 0},
        files=files,
        headers=headers,
        data={"options": json.dumps({"width": 72, "height": 56, **OPTIONS})},
    )
    assert first.status_code in (200, 202), first.text
    job_id = job_id_of(first)
    assert wait_for(client, job_id)["status"] == "done"
    again = client.post(
        "/synthesize",
        params={"wait": 30},
        files=files,
        headers=headers,
        data={"options": json.dumps({"width": 72, "height": 56, **OPTIONS})},
    )
    assert job_id_of(again) == job_id
    # The same key with the examples in another order is another request.
    other = client.post(
        "/synthesize",
        params={"wait": 0},
        files=files[::-1],
        headers=headers,
        data={"options": json.dumps({"width": 72, "height": 56, **OPTIONS})},
    )
    assert_problem(other, 409, "idempotency_conflict")
    assert png_image(client.get(f"/jobs/{job_id}/result").content).size == (72, 56)


@pytest.mark.parametrize("transforms", ["rotations", "transpose,flip_x"])
def test_transforms_of_one_texture(client: httpx.Client, transforms: str) -> None:
    response = _post(client, [_part("texture", FIRST)], {"transforms": transforms})
    local = quilting.synthesize(FIRST, SIZE, **OPTIONS, transforms=transforms)
    assert np.array_equal(_pixels(response), local.image)
