"""``Client.matte``, ``AsyncClient.matte``, ``submit_matte`` and ``quilting-remote matte`` against a
real server.

The reference is a plain ``POST /matte`` made here with httpx, with the same files and options:
matting is deterministic and the service writes no job id or time into the PNG, so the client
must give the same bytes, whichever way it sends the files (paths or bytes) and follows the job.
"""

from __future__ import annotations

import asyncio
import json
import uuid
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from service_helpers import Server, assert_png, job_id_of, lit_sphere, png_bytes, png_image

from quilting_client import (
    AsyncClient,
    Client,
    ConflictError,
    NotFoundError,
    UnsupportedMediaTypeError,
    ValidationError,
)
from quilting_client.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"
SIZE = 64
LAYERS = (DATA / "brick.png", DATA / "cloud_rgba.png")
# Given to both the plain request and the clients; "fft" so that every machine gives the same.
OPTIONS: dict[str, Any] = {
    "clusters": 4,
    "light": [1, 1, 2],
    "block": 16,
    "seed": 3,
    "backend": "fft",
}


# A shaded sphere lit from (1, 1, 2) (gray PNG) and its disc mask (PNG).
TARGET, SILHOUETTE = (png_bytes(image) for image in lit_sphere(SIZE))


@pytest.fixture
def inputs(tmp_path: Path) -> tuple[Path, Path]:
    """The target and the silhouette as files."""
    target, silhouette = tmp_path / "sphere.png", tmp_path / "disc.png"
    target.write_bytes(TARGET)
    silhouette.write_bytes(SILHOUETTE)
    return target, silhouette


def _plain_matte(
    client: httpx.Client, options: dict[str, Any], normals: bytes | None = None
) -> httpx.Response:
    """``POST /matte`` by hand: target, silhouette, the layers bottom first, normals."""
    files = [
        ("target", ("target.png", TARGET, "image/png")),
        ("silhouette", ("silhouette.png", SILHOUETTE, "image/png")),
    ]
    files += [("layer", (path.name, path.read_bytes(), "image/png")) for path in LAYERS]
    if normals is not None:
        files.append(("normals", ("normals.png", normals, "image/png")))
    data = {"options": json.dumps(options)}
    return client.post("/matte", params={"wait": 60}, files=files, data=data)


@pytest.fixture(scope="module")
def plain(server: Server) -> dict[str, bytes]:
    """The result, normals and clusters of a plain ``POST /matte`` with OPTIONS."""
    with server.client() as client:
        response = _plain_matte(client, OPTIONS)
        assert_png(response, SIZE, SIZE)
        job_id = job_id_of(response)
        maps = {
            name: client.get(f"/jobs/{job_id}/result/{name}") for name in ("normals", "clusters")
        }
    return {"image": response.content, **{name: r.content for name, r in maps.items()}}


def _size(png: bytes) -> tuple[int, int]:
    return png_image(png).size


def test_client_matte_is_the_plain_http_result(
    server: Server, inputs: tuple[Path, Path], plain: dict[str, bytes]
) -> None:
    target, silhouette = inputs
    with Client(server.url) as client:
        png = client.matte(
            target, silhouette, LAYERS, companions=("normals", "clusters"), **OPTIONS
        )
        job = client.status(png.job_id or "")
        with pytest.raises(NotFoundError) as caught:
            client.layout(job.id)
    assert bytes(png) == plain["image"]
    # The maps made beside the result: the target's size, the same as the plain job's.
    assert set(png.companions) == {"normals", "clusters"}
    for name in ("normals", "clusters"):
        assert _size(png.companions[name]) == (SIZE, SIZE)
        assert png.companions[name] == plain[name]
    assert (job.operation, job.status, job.layout) == ("matte", "done", None)
    assert job.companions == ("normals", "clusters") and (job.width, job.height) == (SIZE, SIZE)
    assert job.stats is not None
    assert np.allclose(job.stats["light"], np.array([1.0, 1.0, 2.0]) / np.sqrt(6.0))
    assert job.stats["clusters"] >= 1 and job.stats["patches"] >= job.stats["clusters"]
    assert isinstance(job.stats["albedo"], float) and isinstance(job.stats["ambient_fit"], float)
    assert len(job.stats["layer_size"]) == 2
    assert caught.value.code == "no_layout" and caught.value.status == 404


def test_async_client_matte_with_bytes_and_progress(
    server: Server, plain: dict[str, bytes]
) -> None:
    seen: list[float] = []
    layers = [path.read_bytes() for path in LAYERS]

    async def run() -> bytes:
        async with AsyncClient(server.url) as client:
            png = await client.matte(
                TARGET,
                SILHOUETTE,
                layers,
                companions=["clusters"],
                progress=lambda fraction, stage: seen.append(fraction),
                **OPTIONS,
            )
            assert set(png.companions) == {"clusters"}
            assert png.companions["clusters"] == plain["clusters"]
            return png

    assert bytes(asyncio.run(run())) == plain["image"]
    assert seen and seen == sorted(seen) and seen[-1] == 1.0


def test_submit_matte_then_wait(
    server: Server, inputs: tuple[Path, Path], plain: dict[str, bytes]
) -> None:
    target, silhouette = inputs
    with Client(server.url) as client:
        job = client.submit_matte(target, silhouette, LAYERS, **OPTIONS)
        assert (job.operation, job.companions) == ("matte", ("normals", "clusters"))
        done = client.wait(job.id, poll_interval=0.05, timeout=60)
        png = client.result(done.id)
        normals = client.result(done.id, "normals")
        clusters = client.result(done.id, "clusters")
    assert done.status == "done" and done.id == job.id and done.layout is None
    assert png == plain["image"]
    assert _size(normals) == _size(clusters) == (SIZE, SIZE)


