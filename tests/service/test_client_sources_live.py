"""The Python client and ``quilting-remote`` against a real server: a synthesis of several
examples and a Wang tile set, sync and async, give what the Python API gives (the unit tests,
tests/client/test_client_wang.py, use fakes)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import numpy as np
import pytest
from service_helpers import DATA, Server

import quilting
from quilting_client import AsyncClient, Client, ValidationError, WangTilesResult
from quilting_client.cli import main

OPTIONS = {"block": 12, "seed": 2, "backend": "fft"}
WANG = {"colors": 2, "tile": 32, **OPTIONS}


@pytest.fixture(scope="module")
def examples(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two examples of one texture, 64x64 and 48x56 crops of gravel.png, as files."""
    gravel = quilting.read_image(DATA / "gravel.png")
    folder = tmp_path_factory.mktemp("examples")
    paths = [folder / "a.png", folder / "b.png"]
    quilting.write_image(paths[0], gravel[:64, :64])
    quilting.write_image(paths[1], gravel[120:168, 100:156])
    return paths


def _images(paths: list[Path]) -> list[np.ndarray]:
    return [quilting.read_image(path) for path in paths]


def test_client_synthesizes_several_examples(server: Server, examples: list[Path]) -> None:
    with Client(server.url) as client:
        png = client.synthesize(
            examples,
            width=72,
            height=56,
            weights=[1, 2],
            companions={"copy": examples},
            **OPTIONS,
        )
        layout = client.layout(png.job_id or "")
    local = quilting.synthesize(_images(examples), (56, 72), weights=[1, 2], **OPTIONS)
    image = quilting.read_image(bytes(png))
    assert np.array_equal(image, local.image)
    assert np.array_equal(quilting.read_image(png.companions["copy"]), image)
    assert layout["sources"]["examples"] == [[64, 64], [48, 56]]
    with Client(server.url) as client, pytest.raises(ValidationError) as info:
        client.synthesize(examples, width=32, height=32, weights=[1], **OPTIONS)
    assert info.value.code == "invalid_parameter" and info.value.field == "weights"


def test_client_wang_tiles_sync_and_async(server: Server, examples: list[Path]) -> None:
    local = quilting.wang_tiles(_images(examples), **WANG)
    with Client(server.url) as client:
        tiles = client.wang_tiles(examples, **WANG)
        assert client.manifest(tiles.job_id or "") == tiles.manifest
        assert client.status(tiles.job_id or "").manifest == f"/jobs/{tiles.job_id}/manifest"
    assert isinstance(tiles, WangTilesResult)
    assert np.array_equal(quilting.read_image(tiles.atlas), local.atlas())
    assert tiles.manifest == json.loads(local.to_json())

    async def run() -> WangTilesResult:
        async with AsyncClient(server.url) as client:
            seen: list[float] = []
            found = await client.wang_tiles(
                examples[0], progress=lambda f, s: seen.append(f), **{**WANG, "seed": 9}
            )
            assert seen and seen[-1] == 1.0
            return found

    single = asyncio.run(run())
    again = quilting.wang_tiles(_images(examples)[0], **{**WANG, "seed": 9})
    assert np.array_equal(quilting.read_image(single.atlas), again.atlas())
    assert len(single.tiles) == 16


def test_quilting_remote_wang_and_synth(
    server: Server, examples: list[Path], tmp_path: Path
) -> None:
    atlas = tmp_path / "set.png"
    argv = ["wang", *map(str, examples), "-o", str(atlas), "--server", server.url]
    argv += ["--colors", "2", "--tile", "32", "--block", "12", "--seed", "2", "--weights", "2,1"]
    assert main(argv) == 0
    local = quilting.wang_tiles(_images(examples), **WANG, weights=[2, 1])
    assert np.array_equal(quilting.read_image(atlas), local.atlas())
    manifest = json.loads((tmp_path / "set.json").read_text())
    assert len(manifest["tiles"]) == 16 and manifest["tile"] == 32

    out = tmp_path / "out.png"
    argv = ["synth", *map(str, examples), "-o", str(out), "--server", server.url]
    argv += ["--size", "72x56", "--block", "12", "--seed", "2", "--transforms", "flips"]
    assert main(argv) == 0
    local_synth = quilting.synthesize(_images(examples), (56, 72), **OPTIONS, transforms="flips")
    assert np.array_equal(quilting.read_image(out), local_synth.image)
