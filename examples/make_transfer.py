"""Regenerate the images of docs/transfer.md: ``examples/camera_gravel_*.png``, ``cat_wood_3.png``.

Gravel onto the 256² cameraman (the README's example) before issue 20 part 3 (one pass,
per-pixel luminance, no shading), with today's two passes unshaded (``shade=1``), with the
defaults, and with three passes; wood onto the cat in three passes. Seed 0, the ``fft``
backend (every backend gives the same bytes anyway). Run from the repository root::

    .venv/bin/python examples/make_transfer.py

It prints, for each image, the two figures of the docs table: the likeness (Pearson r of the
output's and the target's luminance, each Gaussian-blurred with sigma 2) and the hf gap
(texeval's ``hf_excess`` of the output against the texture minus that of a plain synthesis
from the same texture at the target's size, same block and seed; 0: as crisp as a
synthesis), both as ``benchmarks/bench_quality.py --transfer`` computes them, and the engine
time.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "benchmarks"))

from bench_quality import likeness, load_texeval, texeval_figures  # noqa: E402

import quilting  # noqa: E402

BACKEND = "fft"
SEED = 0
#: File name -> (texture, target, options of quilting.transfer).
IMAGES: dict[str, tuple[str, str, dict[str, Any]]] = {
    "camera_gravel_1.png": (
        "gravel",
        "camera",
        {"iterations": 1, "correspondence": "luminance", "shade": 1},
    ),
    "camera_gravel_2_unshaded.png": ("gravel", "camera", {"shade": 1}),
    "camera_gravel_2.png": ("gravel", "camera", {}),
    "camera_gravel_3.png": ("gravel", "camera", {"iterations": 3}),
    "cat_wood_3.png": ("wood", "cat", {"iterations": 3}),
}


def main() -> None:
    texeval = load_texeval()
    for name, (texture_name, target_name, options) in IMAGES.items():
        texture = quilting.read_image(HERE / f"{texture_name}.png")
        target = quilting.read_image(HERE / f"{target_name}.png")
        result = quilting.transfer(texture, target, seed=SEED, backend=BACKEND, **options)
        block = int(options.get("block", 24))
        plain = quilting.synthesize(
            texture, target.shape[:2], block=block, seed=SEED, backend=BACKEND
        )
        gap = "n/a"
        if texeval is not None:
            mine = texeval_figures(texeval, texture, result.image)["hf_excess"]
            theirs = texeval_figures(texeval, texture, plain.image)["hf_excess"]
            gap = f"{mine - theirs:+.2f}"
        quilting.write_image(HERE / name, result.image)
        blocks = ", ".join(str(p.grid.block) for p in result.layout.passes)
        print(
            f"{name}: {options or 'defaults'}; blocks {blocks}; likeness "
            f"{likeness(result.image, target):.3f}; hf gap {gap}; "
            f"{result.timings['total']:.2f} s"
        )


if __name__ == "__main__":
    main()
