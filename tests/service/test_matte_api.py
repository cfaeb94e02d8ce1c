"""Texture matting over ``POST /matte``: the same pixels as the Python API, the normals and
patches beside the result, the job contract, and every bad input answered with its problem."""

from __future__ import annotations

import json
from collections.abc import Callable

import httpx
import numpy as np
import pytest
from service_helpers import (
    Server,
    assert_png,
    assert_problem,
    assert_status_document,
    job_id_of,
    lit_sphere,
    png_bytes,
    png_image,
    texture,
    wait_for,
)

import quilting

SIZE = 96


TARGET, SILHOUETTE = lit_sphere(SIZE)


def _files(
    layers: tuple[str, ...] = ("brick", "cloud_rgba"),
    target: bytes | None = None,
    silhouette: bytes | None = None,
    normals: bytes | None = None,
) -> list[tuple[str, tuple[str, bytes, str]]]:
    files = [
        ("target", ("target.png", target or png_bytes(TARGET), "image/png")),
        ("silhouette", ("mask.png", silhouette or png_bytes(SILHOUETTE), "image/png")),
    ]
    files += [("layer", (f"{name}.png", texture(name), "image/png")) for name in layers]
    if normals is not None:
        files.append(("normals", ("normals.png", normals, "image/png")))
    return files


def _matte(
    client: httpx.Client,
    options: dict | str | None = None,
    wait: float = 60,
    **files: object,
) -> httpx.Response:
    data = {}
    if options is not None:
        data["options"] = options if isinstance(options, str) else json.dumps(options)
    return client.post("/matte", params={"wait": wait}, files=_files(**files), data=data)


OPTIONS = {"block": 32, "seed": 5, "clusters": 6, "backend": "fft"}


def _expected(**extra: object) -> quilting.MatteResult:
    layers = [quilting.read_image(texture(name)) for name in ("brick", "cloud_rgba")]
    return quilting.matte(TARGET, layers, silhouette=SILHOUETTE, **{**OPTIONS, **extra})


def test_matte_over_http_is_the_python_result(client: httpx.Client) -> None:
    """Two layers: the PNG equals the Python API's image; normals and clusters come beside it;
    the status document says what was done."""
    response = _matte(client, OPTIONS)
    image = np.asarray(assert_png(response, SIZE, SIZE))
    expected = _expected()
    assert np.array_equal(image, expected.image)
    job_id = job_id_of(response)
    status = client.get(f"/jobs/{job_id}").json()
    assert_status_document(status)
    assert status["operation"] == "matte"
    assert status["companions"] == ["normals", "clusters"]
    assert status["layout"] is None
    assert np.allclose(status["stats"]["light"], expected.light)
    assert status["stats"]["clusters"] == int(expected.clusters.max()) + 1
    assert status["stats"]["patches"] == int(expected.patches.max()) + 1
    assert set(status["timings"]) >= {"layers", "surface", "lay", "total"}
    normals = client.get(f"/jobs/{job_id}/result/normals")
    assert np.array_equal(np.asarray(assert_png(normals, SIZE, SIZE)), expected.normal_map())
    clusters = client.get(f"/jobs/{job_id}/result/clusters")
    assert np.array_equal(np.asarray(assert_png(clusters, SIZE, SIZE)), expected.patch_map())
    assert_problem(client.get(f"/jobs/{job_id}/layout"), 404, "no_layout")
    assert_problem(client.get(f"/jobs/{job_id}/seams"), 404, "no_layout")
    meta = json.loads(png_image(response.content).info["quilting"])
    assert meta["operation"] == "matte"
    assert np.allclose(meta["light_used"], expected.light)


def test_given_light_and_normal_map_are_used(client: httpx.Client) -> None:
    """A light in the options and a normal-map part replace the estimates: the same image as
    the Python API given the same; the job reports the given light, normalized."""
    flat = np.zeros((SIZE, SIZE, 3), dtype=np.uint8)
    flat[...] = (128, 128, 255)  # (0, 0, 1) everywhere
    options = {**OPTIONS, "light": [0, 0, 3]}
    response = _matte(client, options, normals=png_bytes(flat))
    image = np.asarray(assert_png(response, SIZE, SIZE))
    expected = _expected(light=(0.0, 0.0, 3.0), normals=flat)
    assert np.array_equal(image, expected.image)
    status = client.get(f"/jobs/{job_id_of(response)}").json()
    assert np.allclose(status["stats"]["light"], [0.0, 0.0, 1.0])


