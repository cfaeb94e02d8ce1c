"""The Python client and `quilting-remote` against a real server (the unit tests use fakes)."""

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
    argv = ["synth", str(DATA / "brick.png"), "-o", str(out)]
    assert main([*argv, "--server", server.url, "--size", "300x200", "--seed", "5"]) == 0
    local = quilting.synthesize(quilting.read_image(DATA / "brick.png"), (200, 300), seed=5)
    assert np.array_equal(quilting.read_image(out), local.image)  # same seed, same pixels


def _target(tmp_path: Path) -> Path:
    """A 48x40 RGB crop of hubble.png, as a file."""
    path = tmp_path / "target.png"
    quilting.write_image(path, quilting.read_image(DATA / "hubble.png")[100:140, 60:108])
    return path


def test_client_transfer_matches_the_python_api(server: Server, tmp_path: Path) -> None:
    target = _target(tmp_path)
    seen: list[str] = []
    options = {"block": 12, "iterations": 2, "seed": 6, "correspondence": "orientation"}
    with Client(server.url) as client:
        png = client.transfer(
            DATA / "gravel.png",
            target,
            companions={"copy": DATA / "gravel.png"},
            progress=lambda fraction, stage: seen.append(stage),
            **options,
        )
        job = client.status(png.job_id or "")
    image = quilting.read_image(bytes(png))
    local = quilting.transfer(
        quilting.read_image(DATA / "gravel.png"), quilting.read_image(target), **options
    )
    assert image.shape == (40, 48) and np.array_equal(image, local.image)
    # The companion is the texture itself: quilted with the same layout, it is the result.
    assert np.array_equal(quilting.read_image(png.companions["copy"]), image)
    assert job.operation == "transfer" and job.status == "done"
    assert job.stats is not None and isinstance(job.stats["correspondence_error"], float)
    assert seen and seen[-1] in ("done", "encoding")


def test_async_client_submit_transfer_then_wait(server: Server, tmp_path: Path) -> None:
    target = _target(tmp_path).read_bytes()

    async def run() -> tuple[str, bytes, str]:
        async with AsyncClient(server.url) as client:
            job = await client.submit_transfer(DATA / "brick.png", target, block=16, seed=2)
            done = await client.wait(job.id, poll_interval=0.05)
            return job.operation, await client.result(done.id), done.status

    operation, png, status = asyncio.run(run())
    assert (operation, status) == ("transfer", "done")
    assert quilting.read_image(png).shape == (40, 48)
    with Client(server.url) as client, pytest.raises(ValidationError) as info:
        client.transfer(DATA / "gravel.png", target, correspondence="custom")
    assert info.value.code == "invalid_parameter" and info.value.field == "correspondence"


def test_quilting_remote_transfer(server: Server, tmp_path: Path, capsys) -> None:
    target, out = _target(tmp_path), tmp_path / "out.png"
    argv = ["transfer", str(DATA / "wood.png"), str(target), "-o", str(out)]
    options = ["--block", "12", "--seed", "5", "--no-remap", "--alpha", "0.4"]
    assert main([*argv, "--server", server.url, *options]) == 0
    assert "(48x40, job " in capsys.readouterr().out
    local = quilting.transfer(
        quilting.read_image(DATA / "wood.png"),
        quilting.read_image(target),
        block=12,
        seed=5,
        remap=False,
        alpha=0.4,
    )
    assert np.array_equal(quilting.read_image(out), local.image)  # wood is RGB: (40, 48, 3)


def test_quilting_remote_synth_with_companions_error_and_discard(
    server: Server, tmp_path: Path, capsys
) -> None:
    texture = quilting.read_image(DATA / "hubble.png")[:64, :64]
    texture_path, normal_path, small = tmp_path / "t.png", tmp_path / "n.png", tmp_path / "s.png"
    quilting.write_image(texture_path, texture)
    normal = quilting.read_image(DATA / "wood.png")[:64, :64]
    quilting.write_image(normal_path, normal)
    quilting.write_image(small, texture[:40])
    folder = tmp_path / "out"
    folder.mkdir()
    out = folder / "res.png"
    argv = ["synth", str(texture_path), "-o", str(out), "--server", server.url]
    argv += ["--size", "96x80", "--block", "14", "--seed", "9"]
    argv += ["--error", "luminance", "--discard", "0.3"]
    companions = ["--with", f"normal={normal_path}", "--with", f"copy={texture_path}"]
    assert main([*argv, *companions]) == 0
    local = quilting.synthesize(texture, (80, 96), block=14, seed=9, error="luminance", discard=0.3)
    image = quilting.read_image(out)
    assert np.array_equal(image, local.image)  # the options reached the service's engine
    assert np.array_equal(
        quilting.read_image(folder / "res_normal.png"), quilting.apply_layout(local.layout, normal)
    )
    assert np.array_equal(quilting.read_image(folder / "res_copy.png"), image)
    capsys.readouterr()
    # A map of another size than the texture's: the service refuses it, nothing is written.
    bad = tmp_path / "bad.png"
    argv[3] = str(bad)
    assert main([*argv, "--with", f"small={small}"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert "invalid_companion" in err and "64x40" in err and "64x64" in err
    assert not bad.exists() and not (tmp_path / "bad_small.png").exists()


def test_clients_send_companion_kinds(server: Server) -> None:
    """A 'hard' mask through the sync and async clients keeps only the mask's values."""
    from test_companion_kinds import _mask

    mask = _mask()
    gravel = Path(__file__).parents[1] / "data" / "gravel.png"
    with Client(server.url) as client:
        result = client.synthesize(
            str(gravel),
            width=160,
            height=120,
            seed=2,
            companions={"mask": mask},
            companion_kinds={"mask": "hard"},
        )
    assert set(np.unique(quilting.io.read_image(result.companions["mask"])).tolist()) <= {0, 255}

    async def run() -> bytes:
        async with AsyncClient(server.url) as client:
            blended = await client.synthesize(
                str(gravel), width=160, height=120, seed=2, companions={"mask": mask}
            )
            return blended.companions["mask"]

    values = set(np.unique(quilting.io.read_image(asyncio.run(run()))).tolist())
    assert not values <= {0, 255}
