"""Alpha from an ordinary photo over HTTP: ``POST /extract-alpha``, and ``trimap`` and
``scribbles`` parts beside the photos of ``/synthesize`` and ``/matte``. The result is the
Python API's, its summary comes in the ``Quilting-Extracted`` header (on the job's result
too), and every bad map is refused with its problem before anything is queued."""

from __future__ import annotations

import io
import json
import time
from collections.abc import Callable
from typing import Any

import hostile_inputs as hostile
import httpx
import numpy as np
import pytest
from PIL import Image
from service_helpers import (
    DATA,
    assert_png,
    assert_problem,
    job_id_of,
    lit_sphere,
    png_bytes,
    texture,
    wait_for,
)

import quilting

SIDE = 64
HEADER = "Quilting-Extracted"


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """A photo (a smooth foreground over a smooth background, a known alpha) and its trimap."""
    cloud = Image.open(DATA / "cloud_rgba.png").resize((SIDE, SIDE), Image.Resampling.LANCZOS)
    alpha = np.asarray(cloud, dtype=np.float64)[..., 3] / 255
    yy, xx = np.mgrid[0:SIDE, 0:SIDE] / (SIDE - 1)
    foreground = np.stack([0.9 - 0.3 * yy, 0.75 + 0 * xx, 0.35 + 0.4 * xx], -1)
    background = np.stack([0.1 + 0.2 * xx, 0.15 + 0 * xx, 0.5 - 0.3 * yy], -1)
    photo = alpha[..., None] * foreground + (1 - alpha[..., None]) * background
    trimap = np.full(alpha.shape, 128, np.uint8)
    trimap[alpha > 0.97] = 255
    trimap[alpha < 0.03] = 0
    return np.round(photo * 255).astype(np.uint8), trimap


PHOTO, TRIMAP = _scene()


def _scribbles() -> np.ndarray:
    """Gray (unknown) with a white stroke on the cloud's core and a black one in a corner."""
    strokes = np.full((SIDE, SIDE), 128, np.uint8)
    core = TRIMAP == 255
    strokes[core] = 255
    strokes[:6, :6] = 0
    return strokes


def _part(name: str, data: bytes, filename: str | None = None) -> tuple[str, Any]:
    return (name, (filename or f"{name}.png", data, "image/png"))


def _extract(
    client: httpx.Client,
    *,
    photo: bytes | None = None,
    trimap: bytes | None = None,
    scribbles: bytes | None = None,
    options: dict[str, Any] | str | None = None,
    wait: float = 60,
    headers: dict[str, str] | None = None,
) -> httpx.Response:
    files = [_part("photo", photo if photo is not None else png_bytes(PHOTO), "ice.png")]
    if trimap is not None:
        files.append(_part("trimap", trimap))
    if scribbles is not None:
        files.append(_part("scribbles", scribbles))
    data = {}
    if options is not None:
        data["options"] = options if isinstance(options, str) else json.dumps(options)
    return client.post(
        "/extract-alpha", params={"wait": wait}, files=files, data=data, headers=headers
    )


def _summaries(response: httpx.Response) -> list[dict[str, Any] | None]:
    found = json.loads(response.headers[HEADER])
    assert isinstance(found, list)
    return found


def test_extract_alpha_is_the_python_result(client: httpx.Client) -> None:
    """The RGBA PNG is the Python API's extraction, byte for byte in its pixels; its name says
    what it is; the header and the job's stats carry the summary."""
    response = _extract(client, trimap=png_bytes(TRIMAP))
    image = np.asarray(assert_png(response, SIDE, SIDE))
    expected = quilting.extract_alpha(PHOTO, TRIMAP)
    assert image.shape == (SIDE, SIDE, 4)
    assert np.array_equal(image, expected.image)
    assert f'filename="ice-alpha-{SIDE}x{SIDE}.png"' in response.headers["content-disposition"]
    (summary,) = _summaries(response)
    assert summary is not None
    assert summary["method"] == "lkm" and summary["foreground"] == "ml"
    assert summary["unknown"] == pytest.approx(expected.unknown, abs=1e-4)
    assert summary["iterations"] == expected.iterations
    status = client.get(f"/jobs/{job_id_of(response)}").json()
    assert status["operation"] == "extract_alpha"
    assert status["stats"]["extracted"][0]["iterations"] == expected.iterations


def test_scribbles_and_options_reach_the_solver(client: httpx.Client) -> None:
    """Scribbles alone, another method, the photo's own colour: as the Python API does."""
    strokes = _scribbles()
    options = {"method": "knn", "foreground": "photo"}
    response = _extract(client, scribbles=png_bytes(strokes), options=options)
    image = np.asarray(assert_png(response, SIDE, SIDE))
    expected = quilting.extract_alpha(PHOTO, scribbles=strokes, method="knn", foreground="photo")
    assert np.array_equal(image, expected.image)
    assert np.array_equal(image[..., :3], PHOTO)  # 'photo': the colours as they came
    (summary,) = _summaries(response)
    assert summary is not None and summary["method"] == "knn"