def test_matte_job_follows_the_job_contract(client: httpx.Client) -> None:
    """wait=0 gives 202 and a job that finishes; the events stream ends with done."""
    response = _matte(client, OPTIONS, wait=0)
    assert response.status_code in (200, 202), response.text
    job_id = job_id_of(response)
    status = wait_for(client, job_id, timeout=60)
    assert status["status"] == "done", status
    assert status["result"] == f"/jobs/{job_id}/result"
    assert_png(client.get(f"/jobs/{job_id}/result"), SIZE, SIZE)
    with client.stream("GET", f"/jobs/{job_id}/events") as events:
        text = "".join(events.iter_text())
    assert "done" in text


def test_matte_options_are_in_the_schema(client: httpx.Client) -> None:
    schema = client.get("/openapi.json").json()
    options = schema["components"]["schemas"]["MatteOptions"]["properties"]
    for name in ("clusters", "light", "smoothing", "min_z", "scale", "ambient", "mode", "block"):
        assert name in options, name
    assert "walk" not in options["mode"]["enum"]
    assert "/matte" in schema["paths"]


@pytest.mark.parametrize(
    ("options", "code", "field"),
    [
        ({"light": [1, 1, 0]}, "invalid_parameter", "light"),
        ({"light": [1, 1]}, "invalid_parameter", "light"),
        ({"clusters": 0}, "invalid_parameter", "clusters"),
        ({"mode": "walk"}, "invalid_parameter", "mode"),
        ({"mode": "alpha"}, "invalid_parameter", "mode"),  # brick has no alpha
        ({"block": 500}, "invalid_parameter", "block"),
        ({"scale": 0.1}, "invalid_parameter", "scale"),
        ({"tileable": "both"}, "invalid_options", "tileable"),
        ("[1]", "invalid_options", "options"),
    ],
)
def test_bad_options_are_refused(
    client: httpx.Client, options: dict | str, code: str, field: str
) -> None:
    assert_problem(_matte(client, options), 422, code, field)


def test_bad_images_are_refused(client: httpx.Client) -> None:
    """Wrong sizes, an empty silhouette, a missing part, a non-image: each named."""
    small = png_bytes(np.zeros((SIZE // 2, SIZE), dtype=np.uint8) + 255)
    body = assert_problem(
        _matte(client, OPTIONS, silhouette=small), 422, "invalid_image", "silhouette"
    )
    assert "silhouette" in body["detail"] and "target's size" in body["detail"]
    body = assert_problem(_matte(client, OPTIONS, normals=small), 422, "invalid_image", "normals")
    assert "normals" in body["detail"]
    black = png_bytes(np.zeros((SIZE, SIZE), dtype=np.uint8))
    body = assert_problem(
        _matte(client, OPTIONS, silhouette=black), 422, "invalid_image", "silhouette"
    )
    assert "silhouette" in body["detail"]
    missing = client.post(
        "/matte", files=[f for f in _files() if f[0] != "layer"], data={"options": "{}"}
    )
    assert_problem(missing, 422, "missing_field", "layer")
    text = _files()
    text[0] = ("target", ("target.txt", b"not an image", "text/plain"))
    assert_problem(client.post("/matte", files=text), 415, "unsupported_media_type", "target")


def test_layer_count_and_size_limits(start_server: Callable[[str, dict[str, str]], Server]) -> None:
    """More layers than max_layers, or layers that would be quilted beyond max_output_pixels."""
    server = start_server(
        "matte-limits", {"QUILTING_MAX_LAYERS": "1", "QUILTING_MAX_OUTPUT_PIXELS": "12000"}
    )
    with server.client() as client:
        assert_problem(_matte(client, OPTIONS), 422, "too_many_layers", "layer")
        # The sphere's extent is 77 px: at scale 0.5 each layer would be 154 x 154.
        refused = _matte(client, {**OPTIONS, "scale": 0.5}, layers=("brick",))
        body = assert_problem(refused, 422, "invalid_parameter", "scale")
        assert "max_output_pixels" in body["detail"]
        assert_png(_matte(client, OPTIONS, layers=("brick",)), SIZE, SIZE)
