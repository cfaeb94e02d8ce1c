"""Tileable output and walk mode over ``POST /synthesize``, and ``POST /tile``: the same pixels
as the Python API, sizes, bit depth, and every bad input answered with its problem."""

from __future__ import annotations

import dataclasses
import io

import httpx
import numpy as np
import pytest
from PIL import Image
from service_helpers import (
    assert_png,
    assert_problem,
    png_bytes,
    synth,
    synth_request,
    texture,
    tile,
)

import quilting
from quilting.options import TileOptions


def test_tileable_synthesis_matches_the_python_api_and_tiles(client: httpx.Client) -> None:
    options = {"width": 100, "height": 90, "block": 24, "seed": 3, "tileable": "both"}
    response = client.post("/synthesize", params={"wait": 30}, **synth_request(options))
    image = np.asarray(assert_png(response, 100, 90))
    gravel = quilting.read_image(texture("gravel"))
    expected = quilting.synthesize(gravel, (90, 100), block=24, seed=3, tileable="both")
    assert np.array_equal(image, expected.image)
    job = client.get(f"/jobs/{response.headers['X-Job-Id']}").json()
    layout = quilting.Layout.from_json(client.get(job["layout"]).content)
    assert layout.passes[0].grid.period == (90, 100)


def test_walk_mode_matches_the_python_api(client: httpx.Client) -> None:
    options = {"width": 80, "height": 70, "block": 20, "seed": 5, "mode": "walk", "feather": 2}
    response = client.post("/synthesize", params={"wait": 30}, **synth_request(options))
    image = np.asarray(assert_png(response, 80, 70))
    gravel = quilting.read_image(texture("gravel"))
    expected = quilting.synthesize(gravel, (70, 80), block=20, seed=5, mode="walk", feather=2)
    assert np.array_equal(image, expected.image)
    job = client.get(f"/jobs/{response.headers['X-Job-Id']}").json()
    assert job["backend"] == "none"


@pytest.mark.parametrize(
    ("options", "field"),
    [
        ({"width": 30, "height": 90, "block": 40, "tileable": "x"}, "size"),
        ({"width": 90, "height": 90, "mode": "walk", "tileable": "both"}, "tileable"),
        ({"width": 90, "height": 90, "tileable": "diagonal"}, "tileable"),
        ({"width": 90, "height": 90, "mode": "walk", "max_run": 0}, "max_run"),
        ({"width": 90, "height": 90, "feather": -1}, "feather"),
    ],
)
def test_bad_variant_options_are_422(client: httpx.Client, options: dict, field: str) -> None:
    response = client.post("/synthesize", params={"wait": 30}, **synth_request(options))
    body = assert_problem(response, 422, "invalid_parameter")
    assert field in body["detail"], body


def test_tile_matches_the_python_api_and_keeps_the_size(client: httpx.Client) -> None:
    response = tile(client, texture("brick"), {"axes": "both", "band": 20})
    image = np.asarray(assert_png(response, 256, 256))
    brick = quilting.read_image(texture("brick"))
    expected = quilting.make_tileable(brick, axes="both", band=20)
    assert np.array_equal(image, expected.image)
    # The default band keeps the middle half as it was: bit for bit unblended; blended (the
    # default) up to the blend's gentle correction, a few levels that change by at most a
    # level or two from pixel to pixel.
    plain = {"blend": "none"}
    exact = np.asarray(assert_png(tile(client, texture("brick"), plain), 256, 256))
    assert np.array_equal(exact[64:192, 64:192], brick[64:192, 64:192])
    assert not np.array_equal(exact, brick)
    default = np.asarray(assert_png(tile(client, texture("brick")), 256, 256)).astype(int)
    shift = default[64:192, 64:192] - brick[64:192, 64:192]
    assert np.abs(shift).max() <= 16 and np.abs(np.diff(shift, axis=1)).max() <= 2


def test_tile_keeps_16_bit_and_gray(client: httpx.Client) -> None:
    rng = np.random.default_rng(0)
    deep = (rng.random((40, 60)) * 65535).astype(np.uint16)
    response = tile(client, png_bytes(deep), {"axes": "x"})
    assert response.status_code == 200, response.text[:300]
    decoded = quilting.read_image(response.content)
    assert decoded.dtype == np.uint16 and decoded.shape == (40, 60)
    assert np.array_equal(decoded, quilting.make_tileable(deep, axes="x").image)


