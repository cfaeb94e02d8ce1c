"""Regenerate the README's alpha-quilting images: ``examples/alpha_*.png``.

The RGBA cloud texture (``tests/data/cloud_rgba.png``) quilted to 384x256 with alpha
quilting (the default for RGBA) and, for comparison, its colour alone quilted with the alpha
carried along by the same layout. Each is written as it is (RGBA) and composited over a
checkerboard, so the transparency shows in any viewer. Seed 0, block 32, ``fft``. Run from the
repository root::

    .venv/bin/python examples/make_alpha.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import quilting

HERE = Path(__file__).resolve().parent
TEXTURE = HERE.parent / "tests" / "data" / "cloud_rgba.png"
SIZE = (256, 384)  # (height, width)


def over_checkerboard(rgba: np.ndarray, square: int = 16) -> np.ndarray:
    """RGBA uint8 (H, W, 4) composited over a gray checkerboard: RGB uint8 (H, W, 3)."""
    h, w = rgba.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    board = np.where(((yy // square) + (xx // square)) % 2 == 0, 90.0, 150.0)[..., None]
    alpha = rgba[..., 3:4] / 255.0
    out = rgba[..., :3] * alpha + board * (1 - alpha)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def main() -> None:
    texture = quilting.read_image(TEXTURE)
    result = quilting.synthesize(texture, SIZE, block=32, seed=0, backend="fft")
    assert result.layout.meta["mode"] == "alpha"
    colour_only = quilting.synthesize(texture[..., :3], SIZE, block=32, seed=0, backend="fft")
    carried = np.dstack(
        [colour_only.image, quilting.apply_layout(colour_only.layout, texture[..., 3])]
    )
    images = {
        "alpha_texture.png": over_checkerboard(texture),
        "alpha_quilted.png": result.image,
        "alpha_quilted_board.png": over_checkerboard(result.image),
        "alpha_rgb_only_board.png": over_checkerboard(carried),
    }
    for name, image in images.items():
        quilting.write_image(HERE / name, image)
        print(f"wrote examples/{name} {image.shape[1]}x{image.shape[0]}")


if __name__ == "__main__":
    main()