def test_async_submit_matte_then_wait_with_events(server: Server, plain: dict[str, bytes]) -> None:
    async def run() -> tuple[str, str, bytes, bytes]:
        async with AsyncClient(server.url) as client:
            job = await client.submit_matte(TARGET, SILHOUETTE, LAYERS, **OPTIONS)
            done = await client.wait(job.id, progress=lambda fraction, stage: None, timeout=60)
            return (
                job.operation,
                done.status,
                await client.result(done.id),
                await client.result(done.id, "normals"),
            )

    operation, status, png, normals = asyncio.run(run())
    assert (operation, status) == ("matte", "done")
    assert png == plain["image"] and normals == plain["normals"]


def test_given_normals_and_light_match_the_plain_request(server: Server) -> None:
    flat = np.zeros((SIZE, SIZE, 3), dtype=np.uint8)
    flat[...] = (128, 128, 255)  # (0, 0, 1) everywhere
    options = {**OPTIONS, "light": [0, 0, 3]}
    with server.client() as http:
        expected = _plain_matte(http, options, normals=png_bytes(flat))
    assert_png(expected, SIZE, SIZE)
    with Client(server.url) as client:
        png = client.matte(TARGET, SILHOUETTE, LAYERS, normals=png_bytes(flat), **options)
        job = client.status(png.job_id or "")
    assert bytes(png) == expected.content
    assert job.stats is not None and np.allclose(job.stats["light"], [0.0, 0.0, 1.0])


def test_the_idempotency_key_binds_the_layers_in_order(server: Server) -> None:
    key = f"matte-live-{uuid.uuid4()}"
    with Client(server.url) as client:
        first = client.submit_matte(TARGET, SILHOUETTE, LAYERS, idempotency_key=key, **OPTIONS)
        again = client.submit_matte(TARGET, SILHOUETTE, LAYERS, idempotency_key=key, **OPTIONS)
        assert again.id == first.id
        # The same files in another order are another request: the key cannot be reused.
        with pytest.raises(ConflictError) as caught:
            client.submit_matte(TARGET, SILHOUETTE, LAYERS[::-1], idempotency_key=key, **OPTIONS)
        client.wait(first.id, timeout=60)
    assert caught.value.code == "idempotency_conflict"


@pytest.mark.parametrize("light", [(1, 1, 0), (1, 1, -2), (1, 1)])
def test_a_bad_light_raises_validation_error(server: Server, light: tuple[int, ...]) -> None:
    with Client(server.url) as client, pytest.raises(ValidationError) as caught:
        client.matte(TARGET, SILHOUETTE, LAYERS, **{**OPTIONS, "light": light})
    error = caught.value
    assert (error.status, error.code, error.field) == (422, "invalid_parameter", "light")


def test_async_bad_light_raises_validation_error(server: Server) -> None:
    async def run() -> None:
        async with AsyncClient(server.url) as client:
            await client.submit_matte(TARGET, SILHOUETTE, LAYERS, light=[0, 1, 0])

    with pytest.raises(ValidationError) as caught:
        asyncio.run(run())
    assert (caught.value.code, caught.value.field) == ("invalid_parameter", "light")


def test_a_wrong_size_silhouette_raises_validation_error(server: Server) -> None:
    small = png_bytes(np.full((SIZE // 2, SIZE), 255, dtype=np.uint8))
    with Client(server.url) as client, pytest.raises(ValidationError) as caught:
        client.matte(TARGET, small, LAYERS, **OPTIONS)
    error = caught.value
    assert (error.status, error.code) == (422, "invalid_image")
    assert "silhouette" in error.detail and f"{SIZE}x{SIZE // 2}" in error.detail


def test_a_target_that_is_no_image_raises_unsupported_media_type(server: Server) -> None:
    with Client(server.url) as client, pytest.raises(UnsupportedMediaTypeError) as caught:
        client.submit_matte(b"not an image", SILHOUETTE, LAYERS)
    assert (caught.value.status, caught.value.code) == (415, "unsupported_media_type")


def test_quilting_remote_matte_writes_the_files(
    server: Server,
    inputs: tuple[Path, Path],
    plain: dict[str, bytes],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    target, silhouette = inputs
    out, normals, clusters = tmp_path / "out.png", tmp_path / "n.png", tmp_path / "c.png"
    argv = ["matte", str(target), "--silhouette", str(silhouette)]
    argv += [arg for path in LAYERS for arg in ("--layer", str(path))]
    argv += ["-o", str(out), "--server", server.url, "--light", "1,1,2", "--clusters", "4"]
    argv += ["--block", "16", "--seed", "3", "--backend", "fft"]
    assert main([*argv, "--normals-out", str(normals), "--clusters-out", str(clusters)]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith(f"wrote {out}, {normals}, {clusters} ({SIZE}x{SIZE}, job ")
    assert captured.err == ""
    assert out.read_bytes() == plain["image"]
    assert normals.read_bytes() == plain["normals"]
    assert clusters.read_bytes() == plain["clusters"]


def test_quilting_remote_matte_refused_exits_2_with_one_line(
    server: Server,
    inputs: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    target, silhouette = inputs
    out = tmp_path / "out.png"
    argv = ["matte", str(target), "--silhouette", str(silhouette)]
    argv += ["--layer", str(LAYERS[0]), "-o", str(out), "--server", server.url]
    assert main([*argv, "--light", "1,1,0"]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("quilting-remote: error: "), captured.err
    assert captured.err.count("\n") == 1 and "invalid_parameter" in captured.err
    assert "light" in captured.err and captured.out == "" and not out.exists()