def test_extraction_follows_the_job_contract(client: httpx.Client) -> None:
    """wait=0: 202, then the job's result carries the header too; an Idempotency-Key gives
    the same job again."""
    key = {"Idempotency-Key": "extract-contract-1"}
    first = _extract(client, trimap=png_bytes(TRIMAP), wait=0, headers=key)
    assert first.status_code in (200, 202), first.text
    job_id = job_id_of(first)
    status = wait_for(client, job_id, timeout=60)
    assert status["status"] == "done", status
    result = client.get(f"/jobs/{job_id}/result")
    assert_png(result, SIDE, SIDE)
    assert _summaries(result)[0] is not None
    again = _extract(client, trimap=png_bytes(TRIMAP), wait=0, headers=key)
    assert job_id_of(again) == job_id


def test_synthesize_takes_a_photo_and_its_trimap(client: httpx.Client) -> None:
    """The photo's alpha is extracted first, then alpha-quilted: the Python API's pixels."""
    options = {"width": 96, "height": 80, "block": 24, "seed": 3, "backend": "fft"}
    files = [_part("texture", png_bytes(PHOTO)), _part("trimap", png_bytes(TRIMAP))]
    response = client.post(
        "/synthesize", params={"wait": 60}, files=files, data={"options": json.dumps(options)}
    )
    image = np.asarray(assert_png(response, 96, 80))
    engine = {k: v for k, v in options.items() if k not in ("width", "height")}
    expected = quilting.synthesize(PHOTO, (80, 96), trimap=TRIMAP, **engine)
    assert image.shape[2] == 4
    assert np.array_equal(image, expected.image)
    (summary,) = _summaries(response)
    assert summary is not None and summary["iterations"] == expected.extracted[0].iterations


def test_several_examples_mark_each_photo_or_none(client: httpx.Client) -> None:
    """Two textures, the first a photo with a trimap, the second RGBA with an empty part:
    one summary and a null, in the textures' order."""
    cloud = Image.open(DATA / "cloud_rgba.png").resize((SIDE, SIDE))
    buffer = io.BytesIO()
    cloud.save(buffer, format="PNG")
    options = {"width": 80, "height": 80, "block": 20, "seed": 2, "backend": "fft"}
    files = [
        _part("texture", png_bytes(PHOTO)),
        _part("texture", buffer.getvalue(), "cloud.png"),
        _part("trimap", png_bytes(TRIMAP)),
        ("trimap", ("", b"", "application/octet-stream")),  # an empty field (no file name)
    ]
    response = client.post(
        "/synthesize", params={"wait": 60}, files=files, data={"options": json.dumps(options)}
    )
    assert_png(response, 80, 80)
    first, second = _summaries(response)
    assert first is not None and first["method"] == "lkm"
    assert second is None


def test_matte_takes_a_photo_layer_and_its_trimap(client: httpx.Client) -> None:
    target, silhouette = lit_sphere(64)
    options = {"block": 16, "seed": 5, "clusters": 4, "backend": "fft"}
    files = [
        _part("target", png_bytes(target)),
        _part("silhouette", png_bytes(silhouette)),
        _part("layer", texture("brick"), "brick.png"),
        _part("layer", png_bytes(PHOTO), "smoke.png"),
        ("trimap", ("none.png", b"", "image/png")),  # an empty file: this layer has none
        _part("trimap", png_bytes(TRIMAP)),
    ]
    response = client.post(
        "/matte", params={"wait": 60}, files=files, data={"options": json.dumps(options)}
    )
    image = np.asarray(assert_png(response, 64, 64))
    layers = [quilting.read_image(texture("brick")), PHOTO]
    expected = quilting.matte(
        target, layers, silhouette=silhouette, trimap=[None, TRIMAP], **options
    )
    assert np.array_equal(image, expected.image)
    below, above = _summaries(response)
    assert below is None and above is not None


# --- refusals, before anything is queued -------------------------------------------------


def test_no_trimap_nor_scribbles_is_refused(client: httpx.Client) -> None:
    body = assert_problem(_extract(client), 422, "invalid_trimap", "trimap")
    assert "trimap or scribbles" in body["detail"]


