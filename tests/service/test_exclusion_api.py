"""Exclusions over HTTP: ``exclude_colors`` in the options and a ``source_mask`` upload on
``POST /synthesize`` and ``/transfer``, the same pixels as the Python API, and the problems."""

from __future__ import annotations

import io
import json

import httpx
import numpy as np
from PIL import Image
from service_helpers import (
    assert_png,
    assert_problem,
    png_image,
    synth_request,
    texture,
    transfer_request,
)

import quilting

HUBBLE_STARS = [[[120, 120, 120], [255, 255, 255]]]


def encode(image: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG")
    return buffer.getvalue()


def _mask() -> np.ndarray:
    mask = np.full((256, 256), 255, dtype=np.uint8)
    mask[40:140, 60:200] = 0
    return mask


def _post(client: httpx.Client, path: str, request: dict, mask: bytes | None) -> httpx.Response:
    if mask is not None:
        request["files"].append(("source_mask", ("mask.png", mask, "image/png")))
    return client.post(path, params={"wait": 30}, **request)


def test_synthesize_with_colours_and_mask_matches_the_python_api(client: httpx.Client) -> None:
    options = {"width": 90, "height": 70, "block": 24, "seed": 4, "exclude_colors": HUBBLE_STARS}
    response = _post(client, "/synthesize", synth_request(options, tex="hubble"), encode(_mask()))
    image = np.asarray(assert_png(response, 90, 70))
    hubble = quilting.read_image(texture("hubble"))
    expected = quilting.synthesize(
        hubble,
        (70, 90),
        block=24,
        seed=4,
        exclude_colors=[tuple(map(tuple, pair)) for pair in HUBBLE_STARS],
        source_mask=_mask(),
    )
    assert np.array_equal(image, expected.image)


def test_transfer_with_a_mask_uses_no_masked_pixel(client: httpx.Client) -> None:
    request = transfer_request({"block": 12, "seed": 1}, tex="gravel", target="hubble")
    response = _post(client, "/transfer", request, encode(_mask()))
    assert response.status_code == 200, response.text[:300]
    job = client.get(f"/jobs/{response.headers['X-Job-Id']}").json()
    layout = quilting.Layout.from_json(client.get(job["layout"]).content)
    traced = quilting.apply_layout(layout, (_mask() == 0).astype(np.uint8))
    assert traced.sum() == 0
    assert png_image(response.content).size == (256, 256)


def test_mask_of_another_size_is_a_problem(client: httpx.Client) -> None:
    response = _post(
        client,
        "/synthesize",
        synth_request({"width": 40, "height": 40}),
        encode(np.zeros((10, 10), np.uint8)),
    )
    body = assert_problem(response, 422, "invalid_image")
    assert "source_mask is 10x10" in body["detail"]


def test_exclusions_leaving_nothing_are_a_problem(client: httpx.Client) -> None:
    everything = [[[0], [255]]]
    response = client.post(
        "/synthesize",
        params={"wait": 30},
        **synth_request({"width": 40, "height": 40, "exclude_colors": everything}),
    )
    body = assert_problem(response, 422, "invalid_parameter")
    assert "every 48x48 block" in body["detail"]


def test_malformed_colour_ranges_are_problems(client: httpx.Client) -> None:
    for ranges in ([[[0, 0, 0]]], [[[9], [1]]], "red", [[[0, 0, 0], [1, 1, 1]]]):
        response = client.post(
            "/synthesize",
            params={"wait": 30},
            **synth_request({"width": 40, "height": 40, "exclude_colors": ranges}),
        )
        assert_problem(response, 422, "invalid_parameter")


def test_mask_that_is_not_an_image_is_415(client: httpx.Client) -> None:
    response = _post(
        client, "/synthesize", synth_request(json.dumps({"width": 40, "height": 40})), b"hello"
    )
    assert_problem(response, 415, "unsupported_media_type", field="source_mask")
