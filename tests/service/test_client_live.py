"""The Python client and `quilting remote` against a real server (the unit tests use fakes)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest
from service_helpers import Server

import quilting
from quilting.cli import main
from quilting_client import AsyncClient, Client, ValidationError

DATA = Path(__file__).resolve().parents[1] / "data"


def test_client_synthesize_with_progress_and_companion(server: Server) -> None:
    seen: list[float] = []
    with Client(server.url) as client:
        png = client.synthesize(
            DATA / "hubble.png",
            width=700,
            height=500,
            seed=3,
            companions={"copy": DATA / "hubble.png"},
            progress=lambda fraction, stage: seen.append(fraction),
        )
    image = quilting.read_image(bytes(png))
    assert image.shape == (500, 700, 3)
    # The companion is the texture itself, so it must come back identical to the result.
    assert np.array_equal(quilting.read_image(png.companions["copy"]), image)
    assert seen and seen == sorted(seen) and seen[-1] == 1.0


def test_async_client_and_validation_error(server: Server) -> None:
    async def run() -> bytes:
        async with AsyncClient(server.url) as client:
            return await client.synthesize(DATA / "gravel.png", width=64, height=48, seed=1)

    assert quilting.read_image(asyncio.run(run())).shape == (48, 64)
    with Client(server.url) as client, pytest.raises(ValidationError) as info:
        client.synthesize(DATA / "gravel.png", width=64, height=48, overlap=40)
    assert info.value.code == "invalid_parameter" and info.value.field == "overlap"


def test_quilting_remote_synth(server: Server, tmp_path: Path) -> None:
    out = tmp_path / "out.png"
    argv = ["remote", "synth", str(DATA / "brick.png"), "-o", str(out)]
    assert main([*argv, "--server", server.url, "--size", "300x200", "--seed", "5"]) == 0
    local = quilting.synthesize(quilting.read_image(DATA / "brick.png"), (200, 300), seed=5)
    assert np.array_equal(quilting.read_image(out), local.image)  # same seed, same pixels
