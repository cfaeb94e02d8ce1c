"""The golden matrix: sha256 of the output bytes of a fixed set of jobs (issue 21, part 3).

Every mode, the torus, transfer with three passes, alpha quilting, the walk, make_tileable,
gray / RGB / RGBA and 8 / 16-bit inputs, two seeds. A refactor of the engine (compiled
kernels, a leaner FFT) must keep every hash; a change that means to alter outputs records
them again, in its own commit, and says why::

    .venv/bin/python tests/golden_cases.py --record

``tests/test_golden.py`` checks them. The jobs are small (64-96 px crops to 96-128 px
outputs) so the whole matrix runs in a few seconds.
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

DATA = Path(__file__).resolve().parent / "data"
GOLDEN = DATA / "golden.json"
#: One entry of the matrix: computes its output array.
Job = Callable[[], np.ndarray]


def _load(name: str) -> np.ndarray:
    return np.asarray(Image.open(DATA / name))


def _crop(image: np.ndarray, side: int) -> np.ndarray:
    return np.ascontiguousarray(image[:side, :side])


def _sixteen(image: np.ndarray) -> np.ndarray:
    # Not a plain x257: the low byte varies, so 16-bit precision is really exercised.
    wide = image.astype(np.uint16) * 257
    return wide ^ (np.arange(wide.size, dtype=np.uint16).reshape(wide.shape) % 7)


def _digest(array: np.ndarray) -> str:
    data = np.ascontiguousarray(array)
    head = f"{data.dtype.str}{data.shape}".encode()
    return hashlib.sha256(head + data.tobytes()).hexdigest()


def cases() -> dict[str, Job]:
    """Name -> job returning the output array, for every entry of the matrix."""
    import quilting

    gravel = _crop(_load("gravel.png"), 96)  # gray
    hubble = _crop(_load("hubble.png"), 96)  # RGB
    cloud = _crop(_load("cloud_rgba.png"), 96)
    camera = _crop(_load("target_camera.png"), 96)
    wood = _crop(_load("wood.png"), 96)
    textures = {
        "rgb8": hubble,
        "gray8": gravel,
        "rgb16": _sixteen(hubble),
        "gray16": _sixteen(gravel),
    }
    jobs: dict[str, Job] = {}
    examples = [hubble[:64, :64], hubble[40:96, 30:90]]

    def synth(texture: Any, size: tuple[int, int], **options: Any) -> Job:
        """A synthesis job of the matrix: 24 px blocks on the fft backend."""
        return lambda: quilting.synthesize(texture, size, block=24, backend="fft", **options).image

    def transfer(texture: np.ndarray, **options: Any) -> Job:
        """A transfer job of the matrix onto the camera crop, on the fft backend."""
        return lambda: quilting.transfer(texture, camera, backend="fft", **options).image

    for seed in (0, 7):
        for label, texture in textures.items():
            for mode in ("cut", "overlap", "random"):
                jobs[f"{mode}-{label}-s{seed}"] = synth(texture, (128, 112), mode=mode, seed=seed)
        jobs[f"cut-none-rgb8-s{seed}"] = synth(hubble, (128, 112), blend="none", seed=seed)
        jobs[f"walk-rgb8-s{seed}"] = synth(hubble, (128, 112), mode="walk", seed=seed)
        jobs[f"tileable-rgb8-s{seed}"] = synth(hubble, (120, 120), tileable="both", seed=seed)
        jobs[f"tileable-x-gray16-s{seed}"] = synth(
            textures["gray16"], (120, 100), tileable="x", seed=seed
        )
        jobs[f"alpha-rgba8-s{seed}"] = synth(cloud, (128, 112), seed=seed)
        # Made when the job runs, as before: the matrix's inputs are built lazily.
        jobs[f"alpha-rgba16-s{seed}"] = lambda s=seed: synth(_sixteen(cloud), (112, 112), seed=s)()
        jobs[f"transfer3-rgb8-s{seed}"] = transfer(
            wood, block=18, iterations=3, min_block=8, seed=seed
        )
        jobs[f"transfer-discard-gray8-s{seed}"] = transfer(gravel, block=16, discard=0.3, seed=seed)
        # Several examples, turned and mirrored (issue 25), and a Wang set cut from them.
        jobs[f"sources-all-rgb8-s{seed}"] = synth(
            examples, (112, 104), transforms="all", weights=[2, 1], seed=seed
        )
        jobs[f"sources-walk-gray8-s{seed}"] = synth(
            [gravel[:60, :60], gravel[30:96, 20:80]], (96, 96), mode="walk", transforms="flips",
            seed=seed,
        )  # fmt: skip
        jobs[f"wang-rgb8-s{seed}"] = lambda s=seed: quilting.wang_tiles(
            examples, tile=32, block=16, transforms="rotations", backend="fft", seed=s
        ).atlas()
    jobs["make-tileable-rgb8"] = lambda: quilting.make_tileable(hubble).image
    jobs["make-tileable-x-gray16"] = lambda: (
        quilting.make_tileable(textures["gray16"], axes="x").image
    )
    return jobs


def digests() -> dict[str, str]:
    """Every case's sha256, computed now."""
    return {name: _digest(job()) for name, job in cases().items()}


def main(argv: list[str]) -> int:
    if argv != ["--record"]:
        print(__doc__)
        return 2
    GOLDEN.write_text(json.dumps(digests(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
