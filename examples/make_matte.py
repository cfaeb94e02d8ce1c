"""Regenerate the README's texture-matting images: ``examples/matte_*.png``.

The target is an egg rendered with numpy: 384x384, a smooth surface of revolution about the
vertical axis (wider below), Lambertian, light warm grey, lit from the upper left with a little
ambient light, on a dark background, anti-aliased by 4x4 supersampling; its silhouette is the
egg's coverage. Matting reads the surface from the target's shading alone and lays
``tests/data/brick.png`` (opaque) on it, then the same brick with ``tests/data/cloud_rgba.png``
(RGBA, alpha quilting) over it. Written:

* ``matte_target.png``, ``matte_silhouette.png``: the inputs;
* ``matte_normals.png``: the normals estimated from the shading, as a normal map
  (``(n + 1) / 2``, +y up);
* ``matte_clusters.png``: the patches (connected parts of the k-means clusters), one colour
  each;
* ``matte_brick.png``: one layer; ``matte_brick_cloud.png``: two layers.

Seed 0, block 48, the matting defaults otherwise (8 clusters, scale 1), ``fft``. Run from the
repository root::

    .venv/bin/python examples/make_matte.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

import quilting

HERE = Path(__file__).resolve().parent
DATA = HERE.parent / "tests" / "data"
SIZE = 384
SUPERSAMPLE = 4
#: Towards the light: upper left, in front (x right, y up, z towards the viewer).
LIGHT = (-1.0, 1.0, 1.4)
ALBEDO = (0.86, 0.80, 0.70)
AMBIENT = 0.06
BACKGROUND = (0.07, 0.07, 0.09)


def render_egg(size: int) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """An egg lit from the upper left on a dark background, and its silhouette.

    The egg is the surface of revolution ``x^2 + z^2 = r(y)^2`` about the vertical axis with
    ``r = b sqrt(1 - t^2) (1 - k t)``, ``t = y / a`` (a the half height, b the half width,
    k = 0.12 makes it wider below), seen along z; its normal is ``(x, -r dr/dy, z)``
    normalized. Rendered ``SUPERSAMPLE`` times larger and averaged down.

    Parameters
    ----------
    size : int
        Side of the square image in pixels.

    Returns
    -------
    target : ndarray, shape (size, size, 3), uint8
    silhouette : ndarray, shape (size, size), uint8
        255 inside, the coverage at the outline, 0 outside.
    """
    fine = size * SUPERSAMPLE
    half_height, half_width, k = 0.44 * fine, 0.31 * fine, 0.12
    grid = np.arange(fine) + 0.5 - fine / 2
    x = grid[None, :]
    y = -grid[:, None] - 0.02 * fine  # y up; the egg sits a little low
    t = np.clip(y / half_height, -1.0, 1.0)
    r2 = half_width**2 * (1.0 - t**2) * (1.0 - k * t) ** 2
    # r dr/dy = d(r^2 / 2)/dy.
    r_dr = -(half_width**2 / half_height) * (1.0 - k * t) * (t * (1.0 - k * t) + k * (1.0 - t**2))
    inside = (x**2 < r2) & (np.abs(y) < half_height)
    z = np.sqrt(np.clip(r2 - x**2, 0.0, None))
    normals = np.stack(np.broadcast_arrays(x, -r_dr, z), axis=-1)
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    light = np.asarray(LIGHT) / np.linalg.norm(LIGHT)
    shade = np.clip(normals @ light, 0.0, None) + AMBIENT
    colour = np.where(inside[..., None], shade[..., None] * ALBEDO, BACKGROUND)

    def down(values: NDArray[np.float64]) -> NDArray[np.float64]:
        shape = (size, SUPERSAMPLE, size, SUPERSAMPLE, *values.shape[2:])
        averaged: NDArray[np.float64] = values.reshape(shape).mean(axis=(1, 3))
        return averaged

    target = np.rint(np.clip(down(colour), 0.0, 1.0) * 255).astype(np.uint8)
    silhouette = np.rint(down(inside.astype(np.float64)) * 255).astype(np.uint8)
    return target, silhouette


def main() -> None:
    """Render the target, matte one and two layers onto it and write the images."""
    target, silhouette = render_egg(SIZE)
    brick = quilting.read_image(DATA / "brick.png")
    cloud = quilting.read_image(DATA / "cloud_rgba.png")
    one, two = (
        quilting.matte(target, layers, silhouette=silhouette, block=48, seed=0, backend="fft")
        for layers in ([brick], [brick, cloud])
    )
    true = np.asarray(LIGHT) / np.linalg.norm(LIGHT)
    print(f"light: estimated {np.round(one.light, 3)}, true {np.round(true, 3)}")
    images = {
        "matte_target.png": target,
        "matte_silhouette.png": silhouette,
        "matte_normals.png": one.normal_map(),
        "matte_clusters.png": one.patch_map(),
        "matte_brick.png": one.image,
        "matte_brick_cloud.png": two.image,
    }
    for name, image in images.items():
        quilting.write_image(HERE / name, image)
        kib = (HERE / name).stat().st_size / 1024
        print(f"wrote examples/{name} {image.shape[1]}x{image.shape[0]} ({kib:.0f} KiB)")


if __name__ == "__main__":
    main()
