"""``Client.tile``, ``AsyncClient.tile`` and ``quilting-remote tile`` against a real server.

The results are compared with :func:`quilting.make_tileable` run here: tiling is deterministic,
so the service must give the same pixels, at the image's size and bit depth. The tests import
the engine; the client package itself never does.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest
from service_helpers import Server

import quilting
from quilting_client import AsyncClient, Client, ValidationError
from quilting_client.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.mark.parametrize("name", ["brick", "hubble"])
def test_tile_returns_what_make_tileable_gives(server: Server, name: str) -> None:
    path = DATA / f"{name}.png"
    with Client(server.url) as client:
        png = client.tile(path)
    image = quilting.read_image(png)
    local = quilting.make_tileable(quilting.read_image(path)).image
    assert image.shape == local.shape == quilting.read_image(path).shape
    assert image.dtype == local.dtype and np.array_equal(image, local)


def test_async_tile_keeps_options_and_bit_depth(server: Server, tmp_path: Path) -> None:
    # A 16-bit crop, sent as bytes: the answer is 16-bit too.
    wide = quilting.read_image(DATA / "wood.png")[:40, :56].astype(np.uint16) * 257
    path = tmp_path / "wood16.png"
    quilting.write_image(path, wide)

    async def run() -> bytes:
        async with AsyncClient(server.url) as client:
            return await client.tile(path.read_bytes(), axes="x", band=9, timeout=30)

    image = quilting.read_image(asyncio.run(run()))
    local = quilting.make_tileable(quilting.read_image(path), axes="x", band=9).image
    assert image.shape == (40, 56, 3) and image.dtype == np.uint16
    assert np.array_equal(image, local)


@pytest.mark.parametrize("band", [0, 1000])
def test_a_bad_band_raises_validation_error(server: Server, band: int) -> None:
    # 0 fails the schema, 1000 the engine's check against the image's sides: both are 422s.
    with Client(server.url) as client, pytest.raises(ValidationError) as caught:
        client.tile(DATA / "wood.png", band=band)
    error = caught.value
    assert (error.status, error.code, error.field) == (422, "invalid_parameter", "band")


def test_blend_travels_and_a_bad_one_raises_validation_error(server: Server) -> None:
    with Client(server.url) as client:
        png = client.tile(DATA / "wood.png", axes="x", blend="poisson")
        with pytest.raises(ValidationError) as caught:
            client.tile(DATA / "wood.png", blend="feather")
    local = quilting.make_tileable(
        quilting.read_image(DATA / "wood.png"), axes="x", blend="poisson"
    )
    assert np.array_equal(quilting.read_image(png), local.image)
    assert (caught.value.code, caught.value.field) == ("invalid_parameter", "blend")


def test_a_bad_axes_raises_validation_error(server: Server) -> None:
    with Client(server.url) as client, pytest.raises(ValidationError) as caught:
        client.tile(DATA / "wood.png", axes="diagonal")
    assert (caught.value.code, caught.value.field) == ("invalid_parameter", "axes")


def test_quilting_remote_tile_writes_the_file(
    server: Server, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.png"
    argv = ["tile", str(DATA / "wood.png"), "-o", str(out), "--server", server.url]
    assert main([*argv, "--axes", "y", "--band", "20"]) == 0
    captured = capsys.readouterr()
    assert captured.out == f"wrote {out} (136x136, tileable along y)\n" and captured.err == ""
    local = quilting.make_tileable(quilting.read_image(DATA / "wood.png"), axes="y", band=20)
    assert np.array_equal(quilting.read_image(out), local.image)


@pytest.mark.parametrize(
    ("option", "fragment"),
    [
        (["--band", "1000"], "band=1000 is not allowed"),
        (["--axes", "z"], "--axes 'z'"),
        (["--blend", "feather"], "--blend 'feather'"),
    ],
)
def test_quilting_remote_tile_bad_option_exits_2_with_one_line(
    server: Server,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    option: list[str],
    fragment: str,
) -> None:
    out = tmp_path / "out.png"
    argv = ["tile", str(DATA / "wood.png"), "-o", str(out), "--server", server.url]
    assert main([*argv, *option]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("quilting-remote: error: "), captured.err
    assert captured.err.count("\n") == 1 and fragment in captured.err
    assert captured.out == "" and not out.exists()
