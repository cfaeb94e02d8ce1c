"""``Client.extract_alpha``, ``AsyncClient.extract_alpha``, the ``trimap`` of
``Client.synthesize`` and ``quilting-remote extract-alpha`` against a real server.

The reference is the Python API's extraction of the same photo and trimap: matting is
deterministic and the service writes no job id or time into the PNG's pixels, so the clients
must give the same pixels, whichever way they send the files and follow the job.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest
from service_helpers import Server, png_bytes, png_image

import quilting
from quilting_client import AsyncClient, Client, ValidationError
from quilting_client.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"
SIDE = 48


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """The cloud (a known alpha) over a gradient, as a photo without alpha, and its trimap."""
    cloud = np.asarray(
        png_image((DATA / "cloud_rgba.png").read_bytes()).resize((SIDE, SIDE)), dtype=np.float64
    )
    alpha = cloud[..., 3:] / 255
    yy = np.linspace(0, 1, SIDE)[:, None, None]
    background = np.concatenate([0.2 + 0 * yy, 0.3 + 0.4 * yy, 0.6 - 0.3 * yy], axis=2)
    photo = alpha * cloud[..., :3] / 255 + (1 - alpha) * background
    trimap = np.full((SIDE, SIDE), 128, np.uint8)
    trimap[alpha[..., 0] > 0.97] = 255
    trimap[alpha[..., 0] < 0.03] = 0
    return np.round(photo * 255).astype(np.uint8), trimap


PHOTO, TRIMAP = _scene()
EXPECTED = quilting.extract_alpha(PHOTO, TRIMAP)


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    photo, trimap = tmp_path / "smoke.png", tmp_path / "smoke_trimap.png"
    photo.write_bytes(png_bytes(PHOTO))
    trimap.write_bytes(png_bytes(TRIMAP))
    return photo, trimap


def test_client_extract_alpha_is_the_python_result(
    server: Server, files: tuple[Path, Path]
) -> None:
    photo, trimap = files
    with Client(server.url) as client:
        png = client.extract_alpha(photo, trimap)
        job = client.status(png.job_id or "")
    assert np.array_equal(np.asarray(png_image(png)), EXPECTED.image)
    (summary,) = png.extracted
    assert summary is not None and summary["iterations"] == EXPECTED.iterations
    assert job.operation == "extract_alpha" and job.stats is not None
    assert job.stats["extracted"][0]["method"] == "lkm"


def test_async_client_follows_an_extraction_with_progress(server: Server) -> None:
    seen: list[float] = []

    async def run() -> bytes:
        async with AsyncClient(server.url) as client:
            png = await client.extract_alpha(
                png_bytes(PHOTO),
                png_bytes(TRIMAP),
                progress=lambda fraction, stage: seen.append(fraction),
            )
            assert png.extracted and png.extracted[0] is not None
            return png

    image = np.asarray(png_image(asyncio.run(run())))
    assert np.array_equal(image, EXPECTED.image)
    assert seen and seen == sorted(seen) and seen[-1] == 1.0


def test_client_synthesize_takes_a_photo_and_its_trimap(server: Server) -> None:
    options = {"block": 16, "seed": 4, "backend": "fft"}
    with Client(server.url) as client:
        png = client.synthesize(
            png_bytes(PHOTO), width=64, height=56, trimap=png_bytes(TRIMAP), **options
        )
    expected = quilting.synthesize(PHOTO, (56, 64), trimap=TRIMAP, **options)
    assert np.array_equal(np.asarray(png_image(png)), expected.image)
    assert len(png.extracted) == 1 and png.extracted[0] is not None


def test_the_service_s_refusal_is_a_validation_error(server: Server) -> None:
    with Client(server.url) as client, pytest.raises(ValidationError) as caught:
        client.extract_alpha(png_bytes(PHOTO), png_bytes(TRIMAP[:, : SIDE // 2]))
    assert caught.value.code == "invalid_trimap" and caught.value.field == "trimap"
    assert caught.value.status == 422


def test_remote_extract_alpha_writes_the_texture(
    server: Server,
    files: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    photo, trimap = files
    out = tmp_path / "smoke_rgba.png"
    argv = ["extract-alpha", str(photo), "--trimap", str(trimap), "-o", str(out)]
    assert main([*argv, "--server", server.url]) == 0, capsys.readouterr().err
    assert np.array_equal(np.asarray(png_image(out.read_bytes())), EXPECTED.image)
    said = capsys.readouterr().out
    assert f"{SIDE}x{SIDE}" in said and "alpha extracted (lkm" in said
