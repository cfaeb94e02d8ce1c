"""Regenerate the pictures of alpha from an ordinary photo: ``examples/extract_*.png``.

The photo is made by this script, as the benchmark makes it (``benchmarks/bench_alpha.py
--extract``): the cloud of ``tests/data/cloud_rgba.png`` (its alpha and colour) laid over the
grass photo of ``tests/data`` tinted green, 192x192, so the true alpha is known. From it:

* ``extract_photo.png``: the photo (opaque RGB: what an artist has);
* ``extract_trimap.png``: the trimap (white where the true alpha is over 0.97, black under
  0.03, grey between); ``extract_scribbles.png``: a few strokes instead (transparent
  elsewhere), and ``extract_scribbles_over.png`` the strokes over the photo;
* ``extract_texture_board.png``: the RGBA texture extracted with the trimap (large-kernel
  matting), over a checkerboard; ``extract_photo_colour_board.png`` the
  same alpha with the photo's own colour (the grass stays in the cloud's edges);
  ``extract_scribbles_board.png`` the texture extracted from the strokes alone;
* ``extract_quilted_board.png``: 384x256 quilted from the photo and its trimap
  (``quilting.synthesize(photo, size, trimap=...)``), over the checkerboard.

Run from the repository root::

    .venv/bin/python examples/make_extract.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import quilting

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "benchmarks"))

from bench_alpha import scene, user_maps  # noqa: E402  (the benchmark's photos)
from make_alpha import over_checkerboard  # noqa: E402

SIDE = 192
SIZE = (256, 384)  # (height, width)


def strokes(alpha: np.ndarray) -> np.ndarray:
    """Scribbles as a user paints them on a transparent layer: RGBA uint8 (h, w, 4)."""
    layer = np.zeros((*alpha.shape, 4), np.uint8)
    marks = user_maps(alpha, "scribbles")
    thick = np.zeros(alpha.shape, bool)
    thick[np.arange(alpha.shape[0]) % 24 < 3] = True  # three-pixel strokes every 24 rows
    layer[thick & (marks == 255)] = (255, 255, 255, 255)
    layer[thick & (marks == 0)] = (0, 0, 0, 255)
    return layer


def main() -> None:
    photo, alpha = scene(SIDE, "grass")
    trimap = user_maps(alpha, "trimap")
    lines = strokes(alpha)
    over = photo.copy()
    drawn = lines[..., 3] > 0
    over[drawn] = lines[drawn, :3]
    extracted = quilting.extract_alpha(photo, trimap)
    tinted = quilting.extract_alpha(photo, trimap, foreground="photo")
    scribbled = quilting.extract_alpha(photo, scribbles=lines)
    quilted = quilting.synthesize(photo, SIZE, trimap=trimap, block=32, seed=0, backend="fft")
    pictures = {
        "extract_photo.png": photo,
        "extract_trimap.png": trimap,
        "extract_scribbles.png": lines,
        "extract_scribbles_over.png": over,
        "extract_texture_board.png": over_checkerboard(extracted.image),
        "extract_photo_colour_board.png": over_checkerboard(tinted.image),
        "extract_scribbles_board.png": over_checkerboard(scribbled.image),
        "extract_quilted_board.png": over_checkerboard(quilted.image),
    }
    for name, image in pictures.items():
        quilting.write_image(HERE / name, image)
    for name, found in (("trimap", extracted), ("scribbles", scribbled)):
        error = float(np.abs(found.alpha - alpha).mean())
        print(f"{name}: {found.summary()}, alpha MAE against the truth {error:.4f}")


if __name__ == "__main__":
    main()