def test_tile_blend_matches_the_python_api(client: httpx.Client) -> None:
    response = tile(client, texture("brick"), {"axes": "x", "blend": "poisson"})
    image = np.asarray(assert_png(response, 256, 256))
    brick = quilting.read_image(texture("brick"))
    expected = quilting.make_tileable(brick, axes="x", blend="poisson")
    assert np.array_equal(image, expected.image)
    assert not np.array_equal(image, quilting.make_tileable(brick, axes="x", blend="none").image)
    none = np.asarray(assert_png(tile(client, texture("brick"), {"blend": "none"}), 256, 256))
    assert np.array_equal(none, quilting.make_tileable(brick, blend="none").image)


@pytest.mark.parametrize(
    ("options", "code"),
    [
        ({"axes": "z"}, "invalid_parameter"),
        ({"blend": "feather"}, "invalid_parameter"),
        ({"blend": 1}, "invalid_parameter"),
        ({"band": 0}, "invalid_parameter"),
        ({"band": 500}, "invalid_parameter"),
        ({"bands": 3}, "invalid_options"),
        ("[1, 2]", "invalid_options"),
        ("not json", "invalid_options"),
    ],
)
def test_tile_bad_options(client: httpx.Client, options: dict | str, code: str) -> None:
    assert_problem(tile(client, texture("brick"), options), 422, code)


def test_tile_bad_images(client: httpx.Client) -> None:
    assert_problem(tile(client, b"GIF89a" + b"\0" * 64), 415, "unsupported_media_type")
    tiny = png_bytes(np.zeros((3, 3), dtype=np.uint8))
    body = assert_problem(tile(client, tiny), 422, ("invalid_image", "invalid_parameter"))
    assert "too small" in body["detail"]
    response = client.post("/tile", data={"options": "{}"})
    assert response.status_code == 422


def test_tile_refuses_an_image_over_the_pixel_limit(start_server) -> None:
    server = start_server("tile-limits", {"QUILTING_MAX_INPUT_PIXELS": "1000"})
    with server.client() as client:
        body = assert_problem(tile(client, texture("brick")), 422, "image_too_large")
        assert "max_input_pixels" in body["detail"]


def test_tile_schema_is_published(client: httpx.Client) -> None:
    schema = client.get("/openapi.json").json()
    tile = schema["components"]["schemas"]["TileOptions"]
    # Every field of TileOptions, from the one place it is declared (method and seed too).
    assert set(tile["properties"]) == {f.name for f in dataclasses.fields(TileOptions)}
    assert {"axes", "band", "blend", "method", "seed"} <= set(tile["properties"])
    assert tile["properties"]["method"]["default"] == "cut"
    assert tile["properties"]["blend"]["default"] == "poisson"
    assert "/tile" in schema["paths"]
    synth = schema["components"]["schemas"]["SynthesizeOptions"]["properties"]
    assert {"tileable", "max_run", "feather"} <= set(synth)
    transfer = schema["components"]["schemas"]["TransferOptions"]["properties"]
    assert "tileable" not in transfer


def test_alpha_quilting_over_http_is_the_python_result(client: httpx.Client) -> None:
    """RGBA through /synthesize: 'auto' is alpha mode, the same bytes as the Python API;
    alpha mode on an RGB texture is refused at submission, naming mode."""
    options = {"width": 120, "height": 100, "block": 32, "seed": 6, "backend": "fft"}
    response = synth(client, options, tex="cloud_rgba")
    image = np.asarray(assert_png(response, 120, 100))
    cloud = np.asarray(Image.open(io.BytesIO(texture("cloud_rgba"))))
    expected = quilting.synthesize(cloud, (100, 120), block=32, seed=6, backend="fft")
    assert expected.layout.meta["mode"] == "alpha"
    assert np.array_equal(image, expected.image)
    refused = synth(client, {**options, "mode": "alpha"}, tex="gravel")
    assert_problem(refused, 422, "invalid_parameter", "mode")