def test_a_trimap_of_another_size_is_refused(client: httpx.Client) -> None:
    small = png_bytes(TRIMAP[: SIDE // 2])
    body = assert_problem(_extract(client, trimap=small), 422, "invalid_trimap", "trimap")
    assert f"{SIDE}x{SIDE // 2}" in body["detail"] and f"{SIDE}x{SIDE}" in body["detail"]


@pytest.mark.parametrize("fill", [0, 128, 255], ids=["all-background", "grey", "all-foreground"])
def test_a_trimap_without_foreground_or_background_is_refused(
    client: httpx.Client, fill: int
) -> None:
    flat = png_bytes(np.full((SIDE, SIDE), fill, np.uint8))
    body = assert_problem(_extract(client, trimap=flat), 422, "invalid_trimap", "trimap")
    assert "foreground" in body["detail"] or "background" in body["detail"]


def test_a_photo_with_alpha_is_refused(client: httpx.Client) -> None:
    rgba = np.dstack([PHOTO, np.full((SIDE, SIDE), 200, np.uint8)])
    response = _extract(client, photo=png_bytes(rgba), trimap=png_bytes(TRIMAP))
    body = assert_problem(response, 422, "invalid_image", "photo")
    assert "alpha" in body["detail"]


def test_bad_parts_and_options_are_refused(client: httpx.Client) -> None:
    assert_problem(
        _extract(client, trimap=b"not an image at all"), 415, "unsupported_media_type", "trimap"
    )
    assert_problem(
        _extract(client, trimap=png_bytes(TRIMAP), options={"method": "poisson"}),
        422,
        "invalid_parameter",
        "method",
    )
    assert_problem(
        _extract(client, trimap=png_bytes(TRIMAP), options={"width": 3}),
        422,
        "invalid_options",
        "width",
    )


def test_marks_per_texture_must_match_the_textures(client: httpx.Client) -> None:
    """Two trimaps for one texture, and a trimap beside a texture that has alpha."""
    options = json.dumps({"width": 64, "height": 64, "block": 16})
    files = [
        _part("texture", png_bytes(PHOTO)),
        _part("trimap", png_bytes(TRIMAP)),
        _part("trimap", png_bytes(TRIMAP)),
    ]
    response = client.post("/synthesize", files=files, data={"options": options})
    assert_problem(response, 422, "invalid_trimap", "trimap")
    files = [_part("texture", texture("cloud_rgba")), _part("trimap", png_bytes(TRIMAP))]
    response = client.post("/synthesize", files=files, data={"options": options})
    assert_problem(response, 422, "invalid_image", "texture")


def test_a_photo_too_large_to_extract_is_refused_at_once(client: httpx.Client) -> None:
    """A flat 3000² photo (a few kB): its extraction is predicted over the job's budget and
    refused from the headers alone, naming the budget."""
    buffer = io.BytesIO()
    Image.new("RGB", (3000, 3000), 90).save(buffer, format="PNG")
    marks = io.BytesIO()
    Image.new("L", (3000, 3000), 128).save(marks, format="PNG")
    response = _extract(
        client, photo=buffer.getvalue(), trimap=marks.getvalue(), options={"method": "knn"}
    )
    body = assert_problem(response, 422, "job_too_large")
    assert "job_memory_bytes" in body["detail"]


@pytest.mark.parametrize(
    ("name", "make", "codes"),
    [
        ("claiming 100000x100000", lambda: hostile.png_claiming(100_000, 100_000), (
            "image_too_large",
        )),
        ("a zlib bomb", hostile.png_zlib_bomb, ("invalid_trimap", "image_too_large")),
        ("truncated", lambda: png_bytes(TRIMAP)[:-40], ("invalid_image", "invalid_trimap")),
    ],
)  # fmt: skip
def test_a_hostile_map_is_refused_at_once(
    client: httpx.Client, name: str, make: Callable[[], bytes], codes: tuple[str, ...]
) -> None:
    """A map built to hurt (a size it does not hold, a bomb, a truncation) beside a small
    photo: a 4xx within a second or two, and the service still answers."""
    started = time.monotonic()
    response = _extract(client, trimap=make())
    assert_problem(response, 422, codes)
    assert time.monotonic() - started < 5, name
    assert client.get("/healthz").status_code == 200


def test_the_schema_documents_the_route_and_its_options(client: httpx.Client) -> None:
    assert client.get("/readyz").json()["matting"] is True  # the CI installs the extra
    schema = client.get("/openapi.json").json()
    assert "/extract-alpha" in schema["paths"]
    options = schema["components"]["schemas"]["AlphaOptions"]["properties"]
    assert set(options["method"]["enum"]) == {"lkm", "cf", "knn"}
    synthesize = schema["components"]["schemas"]["SynthesizeOptions"]["properties"]
    assert synthesize["matting"]["default"] == "lkm"
    for path in ("/extract-alpha", "/synthesize", "/matte"):
        answers = schema["paths"][path]["post"]["responses"]
        assert HEADER in answers["200"]["headers"], path
